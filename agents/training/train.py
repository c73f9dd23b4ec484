"""Train a Stable-Baselines3 agent on a fish environment, fed from the native batched vector env.

CLI (``pectoral-train``, also ``python -m pectoral_gym.agents.training.train``)::

    pectoral-train --env PectoralFish-Averaged-v2 --algo ppo --task goal --seed 0
    pectoral-train --algo sac --hyperparams n_timesteps=5e4 learning_rate=3e-4 --env-kwargs '{"task": "track"}'

The hyperparameter files are rl-baselines3-zoo's (``pectoral_gym.agents.training.zoo_format``):
``python -m rl_zoo3.train --conf-file agents/hyperparams/ppo.yml --gym-packages pectoral_gym ...`` trains from the
same file. The periodic evaluation settings come from the file's ``pectoral_gym.agents.training.train`` section,
``--eval-freq``/``--eval-episodes`` or ``--hyperparams``.

Each run writes ``<out>/<env>/<algo>_<task>_seed<seed>_<stamp>/`` (``--out`` default ``runs``): ``model.zip``
(final), ``best_model.zip`` and ``vecnormalize.pkl`` (best on the periodic
evaluation, its observation statistics; the evaluation runs on ``eval_env``, for
``ppo.yml`` the full model: :func:`pectoral_gym.agents.training.config.evaluation_env`), ``vecnormalize_final.pkl``
(statistics of ``model.zip``), ``config.yaml`` (resolved config, with the model trained on as ``model_spec``:
:func:`pectoral_gym.agents.training.config.run_model_spec`), ``command.txt``,
``training.json`` (time, steps/s, probe time, evaluations) and TensorBoard logs in ``tb/``; with
``--keep-checkpoints`` also the policy of every periodic evaluation, ``rl_model_<steps>_steps.zip`` with
``rl_model_vecnormalize_<steps>_steps.pkl`` (SB3's ``CheckpointCallback`` names; ``load_policy`` and
``pectoral-deploy --policy`` take such a zip). The same ``--seed`` on the same machine repeats a run.

``--quick`` is a smoke run in seconds (tests, CI, trying a command): it overrides the
size of the run (:data:`QUICK`; ``n_timesteps`` 256, 2 envs, no periodic evaluation)
whatever ``--timesteps``/``--hyperparams`` say; the policy means nothing.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shlex
import sys
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import yaml

from pectoral_gym.agents.training.config import (
    algo_kwargs,
    evaluation_env,
    parse_overrides,
    resolve_config,
    run_model_spec,
)
from pectoral_gym.agents.training.run_files import keep_run_files
from pectoral_gym.agents.training.zoo_format import algo_class
from pectoral_gym.model.threads import pin_torch_threads
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name
from pectoral_gym.versions import LATEST_AVERAGED

__all__ = ["EVAL_SEED_OFFSET", "QUICK", "build_parser", "main", "make_run_dir", "train"]

#: ``--quick``: the hyperparameters it overrides, common and per algorithm family.
QUICK: dict[str, dict[str, Any]] = {
    "all": {"n_timesteps": 256, "n_envs": 2, "eval_freq": 0},
    "on_policy": {"n_steps": 64, "batch_size": 64, "n_epochs": 1},  # ppo; a2c takes n_steps only
    "off_policy": {"learning_starts": 64, "batch_size": 64, "buffer_size": 1024},  # sac, td3, ddpg
}

EVAL_SEED_OFFSET = 1_000_000  # periodic evaluations use episodes seed + this + k, apart from training resets


def make_run_dir(config: dict[str, Any], log_dir: str | Path = "runs", name: str | None = None) -> Path:
    """Create ``<log_dir>/<env>/<algo>_<task>_seed<seed>_<stamp>/`` (or ``.../<name>/``) and return it."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    name = name or f"{config['algo']}_{config['env_kwargs']['task']}_seed{config['seed']}_{stamp}"
    run_dir = Path(log_dir) / config["env_id"] / name
    run_dir.mkdir(parents=True, exist_ok=False)
    return run_dir


