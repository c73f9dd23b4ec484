"""How often a controller would be stopped by the robot's geofence: the stopping band on the true simulated state.

On the robot the safety supervisor stops the fish once any part of its outline is closer to a wall than
it needs to coast to a stop (``pectoral_gym.hardware.safety.geofence.Geofence``; the same rule:
:func:`pectoral_gym.agents.controllers.stop_band.band_violation`). It checks every camera frame, so this
study checks the rule on the model's true state every ``check_period`` of simulated time, not only at the
control steps: the env runs at ``control_period / substeps`` with each action held for ``substeps`` steps
(the same fin commands, latched by the same rule); the controller sees an observation every control
period whose velocities are the mean over that period (the mean of its substeps' means), as the env's
own observation is. A goal counts as reached only at a control step, as in the env.

Per episode: success, the first band entry (a would-be geofence stop), time to goal, wall contact.

Example (the figures in ``docs/notes/2026-12-03-robot-stack-rounds.md``, hand baseline)::

    python -m pectoral_gym.agents.controllers.band_study --controller hand --seeds 1000-1099
    python -m pectoral_gym.agents.controllers.band_study --controller hand --seeds 1000-1099 --goal-inset 0.3
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the envs
from pectoral_gym.agents.controllers.stop_band import StopBand, band_violation
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.observation import (
    OBS_COS_PSI,
    OBS_SIN_PSI,
    OBS_TARGET_X,
    OBS_TARGET_Y,
    OBS_VELOCITY,
    OBS_X,
    OBS_Y,
)
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model.tank import ROBOT_STOP_RULE, StopRule
from pectoral_gym.versions import SIMULATION_IDS

__all__ = ["EpisodeRecord", "goal_in_inset", "run_episode", "summarize"]


@dataclass
class EpisodeRecord:
    """One episode of :func:`run_episode`.

    Attributes:
        seed: Reset seed.
        success: Goal reached (at a control step).
        time: Episode length [s] (to the goal if reached).
        band_time: Time of the first band entry [s] (``None``: never entered).
        success_before_band: Goal reached before any band entry (what the robot would score).
        wall: A wall contact ended the episode.
        worst: Largest band shortfall seen, ``sqrt`` of :func:`band_violation` [m].
    """

    seed: int
    success: bool
    time: float
    band_time: float | None
    success_before_band: bool
    wall: bool
    worst: float


def goal_in_inset(seed: int, start: tuple[float, float], inset: float) -> tuple[float, float]:
    """A goal drawn as the env draws it (``kernels.draw_episode``) but ``inset`` [m] from the walls.

    Uniform in the inset tank at ``GOAL_MIN_DISTANCE``-``GOAL_MAX_DISTANCE`` from ``start``, by rejection,
    from a generator of its own seeded with ``(seed, 1)`` (the env's draws stay as they are).
    """
    rng = np.random.default_rng([seed, 1])
    for _ in range(10_000):
        gx = inset + rng.random() * (tk.TANK_X - 2.0 * inset)
        gy = inset + rng.random() * (tk.TANK_Y - 2.0 * inset)
        if tk.GOAL_MIN_DISTANCE <= math.hypot(gx - start[0], gy - start[1]) <= tk.GOAL_MAX_DISTANCE:
            return gx, gy
    raise RuntimeError(f"no goal {inset} m from the walls within reach of {start}")  # pragma: no cover


def _cos_sin(angle: float) -> tuple[float, float]:
    return math.cos(angle), math.sin(angle)


def _aim_observation(obs: np.ndarray, state: np.ndarray, goal: tuple[float, float]) -> None:
    """Write the body-frame target of ``goal`` into ``obs`` in place (the env shows a moved goal one step late)."""
    c, s = math.cos(state[2]), math.sin(state[2])
    ex, ey = goal[0] - state[0], goal[1] - state[1]
    obs[OBS_TARGET_X], obs[OBS_TARGET_Y] = c * ex + s * ey, -s * ex + c * ey


def run_episode(make_controller: Callable[[EnvConfig], object] | None, seed: int, env_id: str = SIMULATION_IDS["full"],
                substeps: int = 5, goal_inset: float | None = None, band: StopRule = ROBOT_STOP_RULE,
                max_steps: int = 240, env_kwargs: dict | None = None, controller=None,
                start: tuple[float, float, float] | None = None,
                goal: tuple[float, float] | None = None) -> EpisodeRecord:
    """Run one seeded goal episode and check the stopping band every ``control_period / substeps``.

    Args:
        make_controller: ``config -> controller`` (called with the env's own config, control period included).
        seed: Reset seed (the env's start and goal; the controller is reset with it).
        env_id: Registered env id; the default is simulation-only (no band of its own ends the episode, so the
            study sees every entry into ``band``).
        substeps: Band checks per control period.
        goal_inset: Redraw the goal this far from the walls [m] (:func:`goal_in_inset`); ``None``: the env's.
        band: The band's :class:`~pectoral_gym.model.tank.StopRule` (default: the robot's supervisor's).
        max_steps: Control steps before truncation (the registry's 240).
        env_kwargs: More env arguments (``task`` is ``goal``).
        controller: A controller built already for ``config`` (then ``make_controller`` is not called).
        start: Place the fish at rest at ``(X, Y, psi)`` [m, m, rad] after the reset (a scripted situation).
        goal: Place the goal at ``(X, Y)`` [m] (instead of the drawn one and of ``goal_inset``).

    Returns:
        The episode's :class:`EpisodeRecord`.
    """
    kwargs = dict(env_kwargs or {})
    config = gym.make(env_id, **kwargs).unwrapped.config
    period = config.control_period
    env = gym.make(env_id, **{**kwargs, "control_period": period / substeps}).unwrapped
    ctrl = controller if controller is not None else make_controller(config)
    stop_band = StopBand.from_params(config.params, band)
    obs, info = env.reset(seed=seed)
    ctrl.reset(seed)
    if start is not None:
        env.set_fish_state([*start, 0.0, 0.0, 0.0])
        obs[OBS_X], obs[OBS_Y], obs[OBS_COS_PSI], obs[OBS_SIN_PSI] = start[0], start[1], *_cos_sin(start[2])
    state = env.fish_state
    if goal is None and goal_inset is not None:
        goal = goal_in_inset(seed, (float(state[0]), float(state[1])), goal_inset)
    if goal is not None:
        env.set_target(*goal)
    _aim_observation(obs, state, env.target)
    band_time, worst, wall, success, t = None, 0.0, False, False, 0.0
    for step in range(max_steps):
        action = ctrl.act(obs)
        velocity = np.zeros(3)
        for sub in range(substeps):
            obs, _, terminated, _, info = env.step(action)
            velocity += obs[OBS_VELOCITY]
            x, y, psi, vx, vy, _ = env.fish_state
            shortfall = math.sqrt(band_violation(x, y, psi, vx, vy, stop_band, np))
            worst = max(worst, shortfall)
            if shortfall > 0 and band_time is None:
                band_time = step * period + (sub + 1) * period / substeps
            if terminated and not info["is_success"]:
                wall = True
                break
        obs[OBS_VELOCITY] = velocity / substeps  # the mean over the control period, as the env observes it
        t = (step + 1) * period
        if wall:
            break
        if info["distance"] < config.goal_radius:
            success = True
            break
    env.close()
    before = success and (band_time is None or band_time > t)
    return EpisodeRecord(seed, success, t, band_time, before, wall, worst)


def summarize(records: list[EpisodeRecord]) -> dict:
    """Counts and means of a list of records: success, band entries, success before the band, time to goal."""
    n = len(records)
    times = [r.time for r in records if r.success]
    return {"episodes": n, "success": sum(r.success for r in records),
            "band_entries": sum(r.band_time is not None for r in records),
            "success_before_band": sum(r.success_before_band for r in records),
            "walls": sum(r.wall for r in records),
            "time_to_goal": float(np.mean(times)) if times else math.nan,
            "worst_shortfall": max((r.worst for r in records), default=0.0)}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m pectoral_gym.agents.controllers.band_study``."""
    from pectoral_gym.tools.cli_common import HelpFormatter, add_seeds_argument, examples, prog_name

    parser = argparse.ArgumentParser(
        prog=prog_name(None, "pectoral_gym.agents.controllers.band_study"), description=__doc__.split("\n\n")[0],
        formatter_class=HelpFormatter,
        epilog=examples("python -m pectoral_gym.agents.controllers.band_study --controller hand --seeds 0-39",
                        "python -m pectoral_gym.agents.controllers.band_study --controller nmpc --seeds 0 1 "
                        "--summary-only --out band.json"))
    parser.add_argument("--controller", default="hand", help="a baseline name (make_baseline)")
    parser.add_argument("--env", default=SIMULATION_IDS["full"],
                        help="env id: one whose own band does not end the episode (default: %(default)s)")
    add_seeds_argument(parser, list(range(40)), "episode seeds (default 0-39)")
    parser.add_argument("--goal-inset", type=float, default=None, help="redraw goals this far from the walls [m]")
    parser.add_argument("--substeps", type=int, default=5, help="band checks per control period")
    parser.add_argument("--kwargs", default="{}", help="controller keyword arguments (JSON)")
    parser.add_argument("--out", default=None, help="JSON file for the records and the summary")
    parser.add_argument("--summary-only", action="store_true", help="print the summary only, not a line per episode")
    return parser


def main(argv: list[str] | None = None) -> dict:
    """Command line: run the seeds, print one line per episode and the summary, optionally write JSON."""
    args = build_parser().parse_args(argv)
    from pectoral_gym.agents.baselines import make_baseline  # the baselines import this package's controllers

    kwargs = json.loads(args.kwargs)
    records = []
    for seed in args.seeds:
        r = run_episode(lambda config: make_baseline(args.controller, config, **kwargs), seed, args.env,
                        args.substeps, args.goal_inset)
        records.append(r)
        if not args.summary_only:
            band = "-" if r.band_time is None else f"{r.band_time:.1f}"
            print(f"seed {seed}: success {int(r.success)} t {r.time:.1f} s band {band} worst {r.worst:.3f} m"
                  f"{' WALL' if r.wall else ''}", flush=True)
    summary = summarize(records)
    print(json.dumps(summary))
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"args": vars(args), "summary": summary, "episodes": [asdict(r) for r in records]}, f, indent=1)
    return summary


if __name__ == "__main__":
    main()
