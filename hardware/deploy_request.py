"""A deployment's request: what drives the fish, on which rig, for how many episodes; checked when made.

:func:`pectoral_gym.hardware.library.run_deployment` runs it; ``pectoral-deploy`` (:mod:`pectoral_gym.hardware.deploy`)
builds one from its arguments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pectoral_gym.hardware.deploy_checks import CONTROL_PERIOD_RANGE, MIN_TRACKING_WALL, NICE_RANGE, SPEED_RANGE
from pectoral_gym.hardware.emulated_firmware import FIRMWARES
from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.hardware.safety.rules import SafetyConfig

__all__ = ["CONTROLLERS", "RIGS", "DeployRequest"]

#: The rigs: the emulated robot and the whole PC stack in simulated time, the emulated robot in real time, a robot.
RIGS = ("lockstep", "emulated", "robot")
#: The controllers a request names (else it passes an object with ``reset(seed)`` and ``act(obs)``).
CONTROLLERS = ("policy", "nmpc", "hand", "excite")


@dataclass(frozen=True)
class DeployRequest:
    """A deployment: what drives the fish, on which rig, for how many episodes (units: seconds, metres).

    Attributes:
        controller: ``"policy"`` (loads ``policy``), ``"nmpc"``, ``"hand"``, ``"excite"`` (an identification run),
            or a controller object (``reset(seed)``, ``act(obs)``; a loaded policy carries its ``trained``
            settings, which are checked as for ``"policy"``); an object runs with ``jobs=1`` only.
        policy: Run folder or ``.zip`` of a trained policy (``controller="policy"`` only). Its pickles run when
            loaded: only folders you made or trust.
        episodes: Episodes, >= 1; episode ``k`` is seeded with ``seed + k``.
        seed: Seed of the targets, starts and every emulated condition, >= 0.
        task: ``"goal"`` or ``"track"`` (``None``: the policy's own, else ``goal``).
        control_period: Seconds between actions (``None``: the policy's own, else 0.5).
        rig: One of :data:`RIGS`.
        port, camera, robot_address, prompt: The robot's radio (serial URL), camera (index, URL, file), its XBee's
            64-bit address (``None``: broadcast) and whether to ask before each episode that the fish be placed
            (``rig="robot"`` only).
        speed: The emulated clock's speed-up (``rig="emulated"``).
        conditions: The emulated radio's and camera's conditions (emulated rigs only).
        emulate_params: The emulated fish's :class:`~pectoral_gym.model.params.FishParams` (``None``: Table 1's).
        firmware: The emulated robot's rules (:data:`pectoral_gym.hardware.emulated_firmware.FIRMWARES`).
        take_over: Take control of a robot that another live session drives.
        safety: The safety supervisor's settings.
        params: The robot's own model for the PC side (geofence, fin replay), checked by a probe first.
        scaling: The K file the hand law and the NMPC plan with (``None``: the shipped K).
        calibration: Camera calibration file (``None``: the emulator's camera model).
        solve_fraction: NMPC: the share of the control period a step's solves may take, in (0, 1].
        jobs: Worker processes for the lockstep episodes, >= 1 (the same results for any number).
        max_episode_steps: Steps per episode, >= 1.
        nice: Nice value to run at in real time, in [-20, 0] (0: leave the process as it is).
        out: Output folder (``None``: no files; the results are in memory either way).
        progress: Show a progress bar over the episodes.
    """

    controller: Any = "hand"
    policy: str | Path | None = None
    episodes: int = 1
    seed: int = 0
    task: str | None = None
    control_period: float | None = None
    rig: str = "lockstep"
    port: str | None = None
    camera: str | None = None
    robot_address: int | None = None
    prompt: bool = True
    speed: float = 1.0
    conditions: RigConditions = RigConditions()
    emulate_params: Any = None
    firmware: str = "python"
    take_over: bool = False
    safety: SafetyConfig = SafetyConfig()
    params: Any = None
    scaling: str | None = None
    calibration: str | None = None
    solve_fraction: float = 0.5
    jobs: int = 1
    max_episode_steps: int = 240
    nice: int = 0
    out: str | Path | None = None
    progress: bool = False

    def __post_init__(self) -> None:
        if self.policy is not None:
            object.__setattr__(self, "policy", str(self.policy))
        problem = _request_problem(self)
        if problem is not None:
            raise ValueError(problem)

    @property
    def controller_name(self) -> str:
        """The controller's name: one of :data:`CONTROLLERS`, or ``"object"`` for a controller object."""
        return self.controller if isinstance(self.controller, str) else "object"


def _request_problem(r: DeployRequest) -> str | None:
    """What is wrong with a request's settings taken alone (``None``: nothing)."""
    from pectoral_gym.agents.baselines import scaling_flag_problem

    emulated = r.rig != "robot"
    if r.rig not in RIGS:
        return f"rig must be one of {RIGS}, got {r.rig!r}"
    if isinstance(r.controller, str) and r.controller not in CONTROLLERS:
        return f"controller must be one of {CONTROLLERS} or a controller object, got {r.controller!r}"
    if not isinstance(r.controller, str) and not (hasattr(r.controller, "act") and hasattr(r.controller, "reset")):
        return f"a controller object needs reset(seed) and act(obs), got {type(r.controller).__name__}"
    if (r.controller_name == "policy") != (r.policy is not None):
        return "policy is needed with controller 'policy', and only then"
    if not isinstance(r.controller, str) and r.jobs != 1:
        return "a controller object runs in this process: jobs must be 1 (or name the policy's folder)"
    if emulated and (r.port, r.camera, r.robot_address) != (None, None, None):
        return "port, camera and robot_address are the robot's: the emulated rigs bring their own"
    if not emulated and (r.port is None or r.camera is None):
        return "rig 'robot' needs port and camera"
    misplaced = [name for name, wrong in (
        ("jobs", r.jobs != 1 and r.rig != "lockstep"), ("speed", r.speed != 1.0 and r.rig != "emulated"),
        ("firmware", r.firmware != "python" and not emulated), ("emulate_params", r.emulate_params is not None
                                                                and not emulated),
        ("conditions", r.conditions != RigConditions() and not emulated)) if wrong]
    if misplaced:
        return f"{', '.join(misplaced)}: not with rig {r.rig!r}"
    if r.firmware not in FIRMWARES:
        return f"firmware must be one of {FIRMWARES}, got {r.firmware!r}"
    if (problem := scaling_flag_problem(r.controller_name, r.scaling)) is not None:
        return problem
    for name, value in (("episodes", r.episodes), ("max_episode_steps", r.max_episode_steps), ("jobs", r.jobs)):
        if value < 1:
            return f"{name} must be >= 1, got {value}"
    if r.seed < 0:
        return f"seed must be >= 0, got {r.seed}"
    if not math.isfinite(r.speed) or not SPEED_RANGE[0] <= r.speed <= SPEED_RANGE[1]:
        return f"speed must be in [{SPEED_RANGE[0]}, {SPEED_RANGE[1]}], got {r.speed}"
    if not NICE_RANGE[0] <= r.nice <= NICE_RANGE[1]:
        return f"nice must be in [{NICE_RANGE[0]}, {NICE_RANGE[1]}], got {r.nice}"
    if not 0 < r.solve_fraction <= 1:
        return f"solve_fraction must be in (0, 1], got {r.solve_fraction}"
    if not r.safety.tracking_timeout / r.speed >= MIN_TRACKING_WALL:
        return (f"safety.tracking_timeout / speed must be >= {MIN_TRACKING_WALL} s of wall time, got "
                f"{r.safety.tracking_timeout} at speed {r.speed}")
    if r.control_period is not None and not (math.isfinite(r.control_period) and CONTROL_PERIOD_RANGE[0]
                                             <= r.control_period <= CONTROL_PERIOD_RANGE[1]):
        return f"control_period must be in [{CONTROL_PERIOD_RANGE[0]}, {CONTROL_PERIOD_RANGE[1]}] s, got " \
               f"{r.control_period}"
    return None
