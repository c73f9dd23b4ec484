"""Results across training seeds: train the demo's PPO for N seeds, evaluate each, aggregate as rliable does.

Each seed trains exactly as ``pectoral-demo --seed S`` (PPO on :data:`pectoral_gym.versions.LATEST_AVERAGED`, task
``goal``, ``agents/hyperparams/ppo.yml``, best model chosen on the periodic evaluation's episodes, which the
shipped file runs on the full model: ``eval_env``) and is then evaluated on three settings, the same held-out
episodes for every seed (episode ``k`` reset with ``--eval-seed + k``, default the demo's): the averaged model, the
full model, and the full model with :data:`pectoral_gym.agents.training.evaluate.DEFAULT_RANDOMIZATION`, each as
the train env's version (v1: with the robot's stopping band, servo limit and goal inset; the full model's fast
integration). A :class:`pectoral_gym.agents.studies.solve_probe.SolveProbe` (``--probe-every``) times each run to
0.95 success on the full model on a third set of episodes.

Across seeds, per setting: the interquartile mean (``scipy.stats.trim_mean(x, 0.25)``, the mean of the
middle half of the seeds, as in rliable) with a percentile-bootstrap interval over seeds
(``scipy.stats.bootstrap``), the mean, min, median, max, and how many seeds meet the targets
(full >= 0.95, full+rand >= 0.90, averaged minus full <= 0.03). With a handful of seeds the bootstrap
interval is coarse: it can only take values that subsets of these seeds give. The statistics are
:mod:`pectoral_gym.agents.studies.seeds_stats` (``iqm`` and ``aggregate``, re-exported here).

CLI (``pectoral-seeds``, also ``python -m pectoral_gym.agents.studies.seeds``)::

    pectoral-seeds                              # seeds 0-4, 2 parallel jobs, writes seeds_out/
    pectoral-seeds --seeds 100 101 102 103 --jobs 2 --out tune_base
    pectoral-seeds --seeds 0 1 --timesteps 2e5 --episodes 50 --hyperparams ent_coef=0.01
    pectoral-seeds --env PectoralFish-Full-v2 --timesteps 1.6e6
    pectoral-seeds --env PectoralFish-Averaged-v0   # the v0 envs, as before

``--env PectoralFish-Full-v*`` trains on the full model instead (its entry of the hyperparameter file);
the evaluations run the full model as the train env's version registers it (v0: the reference steps,
v1: the fast integration), whatever ``integration`` the training used.

Writes ``<out>/seeds.md``, ``<out>/seeds.json``, ``<out>/seeds.png`` and one training run folder per
seed, ``<out>/seed<S>/`` (with ``eval_<setting>.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.studies.seeds_report import plot_seeds, to_markdown
from pectoral_gym.agents.studies.seeds_stats import aggregate, iqm
from pectoral_gym.tools.cli_common import HelpFormatter, add_seeds_argument, examples, prog_name
from pectoral_gym.versions import ENV_VERSIONS, LATEST_AVERAGED, LATEST_FULL

__all__ = ["SETTINGS", "TARGETS", "aggregate", "build_parser", "iqm", "main", "run_seed", "run_seeds",
           "summarize_seeds", "train_seeds", "versioned"]

TRAIN_ENV = LATEST_AVERAGED
# label -> (env id, randomised) of the latest envs; as pectoral_gym.agents.studies.benchmark_settings.ENVS.
# versioned() gives another version's.
SETTINGS = {"averaged": (LATEST_AVERAGED, False), "full": (LATEST_FULL, False), "full+rand": (LATEST_FULL, True)}
TRAIN_ENVS = tuple(sorted(ENV_VERSIONS, key=lambda env_id: (env_id.rsplit("-", 1)[1], env_id)))


def versioned(env_id: str, train_env: str) -> str:
    """``env_id`` in ``train_env``'s version: a policy is evaluated on the envs it trained for."""
    return env_id.rsplit("-", 1)[0] + "-" + train_env.rsplit("-", 1)[1]
