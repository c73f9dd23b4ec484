"""Side-by-side comparison of NMPC settings on the same seeded episodes (solver options, horizons, ...).

Every variant drives the same episodes, interleaved (episode ``k`` with each variant in turn), so the
solve times of all variants share the machine's load. Solve time is the wall time of the whole
control step (screening and every solve), as in :mod:`pectoral_gym.agents.studies.benchmark`.

CLI::

    python -m pectoral_gym.agents.nmpc.compare --seeds 100-119 --env full --variants '{"sqp": {}, "exact": {"hessian":
    "exact"}}'

(``"blocks": null`` in a variant: one input per interval; ``"solver": "ipopt"`` for the interior point.)
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

import numpy as np

from pectoral_gym.versions import SIMULATION_IDS

__all__ = ["compare", "main"]

# The simulation-only ids, on which the NMPC's development rounds (docs/notes) were measured and reproduce.
_ENVS = {"averaged": (SIMULATION_IDS["averaged"], False), "full": (SIMULATION_IDS["full"], False),
         "full+rand": (SIMULATION_IDS["full"], True)}


def compare(variants: dict[str, dict[str, Any]], seeds: list[int], env: str = "full", task: str = "goal",
            max_steps: int = 240) -> dict[str, dict[str, Any]]:
    """Run every NMPC variant on the episodes ``seeds``; per variant: success, time to goal, solve times.

    Args:
        variants: Name -> :class:`pectoral_gym.agents.nmpc.controller.NMPCSettings` overrides.
        seeds: Episode seeds.
        env: ``"averaged"``, ``"full"`` or ``"full+rand"`` (``DEFAULT_RANDOMIZATION``).
        task: ``"goal"`` or ``"track"``.
        max_steps: Episode truncation.

    Returns:
        Name -> ``{"success", "time_to_goal_s", "mean_distance_cm", "p50_ms", "p95_ms", "max_ms", "failures",
        "late", "failed"}``; ``mean_distance_cm``: the distance to the target averaged over each episode's steps
        (``track``: the tracking error), then over episodes; ``failed``: ``(seed, steps, "wall" or
        "time-out")`` of each unsuccessful episode (``track``: episodes are unsuccessful by definition).
    """
    import gymnasium as gym

    import pectoral_gym  # noqa: F401 - registers the ids
    from pectoral_gym.agents.baselines import make_baseline
    from pectoral_gym.agents.training.evaluate import DEFAULT_RANDOMIZATION

    if env not in _ENVS:
        raise ValueError(f"env must be one of {list(_ENVS)}, got {env!r}")
    env_id, randomised = _ENVS[env]
    kwargs: dict[str, Any] = {"task": task}
    if randomised:
        kwargs["randomize"] = DEFAULT_RANDOMIZATION
    environment = gym.make(env_id, max_episode_steps=int(max_steps), **kwargs)
    config = environment.unwrapped.config
    controllers = {name: make_baseline("nmpc", config, **settings) for name, settings in variants.items()}
    outcomes: dict[str, list[tuple[bool, int, float, bool]]] = {name: [] for name in controllers}
    for seed in seeds:
        for name, controller in controllers.items():
            obs, _ = environment.reset(seed=int(seed))
            controller.reset()
            steps, done, info, distance, wall = 0, False, {}, 0.0, False
            while not done:
                obs, _, terminated, truncated, info = environment.step(controller.act(obs))
                steps += 1
                distance += float(info.get("distance", math.nan))
                wall |= float(info.get("reward_wall", 0.0)) != 0.0
                done = terminated or truncated
            outcomes[name].append((bool(info.get("is_success", False)), steps, distance / steps, wall))
    environment.close()
    results = {}
    for name, controller in controllers.items():
        times = np.asarray(controller.solve_times) * 1e3
        reached = [steps for ok, steps, *_ in outcomes[name] if ok]
        results[name] = {
            "episodes": len(seeds), "success": len(reached) / len(seeds),
            "time_to_goal_s": float(np.mean(reached) * config.control_period) if reached else None,
            "mean_distance_cm": float(np.mean([o[2] for o in outcomes[name]]) * 100.0),
            "p50_ms": float(np.percentile(times, 50)), "p95_ms": float(np.percentile(times, 95)),
            "max_ms": float(times.max()), "failures": int(controller.failures), "late": int(controller.late),
            "failed": [(int(seed), steps, "wall" if wall else "time-out")
                       for seed, (ok, steps, _, wall) in zip(seeds, outcomes[name], strict=True) if not ok],
        }
    return results


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m pectoral_gym.agents.nmpc.compare``."""
    from pectoral_gym.tools.cli_common import HelpFormatter, add_seeds_argument, examples, prog_name

    parser = argparse.ArgumentParser(
        prog=prog_name(None, "pectoral_gym.agents.nmpc.compare"), description=__doc__.split("\n\n")[0],
        formatter_class=HelpFormatter,
        epilog=examples("python -m pectoral_gym.agents.nmpc.compare --seeds 100-119 --env full "
                        "--variants '{\"sqp\": {}, \"exact\": {\"hessian\": \"exact\"}}'",
                        "python -m pectoral_gym.agents.nmpc.compare --seeds 100 101 --task track "
                        "--variants '{\"base\": {}}' --failed"))
    parser.add_argument("--variants", required=True, help="JSON: name -> NMPCSettings overrides")
    add_seeds_argument(parser, list(range(100, 120)), "episode seeds (default 100-119)")
    parser.add_argument("--env", default="full", choices=list(_ENVS))
    parser.add_argument("--task", default="goal", choices=("goal", "track"))
    parser.add_argument("--max-episode-steps", dest="max_steps", type=int, default=240, metavar="N",
                        help="steps per episode")
    parser.add_argument("--failed", action="store_true", help="list the unsuccessful episodes of each variant")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point: prints one markdown row per variant."""
    args = build_parser().parse_args(argv)
    results = compare(json.loads(args.variants), args.seeds, args.env, args.task, args.max_steps)
    print("| variant | episodes | success | time to goal [s] | mean distance [cm] | p50 [ms] | p95 [ms] | max [ms] "
          "| failures | late |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, r in results.items():
        ttg = "-" if r["time_to_goal_s"] is None else f"{r['time_to_goal_s']:.1f}"
        print(f"| {name} | {r['episodes']} | {r['success']:.2f} | {ttg} | {r['mean_distance_cm']:.1f} | "
              f"{r['p50_ms']:.0f} | {r['p95_ms']:.0f} | "
              f"{r['max_ms']:.0f} | {r['failures']} | {r['late']} |")
    if args.failed:
        for name, r in results.items():
            print(f"{name} failed: " + (", ".join(f"{seed} ({steps} steps, {why})" for seed, steps, why in r["failed"])
                                        or "none"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
