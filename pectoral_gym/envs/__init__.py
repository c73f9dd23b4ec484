"""Gymnasium environments of the pectoral-fin fish (the only package that imports Gymnasium).

``PectoralFish-Full-v2`` and ``PectoralFish-Averaged-v2`` (and their ``-v1`` and ``-v0``) are registered by
:func:`pectoral_gym.registration.register_envs` when ``pectoral_gym`` is imported, from the table of
:mod:`pectoral_gym.versions` (re-exported here: ``LATEST``, ``LATEST_AVERAGED``, ``LATEST_FULL``, the recommended ids).

Modules: ``fish_env`` (the single env), ``vector`` (the native vector env),
``config`` (their settings, ``EnvConfig``), ``core`` (the batched core both share), ``tasks`` (the numba task
kernels, a task row, and the task table and ``TaskState``, shared with the robot
env), ``fused`` (those kernels and the model advance in one compiled
call per step, a serial and a parallel build chosen by batch size), ``layout`` (their packed arrays,
named), ``observation`` (the observation layout and ``decode``), ``sensed`` (the simulated camera and
observer), ``timing`` (the robot's command delays and late ticks), ``rendering`` (pygame top view).
"""

from pectoral_gym.envs.core import EnvConfig, EnvCore
from pectoral_gym.envs.fish_env import PectoralFishEnv
from pectoral_gym.envs.tasks.table import TaskState, register_task
from pectoral_gym.envs.vector import PectoralFishVectorEnv
from pectoral_gym.versions import LATEST, LATEST_AVERAGED, LATEST_FULL

__all__ = ["LATEST", "LATEST_AVERAGED", "LATEST_FULL", "EnvConfig", "EnvCore", "PectoralFishEnv",
           "PectoralFishVectorEnv", "TaskState", "register_task"]