TARGETS = {"full": 0.95, "full+rand": 0.90, "gap": 0.03}  # success >= (gap: averaged - full <=)
REPORTED = ("success", "time_to_goal", "final_distance", "fin_work", "return", "wall")
QUICK = {"n_timesteps": 2048, "n_envs": 8, "n_steps": 64, "batch_size": 128, "n_epochs": 1, "eval_freq": 1024,
         "eval_episodes": 4}


def run_seed(seed: int, out: str | Path, overrides: dict[str, Any] | None = None, episodes: int = 100,
             eval_seed: int | None = None, probe: dict[str, Any] | None = None, hyperparams_file: str | None = None,
             queue: Any = None, settings: Sequence[str] = tuple(SETTINGS),
             train_env: str = TRAIN_ENV) -> dict[str, Any]:
    """Train one seed as the demo does and evaluate it on :data:`SETTINGS` (a worker of :func:`run_seeds`).

    Args:
        seed: Training seed.
        out: Parent folder; the run goes to ``<out>/seed<seed>/``.
        overrides: Hyperparameter overrides (``pectoral_gym.agents.training.config.resolve_config``'s ``hyperparams``).
        episodes: Evaluation episodes per setting.
        eval_seed: Evaluation episode ``k`` is reset with ``eval_seed + k`` (default the demo's).
        probe: Keyword arguments of :class:`pectoral_gym.agents.studies.solve_probe.SolveProbe` (``None``: no time to
            solve).
        hyperparams_file: Hyperparameter file (default ``agents/hyperparams/ppo.yml``).
        queue: Anything with ``put``; receives ``(seed, stage, timesteps)`` progress messages.
        settings: Labels of :data:`SETTINGS` to evaluate on after training (empty: none).
        train_env: The env id trained on (default :data:`TRAIN_ENV`, the demo's).

    Returns:
        ``seed, run_dir, timesteps, train_time_s, best_eval, evaluations`` (per setting, the :data:`REPORTED`
        metric summaries) and ``time_to_solve`` (:meth:`SolveProbe.summary`, or ``None``).
    """
    from pectoral_gym.agents.studies.solve_probe import REPORT_SEED, SolveProbe
    from pectoral_gym.agents.training.config import resolve_config
    from pectoral_gym.agents.training.evaluate import DEFAULT_RANDOMIZATION, TRAINING_ONLY, evaluate, write_json
    from pectoral_gym.agents.training.policy import load_policy
    from pectoral_gym.agents.training.train import train

    put = queue.put if queue is not None else (lambda _message: None)
    eval_seed = REPORT_SEED if eval_seed is None else int(eval_seed)
    config = resolve_config("ppo", train_env, int(seed), task="goal", hyperparams=dict(overrides or {}),
                            hyperparams_file=hyperparams_file)
    run_dir = Path(out) / f"seed{seed}"
    solve = SolveProbe(**probe) if probe is not None else None

    def on_evaluation(record: dict[str, Any]) -> bool:
        put((seed, "train", int(record["timesteps"])))
        return True if solve is None else solve.on_evaluation(record)

    command = shlex.join(["python", "-m", "pectoral_gym.agents.studies.seeds", *sys.argv[1:]])
    train(config, run_dir, progress=False, command=command, on_evaluation=on_evaluation, probe=solve)
    training = json.loads((run_dir / "training.json").read_text())
    put((seed, "train", int(training["timesteps"])))
    policy = load_policy(run_dir)
    base = {k: v for k, v in config["env_kwargs"].items() if k not in TRAINING_ONLY}
    evaluations = {}
    for label in settings:
        env_id, randomised = SETTINGS[label]
        env_id = versioned(env_id, train_env)
        put((seed, f"eval {label}", int(training["timesteps"])))
        kwargs = {**base, "randomize": dict(DEFAULT_RANDOMIZATION)} if randomised else dict(base)
        result = evaluate(policy, env_id, n_episodes=episodes, seed=eval_seed, env_kwargs=kwargs)
        write_json(result, run_dir / f"eval_{label}.json")  # per-episode metrics too: failure analysis
        evaluations[label] = {m: result.metrics[m].as_dict() for m in REPORTED if m in result.metrics}
    best = max(training["evaluations"], key=lambda r: (r["success"], r["mean_return"]), default=None)
    put((seed, "done", int(training["timesteps"])))
    return {"seed": int(seed), "run_dir": str(run_dir), "timesteps": training["timesteps"],
            "train_time_s": training["train_time_s"], "probe_time_s": training.get("probe_time_s", 0.0),
            "best_eval": best, "training_evaluations": training["evaluations"], "evaluations": evaluations,
            "time_to_solve": solve.summary() if solve is not None else None}


