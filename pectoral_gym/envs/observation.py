"""The observation layout shared by every fish environment (full, averaged, hardware).

The observation is a float32 vector of :data:`OBS_SIZE` entries. Kernels and
controllers index it with the constants below; :func:`decode` gives the named
view. :data:`OBSERVATION_STRUCTURE` lists the blocks in order, as Gymnasium's
MuJoCo envs publish ``observation_structure``.

| index | name | meaning | unit |
|---|---|---|---|
| 0-1 | ``x, y`` | position in the tank (origin at a corner) | m |
| 2-3 | ``cos_psi, sin_psi`` | heading | - |
| 4-6 | ``vx, vy, omega`` | body-frame velocity, mean over the last control period | m/s, m/s, rad/s |
| 7-8 | ``target_x, target_y`` | target relative to the fish, body frame | m |
| 9-10 | ``target_vx, target_vy`` | target velocity, body frame (zero for ``goal``) | m/s |
| 11-18 | ``last_action`` | last action, normalised to [-1, 1] (right fin, then left) | - |

With ``observe_fins=True`` (:class:`~pectoral_gym.envs.core.EnvConfig`) the observation has
:data:`FIN_OBS_SIZE` more entries, the half-stroke in progress of each fin (right fin, then left;
:mod:`pectoral_gym.model.strokes`), on which the effect of a new command depends: a fin latches it at the
end of that half-stroke, and the next half-stroke starts at that stroke's end angle
(``docs/model.md`` 3.7 and 5):

| index | name | meaning | unit |
|---|---|---|---|
| 19 + 4f | ``fin_angle`` | fin angle now, ``(gamma - pi/2) / (pi/2)`` | - |
| 20 + 4f | ``fin_angle_to`` | angle at the end of the half-stroke (the next turning point), same scale | - |
| 21 + 4f | ``fin_power`` | +1 in a power stroke, -1 in a recovery stroke (or parked) | - |
| 22 + 4f | ``fin_time_left`` | time to that turning point / largest ``period_range``, clipped to [0, 1] | - |
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

__all__ = [
    "OBS_X", "OBS_Y", "OBS_COS_PSI", "OBS_SIN_PSI", "OBS_VX", "OBS_VY", "OBS_OMEGA",
    "OBS_TARGET_X", "OBS_TARGET_Y", "OBS_TARGET_VX", "OBS_TARGET_VY", "OBS_LAST_ACTION", "OBS_SIZE",
    "OBS_POSITION", "OBS_HEADING", "OBS_VELOCITY", "OBS_TARGET", "OBS_TARGET_VELOCITY", "OBS_ACTION",
    "OBSERVATION_STRUCTURE", "Observation", "decode", "one_observation", "MAX_SPEED", "MAX_YAW_RATE",
    "observation_bounds",
    "FIN_OBS_SIZE", "FIN_OBS_FIELDS", "OBS_FIN_ANGLE", "OBS_FIN_ANGLE_TO", "OBS_FIN_POWER", "OBS_FIN_TIME_LEFT",
    "OBS_FINS", "OBS_SIZES", "observation_size", "observation_structure",
]

OBS_X, OBS_Y = 0, 1
OBS_COS_PSI, OBS_SIN_PSI = 2, 3
OBS_VX, OBS_VY, OBS_OMEGA = 4, 5, 6
OBS_TARGET_X, OBS_TARGET_Y = 7, 8
OBS_TARGET_VX, OBS_TARGET_VY = 9, 10
OBS_LAST_ACTION = 11  # first of the 8 action entries (4 per fin, right fin first)
OBS_SIZE = 19

# The same blocks as slices, for numpy code.
OBS_POSITION = slice(OBS_X, OBS_Y + 1)
OBS_HEADING = slice(OBS_COS_PSI, OBS_SIN_PSI + 1)
OBS_VELOCITY = slice(OBS_VX, OBS_OMEGA + 1)
OBS_TARGET = slice(OBS_TARGET_X, OBS_TARGET_Y + 1)
OBS_TARGET_VELOCITY = slice(OBS_TARGET_VX, OBS_TARGET_VY + 1)
OBS_ACTION = slice(OBS_LAST_ACTION, OBS_SIZE)

# The optional fin block (observe_fins=True): per fin f (0 right, 1 left) the entries
# OBS_SIZE + FIN_OBS_FIELDS * f + OBS_FIN_*.
OBS_FIN_ANGLE, OBS_FIN_ANGLE_TO, OBS_FIN_POWER, OBS_FIN_TIME_LEFT = 0, 1, 2, 3
FIN_OBS_FIELDS = 4
FIN_OBS_SIZE = 2 * FIN_OBS_FIELDS
OBS_FINS = slice(OBS_SIZE, OBS_SIZE + FIN_OBS_SIZE)
OBS_SIZES = (OBS_SIZE, OBS_SIZE + FIN_OBS_SIZE)  # the observation's sizes without and with the fin block

#: Block name -> number of entries, in order.
OBSERVATION_STRUCTURE = {
    "position": 2, "heading": 2, "velocity": 3, "target": 2, "target_velocity": 2, "last_action": 8,
}


# Bounds of the observation space. The fish's mean velocities over a control period stay far below these:
# the most measured with extreme actions (every entry -1 or +1, 64 fish x 240 steps, full model) are
# |vx| 0.44 m/s, |vy| 0.15 m/s, |omega| 1.5 rad/s (``docs/guide/envs.md``, "Gymnasium conventions").
MAX_SPEED = 2.0  # bound of |vx| and |vy| [m/s]
MAX_YAW_RATE = 10.0  # bound of |omega| [rad/s]


def observation_size(observe_fins: bool = False) -> int:
    """Number of observation entries: :data:`OBS_SIZE`, plus :data:`FIN_OBS_SIZE` with the fin block."""
    return OBS_SIZE + (FIN_OBS_SIZE if observe_fins else 0)


def observation_structure(observe_fins: bool = False) -> dict[str, int]:
    """Block name -> number of entries, in order (``"fins"`` last with the fin block)."""
    return {**OBSERVATION_STRUCTURE, **({"fins": FIN_OBS_SIZE} if observe_fins else {})}


def observation_bounds(control_period: float, ref_speed: float,
                       observe_fins: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` float32 bounds of the observation of an env with these settings.

    Every step starts with the nose and the tail inside the tank (else the episode has
    ended), so the centre of mass leaves the tank by at most ``MAX_SPEED * control_period``
    during the step that ends the episode; the target (goal or reference point) lies in the
    tank, so its offset from the fish is at most the diagonal of the tank grown by that
    margin; the target moves at ``ref_speed`` (zero for ``goal``); heading and last action
    lie in [-1, 1], and so do the fin block's entries.
    """
    margin = MAX_SPEED * float(control_period)
    reach = math.hypot(TANK_LENGTH + 2.0 * margin, TANK_WIDTH + 2.0 * margin)
    speed = 1.01 * float(ref_speed)  # 1 % over: float32 rounding of the rotated velocity
    low = np.full(observation_size(observe_fins), -1.0)
    high = np.full(observation_size(observe_fins), 1.0)
    low[OBS_X], high[OBS_X] = -margin, TANK_LENGTH + margin
    low[OBS_Y], high[OBS_Y] = -margin, TANK_WIDTH + margin
    low[OBS_VX:OBS_VY + 1], high[OBS_VX:OBS_VY + 1] = -MAX_SPEED, MAX_SPEED
    low[OBS_OMEGA], high[OBS_OMEGA] = -MAX_YAW_RATE, MAX_YAW_RATE
    low[OBS_TARGET], high[OBS_TARGET] = -reach, reach
    low[OBS_TARGET_VELOCITY], high[OBS_TARGET_VELOCITY] = -speed, speed
    return low.astype(np.float32), high.astype(np.float32)


