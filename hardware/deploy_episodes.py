"""The episodes of a deployment on one env: their steps log, their summaries, the trajectory plot.

A run ends early, at once, when the robot serves another session (``RadioLink.displaced``, in
:mod:`pectoral_gym.hardware.radio.link`: another PC took it over, or it was never ours): :func:`run_episodes` runs
no further episode, and the link sends nothing more (``docs/hardware.md``, "Take-over").
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import TextIO

import numpy as np

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.clock import REAL_CLOCK
from pectoral_gym.hardware.radio.link import DisplacedError

__all__ = ["displaced_reason", "plot_trajectories", "random_start", "run_episode", "run_episodes"]


def displaced_reason(env) -> str:
    """``"taken_over"`` or ``"robot_busy"`` if ``env``'s robot serves another session, else ``""``."""
    link = getattr(env.unwrapped, "link", None)
    return str(link.control_lost) if getattr(link, "displaced", False) else ""


def random_start(rng: np.random.Generator, inset: float = tk.START_INSET) -> tuple[float, float, float]:
    """A start pose as the simulated goal task draws one (tank inset by ``inset`` [m], any heading)."""
    x = inset + rng.random() * (tk.TANK_X - 2 * inset)
    y = inset + rng.random() * (tk.TANK_Y - 2 * inset)
    return x, y, -math.pi + 2 * math.pi * rng.random()


def run_episode(env, controller, episode: int, log: TextIO, seed: int | None = None, robot=None) -> dict:
    """Run episode number ``episode``; write one JSON line per step to ``log``; return the episode's summary.

    The env and the controller are reset with ``seed + episode`` (``None``: unseeded). A step's ``t`` is seconds
    since the episode's reset on the env's clock (simulated seconds in lockstep).
    """
    clock = getattr(env.unwrapped, "clock", REAL_CLOCK)
    ep_seed = None if seed is None else seed + episode
    obs, info = env.reset(seed=ep_seed)
    controller.reset(ep_seed)
    ret, steps, t0 = 0.0, 0, clock.monotonic()
    record = {"episode": episode, "step": 0, "event": "reset", "pose": info["pose"], "target": info["target"]}
    if robot is not None:
        record["true_pose"] = list(robot.pose())
    log.write(json.dumps(record) + "\n")
    while True:
        action = np.asarray(controller.act(obs), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        ret += reward
        steps += 1
        record = {"episode": episode, "step": steps, "t": clock.monotonic() - t0,
                  "action": action.tolist(), "command": info["command"], "pose": info["pose"],
                  "estimate": info["estimate"], "target": env.unwrapped.target, "reward": reward,
                  "terminated": terminated, "truncated": truncated, "safety_stop": info["safety_stop"],
                  "distance": info["distance"], "link": info["link"], "tracking": info["tracking"]}
        if robot is not None:
            record["true_pose"] = list(robot.pose())
        log.write(json.dumps(record) + "\n")
        if terminated or truncated:
            break
    success = bool(info.get("is_success", False))
    return {"episode": episode, "return": ret, "steps": steps, "terminated": terminated, "truncated": truncated,
            "safety_stop": info["safety_stop"], "success": success,
            # as the simulated envs' metric (agents.training.metrics.time_to_goal): steps x control period [s]
            "time_to_goal": steps * env.unwrapped.config.control_period if success else None,
            "final_distance": info["distance"]}


def run_episodes(env, controller, episodes: int, log_path: Path | TextIO, seed: int | None = None, robot=None,
                 progress: bool = True) -> list[dict]:
    """Run ``episodes`` episodes on one env (:func:`run_episode`); write the steps to ``log_path``; return summaries.

    ``log_path``: a file (created or overwritten) or an open text stream (written, left open).

    Stops early, with the episodes so far, once the robot serves another session (:func:`displaced_reason`):
    after an episode that ended so, or at a reset that found it so (:class:`DisplacedError`; that episode has no
    summary and no steps).
    """
    from tqdm import tqdm

    summaries = []
    stream = contextlib.nullcontext(log_path) if hasattr(log_path, "write") else open(log_path, "w", encoding="utf-8")
    with stream as log, tqdm(total=episodes, desc="episodes", disable=not progress) as bar:
        for episode in range(episodes):
            try:
                summaries.append(run_episode(env, controller, episode, log, seed, robot))
            except DisplacedError:
                break
            finally:
                log.flush()
            bar.update(1)
            if displaced_reason(env):
                break
    return summaries


_LEGEND_EPISODES = 10  # the most episodes the plot names in a legend (one colour each)


def plot_trajectories(log_path: Path, png_path: Path) -> None:
    """Tank, measured/estimated path (and the true path when emulated) and targets of every episode.

    Up to ten episodes are named in a legend; with more, colours repeat every ten episodes and the title says so.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episodes: dict[int, list[dict]] = {}
    for line in Path(log_path).read_text(encoding="utf-8").splitlines():
        rec = json.loads(line)
        episodes.setdefault(rec["episode"], []).append(rec)
    fig, ax = plt.subplots(figsize=(9, 5))
    ax.add_patch(plt.Rectangle((0, 0), tk.TANK_X, tk.TANK_Y, fill=False, lw=2, color="k"))
    for k, recs in episodes.items():
        colour = f"C{k % 10}"
        est = np.array([r["estimate"][:2] for r in recs if "estimate" in r])
        if len(est):
            ax.plot(est[:, 0], est[:, 1], "-", color=colour, label=f"episode {k} estimate")
        true = np.array([r["true_pose"][:2] for r in recs if "true_pose" in r])
        if len(true):
            ax.plot(true[:, 0], true[:, 1], ":", color=colour, label=f"episode {k} true")
        start = recs[0]["pose"]
        ax.plot(start[0], start[1], "o", color=colour)
        targets = np.array([r["target"] for r in recs if "target" in r])
        ax.plot(targets[:, 0], targets[:, 1], "x", color=colour, ms=8)
    title = "Deployment: path (o start, x target)"
    if len(episodes) > _LEGEND_EPISODES:  # a legend that long overflows the figure and takes seconds to lay out
        title += f", {len(episodes)} episodes (colour: episode mod 10)"
    ax.set(xlim=(-0.05, tk.TANK_X + 0.05), ylim=(-0.05, tk.TANK_Y + 0.05), xlabel="X [m]", ylabel="Y [m]",
           title=title, aspect="equal")
    if len(episodes) <= _LEGEND_EPISODES:
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)
    plt.close(fig)