def summarize_seeds(per_seed: list[dict[str, Any]], confidence: float = 0.95) -> dict[str, Any]:
    """Across-seed aggregates (:func:`aggregate`) of success per setting, the gap, time to goal and time to solve.

    Also ``targets``: per figure, the threshold and the seeds that meet it.
    """
    def success(run: dict[str, Any], label: str) -> float:
        value = run["evaluations"][label]["success"]["mean"]
        return float("nan") if value is None else float(value)

    figures: dict[str, list[float]] = {f"success {label}": [success(r, label) for r in per_seed] for label in SETTINGS}
    figures["gap averaged-full"] = [success(r, "averaged") - success(r, "full") for r in per_seed]
    figures["time to goal full [s]"] = [
        float("nan") if r["evaluations"]["full"]["time_to_goal"]["mean"] is None
        else r["evaluations"]["full"]["time_to_goal"]["mean"] for r in per_seed]
    solve = [r["time_to_solve"] for r in per_seed]
    if all(s is not None for s in solve):
        figures["time to solve [s]"] = [float("nan") if s["time_to_solve_s"] is None else s["time_to_solve_s"]
                                        for s in solve]
    seeds = [r["seed"] for r in per_seed]
    checks = {"success full": (">=", TARGETS["full"]), "success full+rand": (">=", TARGETS["full+rand"]),
              "gap averaged-full": ("<=", TARGETS["gap"])}
    targets = {}
    for name, (sign, threshold) in checks.items():
        values = np.asarray(figures[name])
        ok = values >= threshold if sign == ">=" else values <= threshold + 1e-12
        targets[name] = {"target": f"{sign} {threshold}", "seeds_met": [s for s, k in zip(seeds, ok, strict=True)
                                                                        if k], "n": len(seeds)}
    return {"seeds": seeds, "confidence": confidence,
            "figures": {name: aggregate(values, confidence=confidence) for name, values in figures.items()},
            "targets": targets}