def _callbacks(config: dict[str, Any], run_dir: Path, progress: bool,
               on_evaluation: Callable[[dict[str, Any]], bool | None] | None = None,
               probe: Callable[[Any, dict[str, Any]], dict[str, Any] | None] | None = None):
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    from pectoral_gym.agents.training.evaluate import evaluate
    from pectoral_gym.agents.training.policy import SB3Controller

    eval_env, eval_kwargs = evaluation_env(config)

    class TrainCallback(BaseCallback):
        """Progress bar, periodic evaluation, best model kept.

        Evaluates with :func:`pectoral_gym.agents.training.evaluate.evaluate`.
        """

        def __init__(self):
            super().__init__()
            self.bar = None
            self.next_eval = config["eval_freq"] or None
            self.best: tuple[float, float] | None = None
            self.evaluations: list[dict[str, Any]] = []
            self.start = time.perf_counter()
            self.stop_requested = False
            self.probe_time = 0.0  # wall time spent in ``probe``, kept out of ``elapsed_s``

        def _on_training_start(self) -> None:
            self.start = time.perf_counter()
            self.bar = tqdm(total=config["n_timesteps"], desc=f"train {config['algo']}", unit="step",
                            disable=not progress, smoothing=0.1)

        def _on_step(self) -> bool:
            self.bar.update(max(0, min(self.model.n_envs, self.bar.total - self.bar.n)))
            if self.next_eval is not None and self.num_timesteps >= self.next_eval:
                self.next_eval += config["eval_freq"]
                self.run_evaluation()
            return not self.stop_requested

        def controller(self) -> SB3Controller:
            venv = self.model.get_env()
            rms = getattr(venv, "obs_rms", None)
            if rms is None:
                return SB3Controller(self.model, name=config["algo"])
            return SB3Controller(self.model, name=config["algo"], obs_mean=rms.mean.copy(), obs_var=rms.var.copy(),
                                 clip_obs=venv.clip_obs, epsilon=venv.epsilon)

        def run_evaluation(self) -> None:
            result = evaluate(self.controller(), eval_env, n_episodes=config["eval_episodes"],
                              seed=config["seed"] + EVAL_SEED_OFFSET, env_kwargs=eval_kwargs)
            mean_return = result.metrics["return"].mean
            success = result.metrics["success"].mean if "success" in result.metrics else 0.0
            self.logger.record("eval/mean_return", mean_return)
            if "success" in result.metrics:
                self.logger.record("eval/success_rate", success)
            if "tracking_error" in result.metrics:
                self.logger.record("eval/tracking_error", result.metrics["tracking_error"].mean)
            score = (success, mean_return)
            improved = self.best is None or score > self.best
            record = {"timesteps": int(self.num_timesteps),
                      "elapsed_s": time.perf_counter() - self.start - self.probe_time,
                      "success": success, "mean_return": mean_return, "best": improved}
            if "tracking_error" in result.metrics:
                record["tracking_error"] = result.metrics["tracking_error"].mean
            self.evaluations.append(record)
            venv = self.model.get_env()
            if improved:
                self.best = score
                self.model.save(run_dir / "best_model.zip")
                if hasattr(venv, "obs_rms"):
                    venv.save(str(run_dir / "vecnormalize.pkl"))
            if config.get("keep_checkpoints"):  # SB3 CheckpointCallback's names: load_policy finds the statistics
                record["checkpoint"] = f"rl_model_{self.num_timesteps}_steps.zip"
                self.model.save(run_dir / record["checkpoint"])
                if hasattr(venv, "obs_rms"):
                    venv.save(str(run_dir / f"rl_model_vecnormalize_{self.num_timesteps}_steps.pkl"))
            self.bar.set_postfix(eval_success=f"{success:.2f}", eval_return=f"{mean_return:.1f}")
            if probe is not None:
                probe_start = time.perf_counter()
                extra = probe(self.controller(), dict(record))
                self.probe_time += time.perf_counter() - probe_start
                if extra:
                    record["probe"] = dict(extra)
            if on_evaluation is not None and on_evaluation(dict(record)) is False:
                self.stop_requested = True  # the caller (e.g. a Tune scheduler) prunes this run

        def _on_training_end(self) -> None:
            self.bar.close()

    return TrainCallback()


@contextlib.contextmanager
def _distribution_checks_off() -> Iterator[None]:
    """torch.distributions' argument checks off while SB3 learns, restored after (the caller's setting).

    The checks only raise on invalid parameters (a NaN in the policy's output: the env refuses such an
    action with a ``ValueError`` naming it); they cost a few percent of a PPO update here, and the numbers
    are the same without them (rsl_rl turns them off for the same reason).
    """
    from torch.distributions import Distribution

    before = Distribution._validate_args
    Distribution.set_default_validate_args(False)
    try:
        yield
    finally:
        Distribution.set_default_validate_args(before)


