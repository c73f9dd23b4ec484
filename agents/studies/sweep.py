"""Sweeps of training on Ray Tune: seeds, hyperparameters and randomisation ranges.

Each trial is a :func:`pectoral_gym.agents.training.train.train`.

CLI (``pectoral-sweep``, also ``python -m pectoral_gym.agents.studies.sweep``)::

    pectoral-sweep --grid seed=0,1,2 ent_coef=0,0.005 --timesteps 2e5
    pectoral-sweep --param-space sweep.yml --num-samples 4 --scheduler asha --metric success
    pectoral-sweep --address auto --grid seed=0,1,2,3 randomize_scale=0,1   # an existing cluster

The parameter space (``--param-space`` file, ``--grid key=v1,v2``; keys and kinds in
:mod:`pectoral_gym.agents.studies.sweep_space`) defaults to ``seed=0,1,2``. Without ``--address`` the command
starts an embedded local Ray (``ray.init(num_cpus=--num-cpus)``) and shuts it down at the
end; with ``--address`` it joins that cluster (the project must be importable on its nodes).

Each trial is one :func:`pectoral_gym.agents.training.train.train` run with ``torch_threads=--cpus-per-trial``;
its ``on_evaluation`` callback sends every periodic evaluation to Tune (``ray.tune.report``:
``timesteps``, ``success``, ``mean_return``, ...), so ``--scheduler asha`` stops trials that
trail at a rung (rungs in environment steps: ``--grace-period`` times powers of
``--reduction-factor``; ``max_t`` the largest ``n_timesteps``). ``--final-env
PectoralFish-Full-v2`` evaluates each trial's best model at the end on held-out episodes,
the same for every trial (``final_success``, ...).
numba's kernels are compiled once before the trials, by a warm-up task on every node, into
numba's cache (beside the sources, which a node's workers share, or ``--numba-cache-dir``,
set as ``NUMBA_CACHE_DIR`` of every worker: a cluster's shared disk); each trial reports the
time it took to get its environments ready (``env_ready_s``: numba compiling or loading the
cache) so the saving can be read from the table.

Output in ``<out>/<name>/`` (``--out``: Tune's storage path): Tune's trial folders (each holds the run folder of
:mod:`pectoral_gym.agents.training.train` in ``run/``), ``results.csv`` and ``results.md`` (one row per trial:
its values, status, last and best evaluation) and ``results.png`` (the metric against
environment steps, one line per trial).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import pectoral_gym
from pectoral_gym.agents.studies.sweep_results import plot_results, result_rows, write_tables
from pectoral_gym.agents.studies.sweep_space import (
    SAMPLERS,
    Dimension,
    grid_points,
    load_param_space,
    parse_grid,
    trial_config,
)
from pectoral_gym.agents.training.config import parse_overrides
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name
from pectoral_gym.versions import LATEST_AVERAGED, LATEST_FULL

__all__ = ["DEFAULT_SPACE", "build_parser", "main", "run_sweep", "tune_space", "warm_up"]

DEFAULT_SPACE: dict[str, Dimension] = {"seed": ("grid", [0, 1, 2])}
METRICS = ("mean_return", "success", "tracking_error")
FINAL_SEED = 2_000_000  # the final evaluation's episodes: apart from training (seed + i) and seed + 1_000_000 + k


def warm_up(config: dict[str, Any], final: dict[str, Any] | None = None) -> float:
    """Compile (or load from numba's cache) every kernel a training run of ``config`` uses; returns seconds.

    Steps the training vector env (``n_envs`` fish, through autoresets) and runs an evaluation with
    ``eval_episodes`` slots, both on two-step episodes; the imports are timed too. ``final``
    (``env_id``, ``n_episodes``, ``env_kwargs``) adds the final evaluation's env.
    """
    start = time.perf_counter()
    import numpy as np

    from pectoral_gym.agents.training.evaluate import evaluate
    from pectoral_gym.agents.training.vec_adapter import make_fish_vec_env
    from pectoral_gym.envs.layout import ACTION_SIZE

    env_kwargs = dict(config["env_kwargs"])
    venv = make_fish_vec_env(config["env_id"], config["n_envs"], env_kwargs, seed=0, max_episode_steps=2)
    venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(5):
        venv.step(rng.uniform(-1, 1, (config["n_envs"], ACTION_SIZE)).astype(np.float32))
    venv.close()
    if config["eval_episodes"] > 0:
        evaluate(_ZeroController(), config["env_id"], n_episodes=config["eval_episodes"], seed=0,
                 env_kwargs={**env_kwargs, "max_episode_steps": 2})
    if final:
        evaluate(_ZeroController(), final["env_id"], n_episodes=final["n_episodes"], seed=0,
                 env_kwargs={**final["env_kwargs"], "max_episode_steps": 2})
    return time.perf_counter() - start


class _ZeroController:
    """The zero action, for the warm-up's evaluation."""

    name = "zero"

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset."""

    def act_batch(self, obs):
        """Zeros ``(n, 8)``."""
        import numpy as np

        from pectoral_gym.envs.layout import ACTION_SIZE

        return np.zeros((len(obs), ACTION_SIZE), dtype=np.float32)

    def act(self, obs):
        """Zeros ``(8,)``."""
        return self.act_batch(obs[None])[0]


def _trainable(params: dict[str, Any], base: dict[str, Any]) -> None:
    """One Tune trial: resolve its config, get the envs ready, train, report every evaluation."""
    from ray import tune

    from pectoral_gym.agents.training.train import train

    config = trial_config(base["algo"], base["env_id"], params, seed=base["seed"], hyperparams=base["hyperparams"],
                          hyperparams_file=base["hyperparams_file"])
    env_ready_s = warm_up(config, _final_spec(config, base))
    run_dir = Path(tune.get_context().get_trial_dir()) / "run"

    final: list[dict[str, Any]] = []

    def report(record: dict[str, Any]) -> None:
        metrics = {**{k: float(v) for k, v in record.items()}, "n_timesteps": config["n_timesteps"],
                   "env_ready_s": env_ready_s, "pid": os.getpid()}
        if record["timesteps"] >= config["n_timesteps"]:
            final.append(metrics)  # reported after train() has saved the model: ASHA stops a trial at max_t
        else:
            tune.report(metrics)  # a scheduler may stop the trial here (its best model is saved already)

    train(config, run_dir, progress=False, torch_threads=base["cpus_per_trial"], on_evaluation=report,
          command=base["command"])
    if final:  # one report: ASHA stops a trial at its first report at max_t, and later ones would be lost
        if base["final_env"]:
            final[-1].update(_final_evaluation(run_dir, config, base))
        tune.report(final[-1])


def _final_evaluation(run_dir: Path, config: dict[str, Any], base: dict[str, Any]) -> dict[str, float]:
    """The run's best model on ``base["final_env"]``: the same held-out episodes for every trial."""
    from pectoral_gym.agents.training.evaluate import evaluate
    from pectoral_gym.agents.training.policy import load_policy

    final = _final_spec(config, base)
    result = evaluate(load_policy(run_dir), final["env_id"], n_episodes=final["n_episodes"], seed=base["final_seed"],
                      env_kwargs=final["env_kwargs"])
    out = {"final_mean_return": float(result.metrics["return"].mean)}
    if "success" in result.metrics:
        out["final_success"] = float(result.metrics["success"].mean)
    if "tracking_error" in result.metrics:
        out["final_tracking_error"] = float(result.metrics["tracking_error"].mean)
    return out


def _final_spec(config: dict[str, Any], base: dict[str, Any]) -> dict[str, Any] | None:
    """The final evaluation's env id, episodes and env arguments (the run's, randomisation as asked), or ``None``."""
    from pectoral_gym.agents.training.evaluate import DEFAULT_RANDOMIZATION

    if not base["final_env"]:
        return None
    env_kwargs = {k: v for k, v in config["env_kwargs"].items() if k != "randomize"}
    if base["final_randomize"]:
        env_kwargs["randomize"] = DEFAULT_RANDOMIZATION
    return {"env_id": base["final_env"], "n_episodes": base["final_episodes"], "env_kwargs": env_kwargs}


def tune_space(space: dict[str, Dimension]) -> dict[str, Any]:
    """A space of :mod:`~pectoral_gym.agents.studies.sweep_space` as Tune's ``param_space``.

    Grid search, samplers and fixed values.
    """
    from ray import tune

    out: dict[str, Any] = {}
    for key, (kind, values) in space.items():
        if kind == "grid":
            out[key] = tune.grid_search(list(values))
        elif kind == "value":
            out[key] = values
        elif kind == "choice":
            out[key] = tune.choice(list(values))
        else:
            assert kind in SAMPLERS
            out[key] = getattr(tune, kind)(*values)
    return out


def _warm_nodes(config: dict[str, Any], final: dict[str, Any] | None) -> list[float]:
    """Run :func:`warm_up` once on every alive node (each writes the shared numba cache); seconds per node."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    task = ray.remote(num_cpus=1)(warm_up)
    nodes = [node["NodeID"] for node in ray.nodes() if node.get("Alive")]
    return ray.get([task.options(scheduling_strategy=NodeAffinitySchedulingStrategy(node, soft=False)).remote(
        config, final) for node in nodes])


def run_sweep(args: argparse.Namespace, space: dict[str, Dimension], base: dict[str, Any]) -> Path:
    """Start or join Ray, warm the numba cache, run the trials, write the tables and the plot; the sweep folder."""
    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler, FIFOScheduler
    from ray.tune.search.basic_variant import BasicVariantGenerator

    storage = Path(args.out).resolve()
    cache_dir = args.numba_cache_dir or os.environ.get("NUMBA_CACHE_DIR")
    root = str(Path(pectoral_gym.__file__).resolve().parents[1])  # the folder that holds the package
    env_vars = {"NUMBA_NUM_THREADS": str(args.cpus_per_trial), "OMP_NUM_THREADS": str(args.cpus_per_trial),
                "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    if cache_dir:
        env_vars["NUMBA_CACHE_DIR"] = str(Path(cache_dir).resolve())
    start = time.perf_counter()
    started = not ray.is_initialized()
    if started:
        if args.address:
            ray.init(address=args.address, runtime_env={"env_vars": env_vars})
        else:
            ray.init(num_cpus=args.num_cpus or os.cpu_count(), include_dashboard=False,
                     runtime_env={"env_vars": env_vars}, log_to_driver=args.verbose > 1)
    try:
        first = trial_config(base["algo"], base["env_id"], grid_points(space)[0], seed=base["seed"],
                             hyperparams=base["hyperparams"], hyperparams_file=base["hyperparams_file"])
        print(f"Ray ready in {time.perf_counter() - start:.1f} s")
        if args.warm_up:
            start = time.perf_counter()
            seconds = _warm_nodes(first, _final_spec(first, base))
            where = env_vars.get("NUMBA_CACHE_DIR", "numba's default, beside the sources")
            print(f"numba cache ({where}) warmed on {len(seconds)} node(s) in {time.perf_counter() - start:.1f} s "
                  "(warm-up task: " + ", ".join(f"{s:.1f} s" for s in seconds) + ")")
        if args.scheduler == "asha":
            grace = int(args.grace_period or first["eval_freq"])
            max_t = max(trial_config(base["algo"], base["env_id"], point, seed=base["seed"],
                                     hyperparams=base["hyperparams"], hyperparams_file=base["hyperparams_file"]
                                     )["n_timesteps"] for point in grid_points(space))
            scheduler = ASHAScheduler(time_attr="timesteps", max_t=max_t, grace_period=grace,
                                      reduction_factor=args.reduction_factor)
        else:
            scheduler = FIFOScheduler()
        trainable = tune.with_resources(tune.with_parameters(_trainable, base=base), {"cpu": args.cpus_per_trial})
        tuner = tune.Tuner(
            trainable, param_space=tune_space(space),
            tune_config=tune.TuneConfig(metric=args.metric, mode="min" if args.metric == "tracking_error" else "max",
                                        scheduler=scheduler, num_samples=args.num_samples, reuse_actors=False,
                                        # the generator limits concurrency itself: Tune ignores
                                        # max_concurrent_trials beside a generator passed as search_alg
                                        search_alg=BasicVariantGenerator(max_concurrent=args.max_concurrent,
                                                                         random_state=args.search_seed)),
            run_config=tune.RunConfig(name=args.name, storage_path=str(storage), verbose=args.verbose))
        grid = tuner.fit()
        rows = result_rows(grid, list(space), args.metric)
    finally:
        if started:
            ray.shutdown()
    folder = storage / args.name
    write_tables(rows, folder)
    plot_results(rows, folder / "results.png", args.metric)
    return folder


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-sweep``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-sweep", "pectoral_gym.agents.studies.sweep"),
        description=__doc__.split("\n\n")[0] + " Writes results.csv, results.md and results.png into "
        "<out>/<name>/ (needs the sweep extra: pip install -e .[sweep]).",
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-sweep --grid seed=0,1,2 ent_coef=0,0.005 --timesteps 2e5",
                        "pectoral-sweep --param-space sweep.yml --num-samples 4 --scheduler asha --metric success",
                        f"pectoral-sweep --grid seed=0,1 --timesteps 1e5 --final-env {LATEST_FULL} --out sweeps",
                        "pectoral-sweep --address auto --grid seed=0,1,2,3 randomize_scale=0,1"))
    parser.add_argument("--env", default=LATEST_AVERAGED, help="environment id")
    parser.add_argument("--algo", default="ppo", help="algorithm: ppo, sac, td3, a2c, ddpg")
    parser.add_argument("--param-space", metavar="FILE",
                        help="parameter space, YAML or JSON (see pectoral_gym.agents.studies.sweep_space)")
    parser.add_argument("--grid", nargs="*", default=[], metavar="KEY=V1,V2",
                        help="grid keys (over the file's); default space without either: seed=0,1,2")
    parser.add_argument("--num-samples", type=int, default=1, help="repeats of each grid point (fresh draws)")
    parser.add_argument("--seed", type=int, default=0, help="seed of trials whose space has no seed")
    parser.add_argument("--search-seed", type=int, default=0, help="seed of the sampled keys' draws")
    parser.add_argument("--hyperparams", nargs="*", default=[], metavar="KEY=VALUE",
                        help="hyperparameters of every trial (as pectoral_gym.agents.training.train; "
                             "the space's keys go over them)")
    parser.add_argument("--hyperparams-file", metavar="YAML", help="hyperparameter file (default: agents/hyperparams)")
    parser.add_argument("--timesteps", type=float, metavar="N", help="steps per trial (default: the file's)")
    parser.add_argument("--eval-freq", type=float, help="steps in all between evaluations (default: the file's)")
    parser.add_argument("--eval-episodes", type=int, help="episodes per evaluation (default: the file's)")
    parser.add_argument("--final-env", metavar="ID", help="evaluate each trial's best model on this env at the end "
                                                          f"({LATEST_FULL}: train averaged, test full)")
    parser.add_argument("--final-episodes", type=int, default=100, help="episodes of the final evaluation")
    parser.add_argument("--final-seed", type=int, default=FINAL_SEED,
                        help="final evaluation's episode k uses seed + k (the same for every trial; apart from the "
                             "training resets and the periodic evaluations)")
    parser.add_argument("--final-randomize", action="store_true",
                        help="final evaluation with pectoral_gym.agents.training.evaluate.DEFAULT_RANDOMIZATION")
    parser.add_argument("--metric", choices=METRICS, default="mean_return",
                        help="evaluation figure the scheduler compares (tracking_error: lower is better)")
    parser.add_argument("--scheduler", choices=("fifo", "asha"), default="fifo", help="fifo: run every trial out")
    parser.add_argument("--grace-period", type=float, help="ASHA: steps before a trial can stop (default: eval-freq)")
    parser.add_argument("--reduction-factor", type=float, default=3, help="ASHA: rung spacing and kept fraction 1/x")
    parser.add_argument("--address", help="Ray cluster to join (auto, ray://host:10001); default: a local Ray")
    parser.add_argument("--num-cpus", type=int, help="CPUs of the local Ray (default: all)")
    parser.add_argument("--cpus-per-trial", type=int, default=1, help="CPUs (torch and numba threads) per trial")
    parser.add_argument("--max-concurrent", type=int, default=0, help="trials at once (0: as the CPUs allow)")
    parser.add_argument("--out", default="runs/sweeps", metavar="DIR",
                        help="parent folder of the sweep folder (Tune's storage path)")
    parser.add_argument("--name", help="sweep folder name (default: <algo>_sweep_<stamp>)")
    parser.add_argument("--numba-cache-dir", help="numba cache of every worker, e.g. on a cluster's shared disk "
                                                  "(default: $NUMBA_CACHE_DIR, else numba's own: __pycache__ "
                                                  "beside the sources, shared by a node's workers)")
    parser.add_argument("--no-warm-up", dest="warm_up", action="store_false",
                        help="skip the numba warm-up (every trial compiles or loads the cache itself)")
    parser.add_argument("--verbose", type=int, default=1, choices=(0, 1, 2), help="Tune verbosity")
    return parser


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    args = build_parser().parse_args(argv)
    args.name = args.name or f"{args.algo}_sweep_{datetime.now().strftime('%Y%m%d-%H%M%S')}"
    return args


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    import shlex

    args = _parse_args(argv)
    try:
        if args.num_samples < 1 or args.cpus_per_trial < 1 or args.final_episodes < 1:
            raise ValueError("--num-samples, --cpus-per-trial and --final-episodes must be >= 1")
        if args.final_env:
            from pectoral_gym.registration import ENV_IDS

            if args.final_env not in ENV_IDS:
                raise ValueError(f"--final-env {args.final_env!r} is not a fish env; choose one of {sorted(ENV_IDS)}")
        space = {**(load_param_space(args.param_space) if args.param_space else {}), **parse_grid(args.grid)}
        space = space or dict(DEFAULT_SPACE)
        hyperparams = parse_overrides(args.hyperparams)
        for key, value in (("n_timesteps", args.timesteps), ("eval_freq", args.eval_freq),
                           ("eval_episodes", args.eval_episodes)):
            if value is not None:
                hyperparams[key] = int(value)
        base = {"algo": args.algo, "env_id": args.env, "seed": args.seed, "hyperparams": hyperparams,
                "hyperparams_file": str(Path(args.hyperparams_file).resolve()) if args.hyperparams_file else None,
                "cpus_per_trial": args.cpus_per_trial, "final_env": args.final_env,
                "final_episodes": args.final_episodes, "final_seed": args.final_seed,
                "final_randomize": args.final_randomize,
                "command": shlex.join(["python", "-m", "pectoral_gym.agents.studies.sweep",
                                        *(sys.argv[1:] if argv is None else argv)])}
        from pectoral_gym.agents.training.vec_adapter import make_fish_vec_env

        for point in grid_points(space):  # every grid point resolves, and its env builds, before Ray starts
            config = trial_config(args.algo, args.env, point, seed=args.seed, hyperparams=hyperparams,
                                  hyperparams_file=base["hyperparams_file"])
            if config["eval_freq"] <= 0 or config["eval_freq"] > config["n_timesteps"]:
                raise ValueError(f"eval_freq must be in [1, n_timesteps] for Tune to get reports, got "
                                 f"{config['eval_freq']} with n_timesteps {config['n_timesteps']}")
            make_fish_vec_env(config["env_id"], 1, config["env_kwargs"]).close()
    except (ValueError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        import ray  # noqa: F401
    except ImportError:
        print("error: Ray Tune is not installed: pip install 'pectoral-gym[sweep]'", file=sys.stderr)
        return 2
    folder = run_sweep(args, space, base)
    print((folder / "results.md").read_text())
    print(f"sweep folder {folder}")
    with open(folder / "results.csv") as f:
        failed = [row["trial"] for row in csv.DictReader(f) if row["status"] == "error"]
    if failed:
        print(f"error: trials {failed} failed; their errors are in their trial folders (error.txt)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