def run_seeds(seeds: Sequence[int], out: str | Path, jobs: int = 1, overrides: dict[str, Any] | None = None,
              episodes: int = 100, eval_seed: int | None = None, probe: dict[str, Any] | None = None,
              hyperparams_file: str | None = None, confidence: float = 0.95, progress: bool = True,
              command: str | None = None, train_env: str = TRAIN_ENV) -> dict[str, Any]:
    """Train and evaluate every seed (``jobs`` processes at once), aggregate, write the outputs.

    Args:
        seeds: Training seeds (distinct).
        out: Output folder (must not hold a run of these seeds yet).
        jobs: Parallel worker processes (1: in this process).
        overrides, episodes, eval_seed, probe, hyperparams_file: As in :func:`run_seed`.
        confidence: Level of the across-seed bootstrap intervals.
        progress: Show one progress bar per seed.
        command: The command line stored in the report.
        train_env: As in :func:`run_seed`.

    Returns:
        The report written to ``seeds.json``: ``settings``, ``per_seed`` (seed order) and ``summary``
        (:func:`summarize_seeds`).

    Raises:
        ValueError: For repeated seeds, ``jobs`` < 1, ``episodes`` < 1 or overlapping episode seeds.
        FileExistsError: If a seed's run folder exists.
    """
    from pectoral_gym.agents.studies.solve_probe import REPORT_SEED, SolveProbe, check_held_out
    from pectoral_gym.agents.training.config import resolve_config

    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct and at least one, got {seeds}")
    if jobs < 1 or episodes < 1:
        raise ValueError(f"jobs and episodes must be >= 1, got {jobs}, {episodes}")
    out = Path(out)
    for seed in seeds:
        if (out / f"seed{seed}").exists():
            raise FileExistsError(f"{out / f'seed{seed}'} exists; choose another --out or remove it")
    config = resolve_config("ppo", train_env, seeds[0], task="goal", hyperparams=dict(overrides or {}),
                            hyperparams_file=hyperparams_file)
    eval_seed = REPORT_SEED if eval_seed is None else int(eval_seed)
    if probe is not None:
        probe = {"confirm_seed": eval_seed, **probe}  # the confirmation runs on the reported episodes
    probe_settings = SolveProbe(**(probe or {}))
    check_held_out(seeds, config["n_envs"], config["eval_episodes"], probe_settings.episodes if probe else 0,
                   episodes, probe_seed=probe_settings.seed, report_seed=eval_seed)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    args = {"out": str(out), "overrides": dict(overrides or {}), "episodes": int(episodes), "eval_seed": eval_seed,
            "probe": probe, "hyperparams_file": hyperparams_file, "train_env": train_env}
    results = train_seeds(seeds, jobs, args, config["n_timesteps"], progress)
    per_seed = [results[s] for s in seeds]
    report = {"settings": {"seeds": seeds, "jobs": int(jobs), "train_env": train_env, "episodes": int(episodes),
                           "eval_seed": eval_seed, "overrides": args["overrides"], "probe": probe,
                           "eval_env": config["eval_env"],
                           "hyperparams_file": hyperparams_file, "n_timesteps": config["n_timesteps"],
                           "algo_kwargs": {k: str(v) for k, v in config["algo_kwargs"].items()},
                           "command": command or shlex.join(["python", "-m", "pectoral_gym.agents.studies.seeds",
                                                             *sys.argv[1:]]),
                           "wall_time_s": time.perf_counter() - start, "cpu_count": os.cpu_count()},
              "per_seed": per_seed, "summary": summarize_seeds(per_seed, confidence=confidence)}
    from pectoral_gym.agents.training.results import json_default

    (out / "seeds.json").write_text(json.dumps(report, indent=2, default=json_default) + "\n")
    (out / "seeds.md").write_text(to_markdown(report) + "\n")
    plot_seeds(report, out / "seeds.png")
    return report


def train_seeds(seeds: Sequence[int], jobs: int, args: dict[str, Any], total: int,
                progress: bool = True) -> dict[int, dict[str, Any]]:
    """:func:`run_seed` for every seed with the keyword arguments ``args``, ``jobs`` processes at once.

    Args:
        seeds: Training seeds.
        jobs: Worker processes (1, or a single seed: in this process).
        args: Keyword arguments of :func:`run_seed` other than ``seed`` and ``queue``.
        total: Training steps per seed (the progress bars' length).
        progress: Show one progress bar per seed.

    Returns:
        ``{seed: run_seed(...)}``.
    """
    seeds = [int(s) for s in seeds]
    bars = _Bars(seeds, total, progress)
    results: dict[int, dict[str, Any]] = {}
    try:
        if jobs == 1 or len(seeds) == 1:
            for seed in seeds:
                results[seed] = run_seed(seed, queue=bars, **args)
        else:
            _run_parallel(seeds, min(jobs, len(seeds)), args, bars, results)
    finally:
        bars.close()
    return results


def _run_parallel(seeds: list[int], jobs: int, args: dict[str, Any], bars: _Bars,
                  results: dict[int, dict[str, Any]]) -> None:
    """Workers in fresh (spawned) processes; their progress messages come back through a manager queue."""
    import multiprocessing
    import queue as queue_module
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    context = multiprocessing.get_context("spawn")  # no fork of a process holding torch/numba threads
    with context.Manager() as manager, ProcessPoolExecutor(jobs, mp_context=context) as pool:
        messages = manager.Queue()
        pending = {pool.submit(run_seed, seed, queue=messages, **args): seed for seed in seeds}
        while pending:
            done, _ = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            while True:
                try:
                    bars.put(messages.get_nowait())
                except queue_module.Empty:
                    break
            for future in done:
                results[pending.pop(future)] = future.result()  # a failing seed raises here


