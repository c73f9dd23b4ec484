"""The project's results table: every controller x task x model, plus env and SB3 training throughput.

Controllers: the baselines of :mod:`pectoral_gym.agents.baselines` (``random``, ``hand``, ``nmpc``) and any
trained policies given with ``--policy``. Each runs on both tasks (``goal``, ``track``) and three
settings: the averaged model, the full model, and the full model with per-episode parameter
randomisation (:data:`pectoral_gym.agents.training.evaluate.DEFAULT_RANDOMIZATION`), through
:func:`pectoral_gym.agents.training.evaluate.evaluate` (seeded: episode ``k`` starts from ``seed + k`` for every
controller). Also measured: env step rates (:func:`pectoral_gym.tools.bench.run_benchmark`) and the
steps per second of a short Stable-Baselines3 PPO ``learn()`` on the averaged vector env, and the
time to solve: per training seed, the wall time until the demo's PPO first reaches 0.95 success on
the full model on held-out episodes (:mod:`pectoral_gym.agents.studies.solve_time`; ``--full`` runs seeds 0-4).
Two more columns run the robot stack on the emulated robot in lockstep simulated time (the installed robot stack,
:mod:`pectoral_gym.agents.studies.robot_stack`: ``pectoral_gym.hardware.studies.deployment``): ``robot`` (ideal radio
and camera) and ``robot+degraded`` (its ``DEGRADED`` conditions), for the baselines the deploy can drive and the
trained policies on their own task.

CLI (``pectoral-benchmark``, also ``python -m pectoral_gym.agents.studies.benchmark``)::

    pectoral-benchmark --quick                      # a few minutes on 2 cores
    pectoral-benchmark --full --policy runs/PectoralFish-Averaged-v2/ppo_goal_seed0_...
    pectoral-benchmark --quick --controller hand nmpc --out bench_quick
    pectoral-benchmark --quick --controller hand --solve-seeds 0 1 --solve-timesteps 4e5
    pectoral-benchmark --quick --env robot robot+degraded --no-throughput --solve-seeds

Writes ``benchmark.md``, ``benchmark.json`` and ``benchmark.png`` into ``--out``. The columns, tasks, sizes and
presets: :mod:`pectoral_gym.agents.studies.benchmark_settings`; the report:
:mod:`pectoral_gym.agents.studies.benchmark_report`.
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.studies.benchmark_report import plot_report, to_markdown, write_outputs
from pectoral_gym.agents.studies.benchmark_settings import (
    ALL_ENVS,
    BASELINE_NAMES,
    ENVS,
    PRESETS,
    TASKS,
    VERSIONS,
    BenchmarkSettings,
    env_id,
)
from pectoral_gym.agents.studies.robot_stack import ROBOT_COLUMNS, RobotStackNotFoundError, robot_stack
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name

__all__ = ["ALL_ENVS", "ENVS", "PRESETS", "VERSIONS", "BenchmarkSettings", "build_parser", "env_id", "main",
           "plot_report", "run_benchmark", "to_markdown", "write_outputs"]

def _baseline_factory(name: str, cell_env: str, env_kwargs: dict[str, Any], settings: BenchmarkSettings,
                      built: dict[tuple[str, str], Any]):
    """A controller (NMPC: one instance, one episode at a time) or a factory of controllers (one per env slot).

    NMPC plans with the nominal parameters whether or not the env randomises them, so one built
    problem per (env id, task) serves both; ``built`` caches it.
    """
    from pectoral_gym.agents.baselines import make_baseline
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.registration import registered_settings

    config = EnvConfig(**registered_settings(cell_env, env_kwargs))
    if name == "nmpc":
        key = (cell_env, config.task)
        if key not in built:
            built[key] = make_baseline("nmpc", config, **settings.nmpc)
        return built[key]
    return lambda: make_baseline(name, config)


def _nmpc_stats(times: list[float], failures: int, late: int = 0) -> dict[str, Any] | None:
    """Wall time per control step (all solves of the step): mean, p50, p95, max [ms]; failed and late steps."""
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        return None
    return {"solves": int(times.size), "mean_ms": float(times.mean() * 1e3),
            "p50_ms": float(np.percentile(times, 50) * 1e3), "p95_ms": float(np.percentile(times, 95) * 1e3),
            "max_ms": float(times.max() * 1e3), "failures": int(failures), "late": int(late)}


def _cell(result: Any, label: str, solver: dict[str, Any] | None) -> dict[str, Any]:
    data = result.to_dict(per_episode=False)
    data["env"] = label
    if solver is not None:
        data["solver"] = solver
    return data


def measure_training(steps: int, seed: int = 0, version: str = VERSIONS[0]) -> dict[str, Any]:
    """Steps per second of PPO ``learn()`` on the averaged vector env with the project's PPO hyperparameters.

    ``version``: of ``PectoralFish-Averaged`` (:data:`VERSIONS`).

    The model is built first (not timed); the timed part is ``learn(steps)``: env stepping through the
    SB3 ``VecEnv`` adapter, rollout collection and the gradient updates, on one torch thread.
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from pectoral_gym.agents.training.config import algo_kwargs, resolve_config
    from pectoral_gym.agents.training.vec_adapter import make_fish_vec_env
    from pectoral_gym.model.threads import pin_torch_threads

    averaged_id = env_id("averaged", version)
    config = resolve_config("ppo", averaged_id, seed)
    pin_torch_threads(1)
    venv = make_fish_vec_env(averaged_id, config["n_envs"], config["env_kwargs"], seed=seed)
    normalize = config.get("normalize")
    if normalize:
        venv = VecNormalize(venv, **(normalize if isinstance(normalize, dict) else {}))
    kwargs = algo_kwargs(config)
    policy = kwargs.pop("policy", "MlpPolicy")
    model = PPO(policy, venv, seed=seed, device="cpu", verbose=0, **kwargs)
    rollout = int(model.n_steps) * int(venv.num_envs)
    steps = max(1, math.ceil(int(steps) / rollout)) * rollout  # whole rollouts: schedules stay in [0, 1]
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    elapsed = time.perf_counter() - start
    venv.close()
    done = int(model.num_timesteps)
    return {"algo": "ppo", "env_id": averaged_id, "n_envs": config["n_envs"], "timesteps": done,
            "seconds": elapsed, "steps_per_s": done / elapsed, "torch_threads": 1}


