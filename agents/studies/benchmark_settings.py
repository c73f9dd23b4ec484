"""What a benchmark run covers and how large it is: its columns, tasks, baselines, sizes and presets.

The simulated columns (:data:`ENVS`: the averaged model, the full model, the full model with parameter
randomisation) in a registered env version (:data:`VERSIONS`, newest first, the latest the default), the robot
stack's columns after them (:data:`ALL_ENVS`), and :class:`BenchmarkSettings`, with the ``--quick`` and ``--full``
sizes of ``pectoral-benchmark`` (:data:`PRESETS`). :mod:`pectoral_gym.agents.studies.benchmark` runs them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pectoral_gym.agents.studies.robot_stack import ROBOT_COLUMNS
from pectoral_gym.versions import ENV_VERSIONS, LATEST_AVERAGED, LATEST_FULL

__all__ = ["ALL_ENVS", "BASELINE_NAMES", "ENVS", "PRESETS", "TASKS", "VERSIONS", "BenchmarkSettings", "env_id"]

# the registered env versions a benchmark can run on, newest first; the latest (the default) is recommended
VERSIONS = tuple(sorted({env_id.rsplit("-", 1)[1] for env_id in ENV_VERSIONS}, key=lambda v: -int(v[1:])))
AVERAGED_ID = LATEST_AVERAGED
FULL_ID = LATEST_FULL
# label -> (env id, randomised), in the default version (env_id() gives another version's)
ENVS = {"averaged": (AVERAGED_ID, False), "full": (FULL_ID, False), "full+rand": (FULL_ID, True)}
# the simulated settings, then the robot stack's columns
ALL_ENVS = (*ENVS, *ROBOT_COLUMNS)
TASKS = ("goal", "track")
BASELINE_NAMES = ("random", "hand", "nmpc")


def env_id(label: str, version: str = VERSIONS[0]) -> str:
    """The env id of a simulated column label of :data:`ENVS` in ``version`` (one of :data:`VERSIONS`)."""
    if version not in VERSIONS:
        raise ValueError(f"unknown env version {version!r}; choose from {VERSIONS}")
    return ENVS[label][0].rsplit("-", 1)[0] + "-" + version


@dataclass(frozen=True)
class BenchmarkSettings:
    """Sizes of a benchmark run.

    Attributes:
        episodes: Episodes per cell for random, hand and trained policies.
        nmpc_episodes: Episodes per cell for NMPC, per task (it solves an optimal control problem each step).
        max_episode_steps: Truncation of every episode (``None``: as registered, 240 steps = 2 min).
        nmpc: Keyword arguments of the NMPC baseline (:class:`pectoral_gym.agents.nmpc.controller.NMPCSettings` fields).
        env_steps: Single-env steps per timed pass of the env throughput (:mod:`pectoral_gym.tools.bench`).
        vector_steps: Vector-env batch steps per timed pass.
        repeats: Timed passes of the env throughput (best kept).
        train_steps: Timesteps of the timed PPO ``learn()`` (0: skip).
        seed: Episode ``k`` of every cell is reset with ``seed + k``.
        solve_seeds: Training seeds of the time to solve
            (:func:`pectoral_gym.agents.studies.solve_time.measure_time_to_solve`;
            empty: skipped).
        solve_timesteps: Training budget per seed of the time to solve (``None``: ``agents/hyperparams/ppo.yml``).
        solve_episodes: Episodes per probe and of the confirmation.
        robot_episodes: Episodes per robot-stack cell, per task (each step renders and tracks camera frames).
        robot_max_steps: Truncation of the robot-stack episodes (``None``: ``max_episode_steps``).
        version: The registered env version of the simulated columns and the training throughput (:data:`VERSIONS`;
            the robot stack's columns always run as the deploy does).
    """

    episodes: int = 100
    nmpc_episodes: dict[str, int] = field(default_factory=lambda: {"goal": 100, "track": 10})
    max_episode_steps: int | None = None
    nmpc: dict[str, Any] = field(default_factory=dict)
    env_steps: int = 20_000
    vector_steps: int = 100
    repeats: int = 5
    train_steps: int = 65_536
    seed: int = 0
    solve_seeds: tuple[int, ...] = ()
    solve_timesteps: int | None = None
    solve_episodes: int = 100
    robot_episodes: dict[str, int] = field(default_factory=lambda: {"goal": 20, "track": 2})
    robot_max_steps: int | None = None
    version: str = VERSIONS[0]


PRESETS = {
    "quick": BenchmarkSettings(episodes=10, nmpc_episodes={"goal": 2, "track": 1}, max_episode_steps=120,
                               env_steps=2_000, vector_steps=5, repeats=1, train_steps=16_384,
                               robot_episodes={"goal": 2, "track": 0}, robot_max_steps=60),
    "full": BenchmarkSettings(solve_seeds=(0, 1, 2, 3, 4)),
}