class Observation(NamedTuple):
    """Named view of one observation (scalars) or of a batch (arrays over the leading axes)."""

    x: np.ndarray | float
    y: np.ndarray | float
    cos_psi: np.ndarray | float
    sin_psi: np.ndarray | float
    vx: np.ndarray | float
    vy: np.ndarray | float
    omega: np.ndarray | float
    target_x: np.ndarray | float
    target_y: np.ndarray | float
    target_vx: np.ndarray | float
    target_vy: np.ndarray | float
    last_action: np.ndarray
    fins: np.ndarray | None = None  # (..., 2, FIN_OBS_FIELDS) with the fin block, else None

    @property
    def psi(self) -> np.ndarray | float:
        """Heading [rad], in (-pi, pi]."""
        return np.arctan2(self.sin_psi, self.cos_psi)

    @property
    def distance(self) -> np.ndarray | float:
        """Distance to the target [m]."""
        return np.hypot(self.target_x, self.target_y)

    def target_in_tank(self) -> tuple[np.ndarray | float, np.ndarray | float]:
        """Target position in the tank frame [m] (the body-frame offset rotated by the heading)."""
        c, s = self.cos_psi, self.sin_psi
        return self.x + c * self.target_x - s * self.target_y, self.y + s * self.target_x + c * self.target_y

    def target_velocity_in_tank(self) -> tuple[np.ndarray | float, np.ndarray | float]:
        """Target velocity in the tank frame [m/s]."""
        c, s = self.cos_psi, self.sin_psi
        return c * self.target_vx - s * self.target_vy, s * self.target_vx + c * self.target_vy


def one_observation(obs: np.ndarray) -> np.ndarray:
    """One env's observation as float64 ``(OBS_SIZE,)`` or, with the fin block, ``(OBS_SIZE + FIN_OBS_SIZE,)``.

    What a controller acting on one observation takes in (a controller that does not read the fin block ignores it).

    Raises:
        ValueError: For another shape (a batch of observations included).
    """
    obs = np.asarray(obs, dtype=np.float64)
    if obs.ndim != 1 or obs.shape[0] not in OBS_SIZES:
        raise ValueError(f"obs must have shape ({OBS_SIZE},) or ({OBS_SIZES[1]},), got {obs.shape}")
    return obs


def decode(obs: np.ndarray) -> Observation:
    """Named view of an observation ``(..., OBS_SIZE)`` or, with the fin block, ``(..., OBS_SIZE + FIN_OBS_SIZE)``.

    Raises:
        ValueError: For another shape.
    """
    obs = np.asarray(obs)
    if obs.ndim == 0 or obs.shape[-1] not in OBS_SIZES:
        raise ValueError(f"an observation has {OBS_SIZE} entries in its last axis ({OBS_SIZE + FIN_OBS_SIZE} with "
                         f"observe_fins), got shape {obs.shape}")
    columns = [obs[..., j] for j in range(OBS_LAST_ACTION)]
    if obs.ndim == 1:
        columns = [float(v) for v in columns]
    fins = obs[..., OBS_FINS].reshape(obs.shape[:-1] + (2, FIN_OBS_FIELDS)) if obs.shape[-1] > OBS_SIZE else None
    return Observation(*columns, last_action=obs[..., OBS_ACTION], fins=fins)