class _Bars:
    """One tqdm bar per seed (training steps; the stage as postfix); ``put`` takes the workers' messages."""

    def __init__(self, seeds: list[int], total: int, enabled: bool):
        from tqdm.auto import tqdm

        self.bars = {s: tqdm(total=int(total), desc=f"seed {s}", unit="step", position=i, disable=not enabled,
                             leave=True) for i, s in enumerate(seeds)}

    def put(self, message: tuple[int, str, int]) -> None:
        seed, stage, timesteps = message
        bar = self.bars[seed]
        bar.update(max(0, min(int(timesteps), bar.total) - bar.n))
        bar.set_postfix_str(stage)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-seeds``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-seeds", "pectoral_gym.agents.studies.seeds"),
        description=__doc__.split("\n\n")[0] + " Writes seeds.md, seeds.json and seeds.png into --out.",
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-seeds --quick --seeds 0 1 --out seeds_quick",
                        "pectoral-seeds --seeds 100 101 102 103 --jobs 2 --out tune_base",
                        "pectoral-seeds --seeds 0 1 --timesteps 2e5 --episodes 50 --hyperparams ent_coef=0.01",
                        f"pectoral-seeds --env {LATEST_FULL} --timesteps 1.6e6"))
    add_seeds_argument(parser, [0, 1, 2, 3, 4], "training seeds (default 0-4)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                        help="seeds trained at once, each in its own process (1 torch thread each; default: 2, or "
                             "the number of CPUs if fewer)")
    parser.add_argument("--out", default="seeds_out", metavar="DIR", help="output folder")
    parser.add_argument("--env", dest="train_env", choices=TRAIN_ENVS, default=TRAIN_ENV, metavar="ID",
                        help=f"env trained on, one of {', '.join(TRAIN_ENVS)} (default: %(default)s, as the demo)")
    parser.add_argument("--timesteps", type=float, metavar="N",
                        help="training steps (default: agents/hyperparams/ppo.yml)")
    parser.add_argument("--episodes", type=int, help="evaluation episodes per setting and seed (default 100, quick 4)")
    parser.add_argument("--eval-seed", type=int,
                        help="evaluation episode k is reset with this + k "
                             "(default: the demo's, pectoral_gym.agents.training.demo.EVAL_SEED)")
    parser.add_argument("--hyperparams", nargs="*", default=[], metavar="KEY=VALUE",
                        help="override hyperparameters (YAML values; nested keys with dots)")
    parser.add_argument("--hyperparams-file", metavar="YAML", help="hyperparameter file (default: agents/hyperparams)")
    parser.add_argument("--probe-every", type=int, default=1,
                        help="time to solve: probe the full model after every k-th periodic evaluation (0: off)")
    parser.add_argument("--probe-episodes", type=int, default=100, help="episodes per probe")
    parser.add_argument("--confidence", type=float, default=0.95, help="level of the across-seed intervals")
    parser.add_argument("--quick", action="store_true", help="smoke run: tiny training, 4 episodes")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    from pectoral_gym.agents.training.config import parse_overrides

    args = build_parser().parse_args(argv)
    try:
        overrides = dict(QUICK) if args.quick else {}
        overrides.update(parse_overrides(args.hyperparams))
        if args.timesteps is not None:
            overrides["n_timesteps"] = int(args.timesteps)
        episodes = args.episodes or (4 if args.quick else 100)
        probe = None
        if args.probe_every:
            probe = {"every": args.probe_every, "episodes": 4 if args.quick else args.probe_episodes,
                     "confirm_episodes": episodes, "keep_probing": True,  # the full model's learning curve
                     "env_id": versioned(SETTINGS["full"][0], args.train_env)}
        command = shlex.join(["python", "-m", "pectoral_gym.agents.studies.seeds",
                              *(sys.argv[1:] if argv is None else argv)])
        report = run_seeds(args.seeds, args.out, jobs=args.jobs, overrides=overrides, episodes=episodes,
                           eval_seed=args.eval_seed, probe=probe, hyperparams_file=args.hyperparams_file,
                           confidence=args.confidence, progress=not args.no_progress, command=command,
                           train_env=args.train_env)
    except (ValueError, FileExistsError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(to_markdown(report))
    print(f"wrote {Path(args.out) / 'seeds.md'}, seeds.json and seeds.png in {report['settings']['wall_time_s']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
