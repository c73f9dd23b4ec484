"""The simulated overhead camera: its settings (:class:`SensingConfig`) and the fish's pose between control instants.

The robot env observes through a camera and an observer (``HardwareFishEnv``): frames at ~30 frames/s, each
with the tracker's pose noise, some lost, each delivered some time after its capture; the high-gain observer
(:mod:`pectoral_gym.sensing.observer`) turns the delivered poses into the state the observation shows. A
simulated env with ``EnvConfig.sensing`` does the same with a simulated camera
(:mod:`pectoral_gym.envs.sensed`), whose levels are drawn per episode from the ranges here.

The fish's true pose at each frame instant comes from the model itself, advanced from one frame instant to
the next (:mod:`pectoral_gym.envs.sensed` says how, and why not by interpolation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pectoral_gym.option_groups import coerce_group, level_range

__all__ = ["CLEAN_CAMERA", "DEGRADED_CAMERA", "LEVELS", "N_LEVELS", "SensingConfig"]

#: The emulated robot's camera without degradation (``pectoral-deploy --emulate`` with no camera flags): the
#: tracker's clean-frame pose noise, 0.3 mm and 0.2 deg rms (``docs/hardware-vision.md``, "High-gain observer"),
#: no frame lost, no latency, 30 frames/s.
CLEAN_CAMERA = {"position_noise": 0.3e-3, "heading_noise": math.radians(0.2), "frame_drop": 0.0, "latency": 0.0}
#: The degraded camera of the robot stack's targets (``--camera-drop 0.1 --pose-noise-mm 5 --pose-noise-deg 2``).
DEGRADED_CAMERA = {"position_noise": 5e-3, "heading_noise": math.radians(2.0), "frame_drop": 0.1}
#: Per-episode levels drawn by :meth:`SensingConfig.draw`, in this order (the last is the first frame's phase).
LEVELS = ("position_noise", "heading_noise", "frame_drop", "latency", "phase")
N_LEVELS = len(LEVELS)
_RANGES = LEVELS[:4]


@dataclass(frozen=True)
class SensingConfig:
    """The simulated camera and observer of ``EnvConfig.sensing`` (SI units; ranges drawn per episode).

    Each range is ``(low, high)`` (a number ``v`` means ``(v, v)``); every reset draws each level uniformly
    from its range. The defaults span the emulated robot's camera from clean (:data:`CLEAN_CAMERA`) to the
    degraded one of the robot stack's targets (:data:`DEGRADED_CAMERA`), with a capture-to-delivery latency up to 0.1 s.

    Attributes:
        frame_rate: Camera frames per second [1/s] (the robot env's ``frame_period`` is its inverse).
        position_noise: Range of the standard deviation of the Gaussian noise on X and Y of each frame [m].
        heading_noise: Range of the standard deviation of the Gaussian noise on psi of each frame [rad].
        frame_drop: Range of the probability that a frame is lost, in [0, 1].
        latency: Range of the delay from a frame's capture to its delivery [s], below the control period.
        observer_epsilon: The high-gain observer's ``epsilon`` [s] (``HardwareFishEnv``'s ``observer_epsilon``).
        max_gap: The observer restarts after a gap between delivered frames longer than this [s].
    """

    frame_rate: float = 30.0
    position_noise: tuple[float, float] = (CLEAN_CAMERA["position_noise"], DEGRADED_CAMERA["position_noise"])
    heading_noise: tuple[float, float] = (CLEAN_CAMERA["heading_noise"], DEGRADED_CAMERA["heading_noise"])
    frame_drop: tuple[float, float] = (0.0, 0.1)
    latency: tuple[float, float] = (0.0, 0.1)
    observer_epsilon: float = 0.1
    max_gap: float = 1.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("frame_rate", "observer_epsilon", "max_gap"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                    and value > 0):
                raise ValueError(f"sensing[{name!r}] must be a finite number > 0, got {value!r}")
            set_(self, name, float(value))
        for name in _RANGES:
            set_(self, name, level_range("sensing", name, getattr(self, name), 1.0 if name == "frame_drop" else None))

    @classmethod
    def coerce(cls, value: Any) -> SensingConfig | None:
        """``EnvConfig.sensing`` as given, as a ``SensingConfig`` or ``None`` (off).

        ``None`` or ``False``: off; ``True`` or ``{}``: the defaults; a mapping of fields; a ``SensingConfig``.

        Raises:
            ValueError: For another value, an unknown key, or an invalid setting.
        """
        return coerce_group(cls, "sensing", value)

    def frames_per_period(self, control_period: float) -> int:
        """Most frames delivered in one control period (a window of ``control_period`` seconds)."""
        return int(math.floor(control_period * self.frame_rate)) + 1

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """One episode's levels (:data:`LEVELS`): each range's uniform draw, and the first frame's phase.

        The first frame is captured ``phase`` in ``(0, 1 / frame_rate]`` after the reset (the camera runs
        free of the control loop). Five uniforms from ``rng``.
        """
        u = rng.random(N_LEVELS)
        levels = np.empty(N_LEVELS)
        for k, name in enumerate(_RANGES):
            low, high = getattr(self, name)
            levels[k] = low + u[k] * (high - low)
        levels[N_LEVELS - 1] = (1.0 - u[N_LEVELS - 1]) / self.frame_rate
        return levels
