"""NMPC `goal` from rest with the goal close by: a development probe for the held-out stalls.

On held-out seeds 1000-1099 (docs/notes/2026-12-01-nmpc-rounds.md, fourth round) four of the NMPC's eight failures were
stalls: the fish came to rest 0.26-0.36 m from the goal and stayed there. The env's own resets
rarely start that close, so this probe draws such starts on purpose (development data, not the
held-out seeds): the fish at rest at a random pose at least 0.15 m from the walls, the goal
``--distance`` away at a random bearing, at least 0.1 m inside the tank. It runs the NMPC (or
``--controller hand``, or a trained ``--policy``) on the full model and prints one line per start and
a summary.

    PYTHONPATH=. python docs/validation/nmpc/stall_probe.py                       # 30 starts, seed 0
    PYTHONPATH=. python docs/validation/nmpc/stall_probe.py --settings '{"togo_steps": 40}'
    PYTHONPATH=. python docs/validation/nmpc/stall_probe.py --policy demo_out/run      # the demo's PPO

Run it alone on the machine: the NMPC's time budgets make outcomes depend on the load.
"""

from __future__ import annotations

import argparse
import json
import math

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.training.policy import load_policy
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FinBeat


def starts(n: int, distance: float, seed: int) -> list[tuple[float, float, float, float, float]]:
    """``(x, y, psi, goal x, goal y)`` of ``n`` starts (m, m, rad, m, m)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        x, y = rng.uniform(0.15, TANK_LENGTH - 0.15), rng.uniform(0.15, TANK_WIDTH - 0.15)
        psi, bearing = rng.uniform(-math.pi, math.pi), math.radians(rng.uniform(0.0, 360.0))
        gx, gy = x + distance * math.cos(bearing), y + distance * math.sin(bearing)
        if 0.1 < gx < TANK_LENGTH - 0.1 and 0.1 < gy < TANK_WIDTH - 0.1:
            out.append((x, y, psi, gx, gy))
    return out


def main() -> None:
    """Run the probe (``--help``)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=30, help="number of starts (default %(default)s)")
    parser.add_argument("--distance", type=float, default=0.3, help="goal distance [m] (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the starts (default %(default)s)")
    parser.add_argument("--settings", default="{}", help="JSON: NMPCSettings overrides (default %(default)s)")
    parser.add_argument("--controller", default="nmpc", choices=("nmpc", "hand"),
                        help="baseline controller (default %(default)s)")
    parser.add_argument("--policy", help="a trained policy's run folder instead (the demo's: fin observation on)")
    args = parser.parse_args()
    # the shipped PPO file trains with the fins' stroke phase in the observation
    env = gym.make("PectoralFish-Full-v0", task="goal", max_episode_steps=240, observe_fins=args.policy is not None)
    if args.policy:
        controller = load_policy(args.policy)
    else:
        settings = json.loads(args.settings) if args.controller == "nmpc" else {}
        controller = make_baseline(args.controller, env.unwrapped.config, **settings)
    core = env.unwrapped.core
    outcomes = []
    for x, y, psi, gx, gy in starts(args.n, args.distance, args.seed):
        env.reset(seed=0)  # then the probe's own start: at rest, the goal placed by hand
        core.model.reset(np.array([[x, y, psi, 0.0, 0.0, 0.0]]), right=FinBeat.rest(), left=FinBeat.rest())
        core.set_target(0, gx, gy)
        core.task_state.observe_reset(np.array([0]), core.model.state)
        obs = core.obs[0].copy()
        if hasattr(controller, "reset"):
            controller.reset()
        path, last, steps, done, info = 0.0, core.model.state[0, :2].copy(), 0, False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(controller.act(obs))
            steps += 1
            done = terminated or truncated
            here = core.model.state[0, :2].copy()
            path, last = path + float(np.linalg.norm(here - last)), here
        ok = bool(info.get("is_success", False))
        why = "goal" if ok else ("wall" if info.get("reward_wall", 0.0) != 0.0 else "time-out")
        outcomes.append((ok, steps, why))
        print(f"start ({x:.2f}, {y:.2f}, {math.degrees(psi):5.0f} deg) goal ({gx:.2f}, {gy:.2f}): {why} after "
              f"{steps} steps, path {path:.2f} m, end distance {info['distance']:.3f} m", flush=True)
    reached = [s for ok, s, _ in outcomes if ok]
    print(f"success {len(reached)}/{len(outcomes)}, walls {sum(w == 'wall' for *_, w in outcomes)}, time-outs "
          f"{sum(w == 'time-out' for *_, w in outcomes)}, mean time to goal "
          f"{np.mean(reached) * env.unwrapped.config.control_period:.1f} s, "
          f"late steps {getattr(controller, 'late', 0)}")


if __name__ == "__main__":
    main()
