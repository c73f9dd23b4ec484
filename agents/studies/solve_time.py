"""Time to solve: train seeds with the probe of :mod:`~pectoral_gym.agents.studies.solve_probe` until :data:`SOLVED`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from pectoral_gym.agents.studies.seeds import TRAIN_ENV, train_seeds
from pectoral_gym.agents.studies.solve_probe import FULL_ID, PROBE_SEED, REPORT_SEED, SOLVED, SolveProbe, check_held_out

__all__ = ["FULL_ID", "PROBE_SEED", "REPORT_SEED", "SOLVED", "SolveProbe", "check_held_out", "measure_time_to_solve"]


def measure_time_to_solve(seeds: list[int], out: str | Path, timesteps: int | None = None, episodes: int = 100,
                          confirm_episodes: int = 100, every: int = 1, jobs: int = 1, progress: bool = False,
                          hyperparams: dict[str, Any] | None = None) -> dict[str, Any]:
    """Train the demo's PPO for each seed until the probe first reaches :data:`SOLVED` on the full model.

    Each run stops once solved (or at ``timesteps``); nothing but the probe and its confirmation is
    evaluated. Wall times are training times (periodic evaluations included, probes left out) and
    depend on the machine's load: run with ``jobs`` at most the number of idle cores.

    Args:
        seeds: Training seeds.
        out: Parent of the run folders (``<out>/<stamp>/seed<S>/``).
        timesteps: Training budget per seed (default: ``agents/hyperparams/ppo.yml``).
        episodes: Episodes per probe (seeds ``PROBE_SEED + k``).
        confirm_episodes: Episodes of the confirmation (seeds ``REPORT_SEED + k``).
        every: Probe after every ``every``-th periodic evaluation.
        jobs: Runs at once, each in its own process.
        progress: Progress bars.
        hyperparams: More hyperparameter overrides (``timesteps`` wins for ``n_timesteps``).

    Returns:
        ``{"settings", "runs": [{"seed", "timesteps", "train_time_s", **SolveProbe.summary()}]}``.
    """
    from pectoral_gym.agents.training.config import resolve_config

    overrides = dict(hyperparams or {}) | ({} if timesteps is None else {"n_timesteps": int(timesteps)})
    config = resolve_config("ppo", TRAIN_ENV, int(seeds[0]), task="goal", hyperparams=dict(overrides))
    check_held_out(list(seeds), config["n_envs"], config["eval_episodes"], episodes, confirm_episodes)
    probe = {"episodes": int(episodes), "confirm_episodes": int(confirm_episodes), "every": int(every),
             "stop_on_solve": True}
    out = Path(out) / time.strftime("%Y%m%d-%H%M%S")  # a new folder each time: no stale run folders
    args = {"out": str(out), "overrides": overrides, "probe": probe, "settings": ()}
    results = train_seeds(seeds, jobs, args, config["n_timesteps"], progress)
    runs = []
    for seed in seeds:
        r = results[int(seed)]
        runs.append({"seed": int(seed), "timesteps": r["timesteps"], "train_time_s": r["train_time_s"],
                     **r["time_to_solve"]})
    return {"settings": {"seeds": [int(s) for s in seeds], "n_timesteps": config["n_timesteps"],
                         "threshold": SOLVED, "probe_episodes": int(episodes), "probe_seed": PROBE_SEED,
                         "confirm_episodes": int(confirm_episodes), "confirm_seed": REPORT_SEED,
                         "every": int(every), "eval_freq": config["eval_freq"], "jobs": int(jobs),
                         "out": str(out)},
            "runs": runs}