def train(config: dict[str, Any], run_dir: str | Path, progress: bool = True, verbose: int = 0,
          torch_threads: int = 1, device: str = "cpu", command: str | None = None,
          on_evaluation: Callable[[dict[str, Any]], bool | None] | None = None,
          probe: Callable[[Any, dict[str, Any]], dict[str, Any] | None] | None = None) -> Path:
    """Train with a resolved config (:func:`pectoral_gym.agents.training.config.resolve_config`) and fill ``run_dir``.

    Args:
        config: The resolved config.
        run_dir: The run folder (created if missing).
        progress: Show a tqdm progress bar.
        verbose: SB3 verbosity.
        torch_threads: Torch CPU threads (fixed, so a seeded run repeats on the same machine).
        device: Torch device.
        command: The command line to store in ``command.txt``.
        on_evaluation: Called after every periodic evaluation with its record (``timesteps``,
            ``elapsed_s`` since training started, ``success``, ``mean_return``, ``best`` and, on
            ``track``, ``tracking_error``); returning ``False`` stops training there (the final
            model is still saved). Ray Tune's ``tune.report`` and the benchmark's time to solve use it.
        probe: Called after every periodic evaluation (before ``on_evaluation``) with the current
            policy as a deterministic controller (:class:`pectoral_gym.agents.training.policy.SB3Controller`, its
            observation statistics copied) and the record; a dict it returns is stored in the record as ``probe``
            (JSON values). Its wall time is left out of ``elapsed_s``, and it plays no part in the
            best-model selection. :class:`pectoral_gym.agents.studies.solve_time.SolveProbe` evaluates on the full
            model.

    Returns:
        The run folder.
    """
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from pectoral_gym.agents.training.vec_adapter import make_fish_vec_env

    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    seed = config["seed"]
    pin_torch_threads(torch_threads)  # numba's threads first, or their start resets torch's count
    set_random_seed(seed)
    config, recorded = keep_run_files(config, run_dir)  # the robot's files, copied: the folder is self-contained
    spec = run_model_spec(config).to_dict()  # the model trained on, explicit (run_model_spec reads it back)
    recorded_spec = dict(spec)
    if spec.get("scaling") is not None and spec["scaling"] == config["env_kwargs"].get("scaling"):
        recorded_spec["scaling"] = recorded["env_kwargs"]["scaling"]  # the kept copy, by its name in the run folder
    with open(run_dir / "config.yaml", "w") as f:
        yaml.safe_dump({**recorded, "torch_threads": int(torch_threads), "device": device,
                        "model_spec": recorded_spec}, f, sort_keys=False)
    (run_dir / "command.txt").write_text((command or shlex.join(sys.argv)) + "\n")
    venv = make_fish_vec_env(config["env_id"], config["n_envs"], config["env_kwargs"], seed=seed)
    if config.get("action_change_penalty"):
        from pectoral_gym.agents.training.smoothing import ActionChangePenalty

        # training only (pectoral_gym.agents.training.smoothing)
        venv = ActionChangePenalty(venv, config["action_change_penalty"])
    venv = VecMonitor(venv)
    normalize = config["normalize"]
    if normalize:
        venv = VecNormalize(venv, gamma=config["algo_kwargs"].get("gamma", 0.99),
                            **(normalize if isinstance(normalize, dict) else {}))
    cls = algo_class(config["algo"])
    model = cls(config["policy"], venv, seed=seed, device=device, verbose=verbose,
                tensorboard_log=str(run_dir / "tb"), **algo_kwargs(config))
    callback = _callbacks(config, run_dir, progress, on_evaluation, probe)
    start = time.perf_counter()
    with _distribution_checks_off():
        model.learn(total_timesteps=config["n_timesteps"], callback=callback, tb_log_name=config["algo"])
    train_time = time.perf_counter() - start
    evaluations = callback.evaluations
    if (config["eval_freq"] and not callback.stop_requested
            and (not evaluations or evaluations[-1]["timesteps"] < model.num_timesteps)):
        callback.run_evaluation()  # the final model competes for best too
    model.save(run_dir / "model.zip")
    if normalize:
        venv.save(str(run_dir / "vecnormalize_final.pkl"))
        if not (run_dir / "vecnormalize.pkl").exists():
            venv.save(str(run_dir / "vecnormalize.pkl"))
    stats = {"timesteps": int(model.num_timesteps), "train_time_s": train_time,
             "steps_per_s": model.num_timesteps / train_time if train_time > 0 else float("nan"),
             "probe_time_s": callback.probe_time, "evaluations": callback.evaluations}
    (run_dir / "training.json").write_text(json.dumps(stats, indent=2) + "\n")
    venv.close()
    return run_dir


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-train``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-train", "pectoral_gym.agents.training.train"),
        description=__doc__.split("\n\n")[0] + " Writes a run folder (model, best model, normalisation "
        "statistics, resolved config, command) under --out.",
        formatter_class=HelpFormatter,
        epilog=examples(f"pectoral-train --env {LATEST_AVERAGED} --algo ppo --task goal --seed 0",
                        "pectoral-train --quick --out runs_smoke",
                        "pectoral-train --algo sac --timesteps 5e4 --hyperparams learning_rate=3e-4 "
                        "--env-kwargs '{\"task\": \"track\"}'",
                        "pectoral-train --params robot.json --out runs --run-name robot"))
    parser.add_argument("--env", default=LATEST_AVERAGED, help="environment id")
    parser.add_argument("--algo", default="ppo", help="algorithm: ppo, sac, td3, a2c, ddpg")
    parser.add_argument("--task", choices=("goal", "track"), help="task (default: from the hyperparameters, else goal)")
    parser.add_argument("--seed", type=int, default=0, help="seed of everything (same seed, same run)")
    parser.add_argument("--hyperparams", nargs="*", default=[], metavar="KEY=VALUE",
                        help="override hyperparameters (YAML values; nested keys with dots)")
    parser.add_argument("--env-kwargs", default="{}", metavar="JSON", help="environment arguments (JSON object)")
    parser.add_argument("--params", metavar="JSON",
                        help="the fish's parameters file (load_params; e.g. a calibrated robot.json): the same as "
                             "--env-kwargs '{\"params\": FILE}'")
    parser.add_argument("--hyperparams-file", metavar="YAML", help="hyperparameter file (default: agents/hyperparams)")
    parser.add_argument("--timesteps", type=float, metavar="N",
                        help="training steps, a shortcut for --hyperparams n_timesteps=N (default: the file's)")
    parser.add_argument("--eval-freq", type=float, help="steps in all between evaluations, 0: none (default: file)")
    parser.add_argument("--eval-episodes", type=int, help="episodes per evaluation (default: from the file)")
    parser.add_argument("--out", default="runs", metavar="DIR", help="parent folder of the run folders")
    parser.add_argument("--run-name", help="run folder name (default: <algo>_<task>_seed<seed>_<stamp>)")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--device", default="cpu", help="torch device")
    parser.add_argument("--verbose", type=int, default=0, help="SB3 verbosity")
    parser.add_argument("--keep-checkpoints", action="store_true",
                        help="keep the policy of every periodic evaluation (rl_model_<steps>_steps.zip and its "
                             "statistics in the run folder), e.g. to select one on the robot stack")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--quick", action="store_true",
                        help="smoke run in seconds: overrides the run's size (n_timesteps 256, 2 envs, no evaluation; "
                             "see pectoral_gym.agents.training.train.QUICK); the policy means nothing")
    return parser