def run_benchmark(settings: BenchmarkSettings, controllers: tuple[str, ...] = BASELINE_NAMES,
                  policies: tuple[str, ...] = (), envs: tuple[str, ...] = ALL_ENVS, tasks: tuple[str, ...] = TASKS,
                  throughput: bool = True, progress: Callable[[str], None] | None = None,
                  solve_out: str | Path = "benchmark/time_to_solve", solve_jobs: int = 1,
                  robot_out: str | Path = "benchmark/robot") -> dict[str, Any]:
    """Run the benchmark and return a JSON-ready dict.

    Args:
        settings: Sizes (:data:`PRESETS`).
        controllers: Baseline names to include.
        policies: Run folders or ``.zip`` files of trained policies
            (:func:`pectoral_gym.agents.training.policy.load_policy`).
        envs: Labels of :data:`ALL_ENVS` to include (simulated settings and robot-stack columns).
        tasks: Tasks to include.
        throughput: Measure env and training throughput.
        progress: Called with a short message before each cell.
        solve_out: Folder of the time-to-solve training runs.
        solve_jobs: Time-to-solve runs at once (each in its own process; the wall times compete for cores).
        robot_out: Folder of the robot-stack runs' logs (one deploy output folder per cell).

    Returns:
        ``{"settings", "cells": [...], "env_throughput", "training_throughput", "time_to_solve", "errors",
        "environment"}``;
        a cell holds ``controller, env, env_id, task, n_episodes, metrics`` (mean and CI per metric) and,
        for NMPC, ``solver`` (solve-time statistics); a robot-stack cell also ``robot``
        (the robot stack's ``robot_cell``, :mod:`pectoral_gym.hardware.studies.deployment`).

    Raises:
        ValueError: For an unknown controller, env label or task.
    """
    from pectoral_gym.agents.training.evaluate import DEFAULT_RANDOMIZATION, evaluate, trained_env_kwargs

    unknown = [c for c in controllers if c not in BASELINE_NAMES] + [e for e in envs if e not in ALL_ENVS]
    unknown += [t for t in tasks if t not in TASKS]
    if unknown:
        raise ValueError(f"unknown controllers/envs/tasks {unknown}; choose from {BASELINE_NAMES}, {ALL_ENVS}, "
                         f"{TASKS}")
    say = progress or (lambda _msg: None)
    loaded, paths = {}, {}
    for path in policies:
        from pectoral_gym.agents.training.policy import load_policy

        name = Path(path).name.removesuffix(".zip")
        loaded[name], paths[name] = load_policy(path), path
    cells, errors = [], {}
    built: dict[tuple[str, str], Any] = {}
    for task in tasks:
        for label in envs:
            if label in ROBOT_COLUMNS:
                policy_paths = {name: (loaded[name], paths[name]) for name in loaded}
                cells += robot_stack().robot_cells(label, task, controllers, policy_paths,
                                                   settings.robot_episodes.get(task, 0), settings.seed,
                                                   Path(robot_out), say, errors,
                                                   max_steps=settings.robot_max_steps or settings.max_episode_steps)
                continue
            cell_env, randomised = env_id(label, settings.version), ENVS[label][1]
            env_kwargs: dict[str, Any] = {"task": task}
            if randomised:
                env_kwargs["randomize"] = dict(DEFAULT_RANDOMIZATION)
            eval_kwargs = dict(env_kwargs)
            if settings.max_episode_steps is not None:
                eval_kwargs["max_episode_steps"] = int(settings.max_episode_steps)
            entries = [(name, None) for name in controllers] + [(name, policy) for name, policy in loaded.items()]
            for name, policy in entries:
                n = settings.nmpc_episodes.get(task, settings.episodes) if name == "nmpc" else settings.episodes
                if n < 1:
                    continue
                say(f"{name} on {label} ({cell_env}), {task}, {n} episodes")
                try:
                    controller = policy if policy is not None else _baseline_factory(name, cell_env, env_kwargs,
                                                                                    settings, built)
                    solves, failures = len(getattr(controller, "solve_times", [])), getattr(controller, "failures", 0)
                    late = getattr(controller, "late", 0)
                    # A policy keeps the model settings it trained with (transitions, observe_fins); the cell
                    # decides task and randomisation.
                    kwargs = eval_kwargs if policy is None else {**trained_env_kwargs(paths[name], cell_env),
                                                                 **eval_kwargs}
                    result = evaluate(controller, cell_env, n_episodes=n, seed=settings.seed, env_kwargs=kwargs)
                except Exception as error:  # noqa: BLE001 - one failing cell must not lose the others
                    errors[f"{name}/{label}/{task}"] = f"{type(error).__name__}: {error}"
                    continue
                result.controller = name
                solver = None
                if name == "nmpc":
                    solver = _nmpc_stats(controller.solve_times[solves:], controller.failures - failures,
                                         controller.late - late)
                cells.append(_cell(result, label, solver))
    env_rates = training = None
    if throughput:
        say("env throughput (pectoral_gym.tools.bench)")
        try:
            from pectoral_gym.tools.bench import run_benchmark as env_benchmark

            env_rates = env_benchmark(steps=settings.env_steps, vector_steps=settings.vector_steps,
                                      repeats=settings.repeats, seed=settings.seed)
        except Exception as error:  # noqa: BLE001
            errors["env_throughput"] = f"{type(error).__name__}: {error}"
        if settings.train_steps > 0:
            say(f"SB3 training throughput (PPO, {settings.train_steps} steps)")
            try:
                training = measure_training(settings.train_steps, settings.seed, settings.version)
            except Exception as error:  # noqa: BLE001
                errors["training_throughput"] = f"{type(error).__name__}: {error}"
    solve = None
    if settings.solve_seeds:
        say(f"time to solve (PPO, full >= 0.95), seeds {list(settings.solve_seeds)}")
        try:
            from pectoral_gym.agents.studies.solve_time import measure_time_to_solve

            solve = measure_time_to_solve(list(settings.solve_seeds), solve_out, settings.solve_timesteps,
                                          settings.solve_episodes, settings.solve_episodes, jobs=solve_jobs)
        except Exception as error:  # noqa: BLE001
            errors["time_to_solve"] = f"{type(error).__name__}: {error}"
    return {"settings": asdict(settings), "controllers": list(controllers) + list(loaded), "envs": list(envs),
            "cells": cells, "env_throughput": env_rates, "training_throughput": training, "time_to_solve": solve,
            "errors": errors,
            "environment": {"python": platform.python_version(), "machine": platform.machine(),
                            "time": time.strftime("%Y-%m-%d %H:%M:%S")}}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-benchmark``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-benchmark", "pectoral_gym.agents.studies.benchmark"),
        description=__doc__.split("\n\n")[0] + " Writes benchmark.md, benchmark.json and benchmark.png into --out.",
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-benchmark --quick",
                        "pectoral-benchmark --full --policy demo_out/run",
                        "pectoral-benchmark --quick --controller hand nmpc --out bench_quick",
                        "pectoral-benchmark --quick --env robot robot+degraded --no-throughput --solve-seeds"))
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_const", const="quick", dest="preset",
                      help="small sizes, a few minutes on 2 cores (the default)")
    size.add_argument("--full", action="store_const", const="full", dest="preset",
                      help="the real table: 100 episodes per cell (NMPC: 100 goal, 10 track)")
    parser.add_argument("--policy", nargs="+", default=[], metavar="RUN", help="trained policies (run folder or .zip)")
    parser.add_argument("--controller", nargs="*", dest="controllers", default=list(BASELINE_NAMES),
                        choices=BASELINE_NAMES, metavar="NAME",
                        help=f"baseline controllers to include: {', '.join(BASELINE_NAMES)}")
    parser.add_argument("--env", nargs="+", dest="envs", default=list(ALL_ENVS), choices=list(ALL_ENVS),
                        metavar="SETTING", help=f"model settings, one or more of {', '.join(ALL_ENVS)} "
                        "(robot, robot+degraded: the robot stack on the emulated robot)")
    parser.add_argument("--env-version", dest="version", choices=VERSIONS, default=VERSIONS[0],
                        help="registered env version of the simulated columns (v0: the tables measured before v1)")
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS, help="tasks")
    parser.add_argument("--episodes", type=int, help="override: episodes per cell (random, hand, policies)")
    parser.add_argument("--nmpc-episodes", type=int, nargs=2, metavar=("GOAL", "TRACK"),
                        help="override: NMPC episodes per cell for goal and track")
    parser.add_argument("--robot-episodes", type=int, nargs=2, metavar=("GOAL", "TRACK"),
                        help="override: episodes per robot-stack cell for goal and track")
    parser.add_argument("--seed", type=int, help="override: episode k is reset with seed + k")
    parser.add_argument("--max-episode-steps", type=int,
                        help="override: truncate episodes (robot-stack ones too) after this many steps")
    parser.add_argument("--no-throughput", action="store_true", help="skip env and training throughput")
    parser.add_argument("--solve-seeds", type=int, nargs="*", metavar="SEED",
                        help="override: training seeds of the time to solve (none: skip; --full: 0-4)")
    parser.add_argument("--solve-timesteps", type=float, help="override: training budget per time-to-solve seed")
    parser.add_argument("--solve-episodes", type=int, help="override: episodes per time-to-solve probe")
    parser.add_argument("--solve-jobs", type=int, default=1, help="time-to-solve runs at once")
    parser.add_argument("--no-plots", action="store_true", help="skip benchmark.png")
    parser.add_argument("--out", default="benchmark", metavar="DIR", help="output folder")
    return parser


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    args = build_parser().parse_args(argv)
    args.preset = args.preset or "quick"
    return args


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    args.preset = args.preset or "quick"
    settings = replace(PRESETS[args.preset], version=args.version)
    if args.episodes is not None:
        settings = replace(settings, episodes=args.episodes)
    if args.nmpc_episodes is not None:
        settings = replace(settings, nmpc_episodes=dict(zip(TASKS, args.nmpc_episodes, strict=True)))
    if args.robot_episodes is not None:
        settings = replace(settings, robot_episodes=dict(zip(TASKS, args.robot_episodes, strict=True)))
    if args.seed is not None:
        settings = replace(settings, seed=args.seed)
    if args.max_episode_steps is not None:
        settings = replace(settings, max_episode_steps=args.max_episode_steps, robot_max_steps=None)  # for all cells
    if args.solve_seeds is not None:
        settings = replace(settings, solve_seeds=tuple(args.solve_seeds))
    if args.solve_timesteps is not None:
        settings = replace(settings, solve_timesteps=int(args.solve_timesteps))
    if args.solve_episodes is not None:
        settings = replace(settings, solve_episodes=args.solve_episodes)
    if settings.episodes < 1 or min(settings.nmpc_episodes.values()) < 0 or (settings.max_episode_steps or 1) < 1 \
            or min(settings.robot_episodes.values()) < 0:
        parser.error("--episodes and --max-episode-steps must be >= 1, --nmpc-episodes and --robot-episodes >= 0")
    if settings.solve_episodes < 1 or args.solve_jobs < 1 or len(set(settings.solve_seeds)) != len(
            settings.solve_seeds):
        parser.error("--solve-episodes and --solve-jobs must be >= 1, --solve-seeds distinct")
    from tqdm.auto import tqdm

    robot = [e for e in args.envs if e in ROBOT_COLUMNS]
    try:
        driven = robot_stack().ROBOT_CONTROLLERS if robot else ()
    except RobotStackNotFoundError as error:
        parser.error(f"--env {' '.join(robot)}: {error}")
    robot_rows = len([c for c in args.controllers if c in driven]) + len(args.policy)  # at most
    n_cells = len(args.tasks) * ((len(args.envs) - len(robot)) * (len(args.controllers) + len(args.policy))
                                 + len(robot) * robot_rows)
    n_items = n_cells + (0 if args.no_throughput else 2) + (1 if settings.solve_seeds else 0)
    bar = tqdm(total=n_items, desc=f"benchmark ({args.preset})")

    calls = 0

    def progress(message: str) -> None:
        nonlocal calls
        if calls:
            bar.update(1)  # the previous item is done
        calls += 1
        bar.set_postfix_str(message[:60])

    try:
        report = run_benchmark(settings, tuple(args.controllers), tuple(args.policy), tuple(args.envs),
                               tuple(args.tasks), throughput=not args.no_throughput, progress=progress,
                               solve_out=Path(args.out) / "time_to_solve", solve_jobs=args.solve_jobs,
                               robot_out=Path(args.out) / "robot")
    except (ValueError, FileNotFoundError) as error:
        bar.close()
        print(f"error: {error}")
        return 2
    bar.update(bar.total - bar.n)
    bar.close()
    report["preset"] = args.preset
    paths = write_outputs(report, args.out, plots=not args.no_plots)
    print(to_markdown(report))
    print("wrote " + ", ".join(str(p) for p in paths))
    return 1 if report["errors"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
