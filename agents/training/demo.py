"""End-to-end demo: train PPO on the averaged model, evaluate on the averaged and the full model, write a report.

CLI (``pectoral-demo``, also ``python -m pectoral_gym.agents.training.demo``)::

    pectoral-demo                 # a few minutes on 2 CPU cores
    pectoral-demo --quick         # smoke run, seconds
    pectoral-demo --out demo_out --timesteps 1e6 --episodes 200
    pectoral-demo --robot-episodes 0                # no robot-stack episodes

Writes ``<out>/report.md`` (results table, training figures), ``<out>/results.json``,
``<out>/trajectories.png`` and the training run folder ``<out>/run/``
(``pectoral-evaluate --policy <out>/run`` evaluates it again). The policy then
drives the emulated robot through the whole robot stack (radio link and firmware rules, camera, tracker,
observer, safety supervisor) in lockstep, ``--robot-episodes`` seeded episodes
(``pectoral-deploy --emulate --lockstep``, its log in ``<out>/robot/``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

from pectoral_gym.agents.studies.robot_stack import RobotStackNotFoundError, prepared_workers
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name
from pectoral_gym.versions import LATEST_AVERAGED, LATEST_FULL

__all__ = ["build_parser", "main", "run_demo"]

TRAIN_ENV = LATEST_AVERAGED
EVAL_ENVS = (LATEST_AVERAGED, LATEST_FULL)
EVAL_SEED = 10_000  # evaluation episodes k use seed EVAL_SEED + k (training uses seed + env index)
QUICK = {"n_timesteps": 1024, "n_envs": 8, "n_steps": 64, "batch_size": 128, "n_epochs": 1, "eval_freq": 0}
ROBOT_EPISODES = 20  # robot-stack episodes (lockstep emulation) by default; 2 of at most 40 steps with --quick
# the robot-stack figures results.json keeps (the robot stack's run_robot_stack returns more)
ROBOT_SUMMARY = ("episodes", "seed", "success", "safety_stops", "wall_time_s", "command")
ROBOT_JOBS = min(2, os.cpu_count() or 1)  # robot-stack episodes at once (worker processes; same results for any)


def run_demo(out: str | Path, quick: bool = False, seed: int = 0, timesteps: int | None = None,
             episodes: int | None = None, task: str = "goal", progress: bool = True,
             robot_episodes: int | None = None, robot_jobs: int = ROBOT_JOBS) -> dict[str, Any]:
    """Train, evaluate and report (see the module docstring); returns the results dict written to JSON.

    ``robot_episodes``: episodes through the robot stack on the emulated robot (``None``: :data:`ROBOT_EPISODES`,
    2 with ``quick``; 0: none); ``robot_jobs`` of them at once, each in a worker process (the deploy's ``--jobs``;
    the same results for any number).
    """
    from pectoral_gym.agents.training.config import resolve_config
    from pectoral_gym.agents.training.evaluate import format_table

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    overrides: dict[str, Any] = dict(QUICK) if quick else {}
    if timesteps is not None:
        overrides["n_timesteps"] = int(timesteps)
    episodes = int(episodes or (5 if quick else 100))
    config = resolve_config("ppo", TRAIN_ENV, seed, task=task, hyperparams=overrides)
    run_dir = out / "run"
    if run_dir.exists():
        raise FileExistsError(f"{run_dir} exists; choose another --out or remove it")
    robot_episodes = (2 if quick else ROBOT_EPISODES) if robot_episodes is None else int(robot_episodes)
    stack = None
    if robot_episodes:  # found before the training, which it would otherwise follow with an error
        from pectoral_gym.agents.studies.robot_stack import robot_stack

        stack = robot_stack()
    start = time.perf_counter()
    with contextlib.ExitStack() as ahead:  # the robot stack's workers, ended on every path out
        workers = None
        if stack is not None and robot_jobs > 1:  # their start-up on the core the training leaves idle
            workers = ahead.enter_context(prepared_workers(stack, robot_jobs))
        results, robot, training = _train_and_test(config, run_dir, out, episodes, progress, stack, workers,
                                                   robot_episodes, robot_jobs, quick)
    total = time.perf_counter() - start
    summary = {
        "train_env": TRAIN_ENV, "task": task, "seed": seed, "quick": quick, "run_dir": str(run_dir),
        "timesteps": training["timesteps"], "train_time_s": training["train_time_s"],
        "train_steps_per_s": training["steps_per_s"], "total_time_s": total,
        "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine()},
        "evaluations": [r.to_dict(per_episode=False) for r in results],
        "robot_stack": robot,
    }
    (out / "results.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "report.md").write_text(_report(summary, format_table(results), config))
    return summary


def _train_and_test(config: dict[str, Any], run_dir: Path, out: Path, episodes: int, progress: bool, stack: Any,
                    workers: Any, robot_episodes: int, robot_jobs: int,
                    quick: bool) -> tuple[list[Any], dict[str, Any] | None, dict[str, Any]]:
    """Train, evaluate on :data:`EVAL_ENVS`, run the robot stack (``stack``, if any, with ``workers`` if any).

    Returns the evaluations, the robot-stack figures (:data:`ROBOT_SUMMARY`, or ``None``) and ``training.json``.
    """
    from pectoral_gym.agents.training.evaluate import evaluate, plot_trajectories, write_json
    from pectoral_gym.agents.training.policy import load_policy
    from pectoral_gym.agents.training.train import train

    train(config, run_dir, progress=progress,
          command=" ".join(["python", "-m", "pectoral_gym.agents.training.demo", *sys.argv[1:]]))
    training = json.loads((run_dir / "training.json").read_text())
    policy = load_policy(run_dir)
    policy.name = f"ppo ({TRAIN_ENV.split('-')[1].lower()})"
    eval_kwargs = {k: v for k, v in config["env_kwargs"].items() if k != "randomize"}
    results = []
    for env_id in EVAL_ENVS:
        result = evaluate(policy, env_id, n_episodes=episodes, seed=EVAL_SEED, env_kwargs=eval_kwargs,
                          progress=progress)
        write_json(result, out / f"eval_{env_id}.json")
        results.append(result)
    plot_trajectories(results, out / "trajectories.png", max_episodes=12)
    robot = None
    if stack is not None:
        run = stack.run_robot_stack(out / "robot", robot_episodes, EVAL_SEED, policy=run_dir,
                                    max_steps=40 if quick else None, progress=progress, jobs=robot_jobs,
                                    **({} if workers is None else {"workers": workers}))
        robot = {key: run[key] for key in ROBOT_SUMMARY}
    return results, robot, training


def _robot_lines(robot: dict[str, Any] | None) -> list[str]:
    if not robot:
        return []
    s = robot["success"]
    stops = ", ".join(f"{n} {reason}" for reason, n in sorted(robot["safety_stops"].items())) or "none"
    return [f"On the emulated robot through the whole robot stack (radio link and firmware rules, camera, tracker, "
            f"observer, safety supervisor), in lockstep: success **{s['mean']:.2f}** [{s['ci_low']:.2f}, "
            f"{s['ci_high']:.2f}] "
            f"over {robot['episodes']} seeded episodes (seed {robot['seed']}); safety stops: {stops} "
            f"({robot['wall_time_s']:.0f} s; `{robot['command']}`, log in `robot/`).", ""]


def _report(summary: dict[str, Any], table: str, config: dict[str, Any]) -> str:
    lines = [
        "# pectoral-gym demo: trained on the averaged model, tested on the full model",
        "",
        f"PPO trained on `{summary['train_env']}` (task `{summary['task']}`, seed {summary['seed']}) for "
        f"{summary['timesteps']} steps in {summary['train_time_s']:.0f} s "
        f"({summary['train_steps_per_s']:.0f} env steps/s including learning); whole demo "
        f"{summary['total_time_s']:.0f} s. Wall-clock figures depend on the machine and its load.",
        "",
        f"Evaluation: {summary['evaluations'][0]['n_episodes']} seeded episodes per env (the same starts and goals "
        "on both models), deterministic policy. Mean [95 % bootstrap interval]:",
        "",
        table,
        "",
        *_robot_lines(summary.get("robot_stack")),
        "![trajectories](trajectories.png)",
        "",
        "Metrics: `success` fraction of episodes that reached the goal radius; `time_to_goal` [s] over the "
        "successful ones; `path_length` [m]; `fin_work` [J] hydrodynamic fin work per episode as the env prices "
        "it (the commanded patterns' regular beats); `swept_work` [J] over the strokes actually swept "
        "(transitional ones too); `return` sum of "
        "rewards. Definitions in `agents/training/metrics.py`; per-env JSON next to this report.",
        "",
        f"Going further: `pectoral-train --env {LATEST_AVERAGED} --algo ppo "
        "--task goal --timesteps 2e6`, then `pectoral-evaluate --policy runs/... "
        f"--env {LATEST_FULL} --randomize`; `pectoral-benchmark` for every "
        "controller; see `docs/agents.md`.",
        "",
        f"Hyperparameters: `{json.dumps(config['algo_kwargs'])}`, n_envs {config['n_envs']}, "
        f"normalize {json.dumps(config['normalize'])}.",
        "",
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-demo``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-demo", "pectoral_gym.agents.training.demo"),
        description=__doc__.split("\n\n")[0] + " Writes report.md, results.json, trajectories.png and the run "
        "folder into --out; then drives the emulated robot through the robot stack (--robot-episodes).",
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-demo", "pectoral-demo --quick --out demo_quick",
                        "pectoral-demo --out demo_out --timesteps 1e6 --episodes 200",
                        "pectoral-demo --robot-episodes 0"))
    parser.add_argument("--out", default="demo_out", metavar="DIR", help="output folder")
    parser.add_argument("--quick", action="store_true", help="smoke run: tiny training, 5 episodes")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--timesteps", type=float, metavar="N",
                        help="training steps (default: agents/hyperparams/ppo.yml)")
    parser.add_argument("--episodes", type=int, metavar="N", help="evaluation episodes per env (default 100, quick 5)")
    parser.add_argument("--task", choices=("goal", "track"), default="goal", help="task")
    parser.add_argument("--robot-episodes", type=int, default=None, metavar="N",
                        help=f"episodes on the emulated robot through the robot stack, lockstep (default "
                             f"{ROBOT_EPISODES}, quick 2; 0: none)")
    parser.add_argument("--jobs", type=int, default=ROBOT_JOBS, metavar="J",
                        help="robot-stack episodes at once, each in a worker process (the same results for any J; "
                             "default: 2, or the number of CPUs if fewer)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    return parser


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    if args.robot_episodes is not None and args.robot_episodes < 0:
        parser.error(f"--robot-episodes must be >= 0, got {args.robot_episodes}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    args = _parse_args(argv)
    try:
        summary = run_demo(args.out, quick=args.quick, seed=args.seed, timesteps=args.timesteps,
                           episodes=args.episodes, task=args.task, progress=not args.no_progress,
                           robot_episodes=args.robot_episodes, robot_jobs=args.jobs)
    except (FileExistsError, ValueError, RobotStackNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(Path(args.out, "report.md").read_text())
    print(f"demo finished in {summary['total_time_s']:.0f} s; report in {Path(args.out) / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