def quick_overrides(algo: str) -> dict[str, Any]:
    """The hyperparameters ``--quick`` sets for ``algo`` (:data:`QUICK`)."""
    algo = algo.lower()
    family = {"ppo": QUICK["on_policy"], "a2c": {"n_steps": QUICK["on_policy"]["n_steps"]}}.get(
        algo, QUICK["off_policy"])
    return {**QUICK["all"], **family}


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    args = build_parser().parse_args(argv)
    try:
        overrides = parse_overrides(args.hyperparams)
        if args.timesteps is not None:
            overrides["n_timesteps"] = int(args.timesteps)
        if args.eval_freq is not None:
            overrides["eval_freq"] = int(args.eval_freq)
        if args.eval_episodes is not None:
            overrides["eval_episodes"] = int(args.eval_episodes)
        if args.keep_checkpoints:
            overrides["keep_checkpoints"] = True
        if args.quick:
            overrides.update(quick_overrides(args.algo))
        env_kwargs = json.loads(args.env_kwargs)
        if not isinstance(env_kwargs, dict):
            raise ValueError("--env-kwargs must be a JSON object")
        if args.params is not None:
            if "params" in env_kwargs:
                raise ValueError("give the parameters once: --params or \"params\" in --env-kwargs")
            env_kwargs["params"] = args.params
        config = resolve_config(args.algo, args.env, args.seed, task=args.task, hyperparams=overrides,
                                env_kwargs=env_kwargs, hyperparams_file=args.hyperparams_file)
        from pectoral_gym.agents.training.vec_adapter import make_fish_vec_env

        make_fish_vec_env(config["env_id"], 1, config["env_kwargs"]).close()  # bad env arguments fail here, early
    except (ValueError, FileNotFoundError, json.JSONDecodeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    run_dir = make_run_dir(config, args.out, args.run_name)
    command = shlex.join(["python", "-m", "pectoral_gym.agents.training.train",
                          *(sys.argv[1:] if argv is None else argv)])
    train(config, run_dir, progress=not args.no_progress, verbose=args.verbose, torch_threads=args.torch_threads,
          device=args.device, command=command)
    stats = json.loads((run_dir / "training.json").read_text())
    print(f"trained {stats['timesteps']} steps in {stats['train_time_s']:.0f} s "
          f"({stats['steps_per_s']:.0f} steps/s); run folder {run_dir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
