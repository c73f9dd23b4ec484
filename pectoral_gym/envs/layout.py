"""The packed arrays of the task kernels (:mod:`pectoral_gym.envs.tasks.kernels`): index constants and named views.

Kernels read and write flat float64 arrays for speed; every field has a name
here, and Python code reads them through the named views below (or the
accessors of :class:`~pectoral_gym.envs.core.EnvCore`), never by bare index.
The observation has its own module, :mod:`pectoral_gym.envs.observation`.
Units: metres, seconds, radians, joules; the tank frame has its origin at a
corner, X along the long side.

``cfg`` ``(N_CFG,)``: the task settings, packed by ``EnvConfig.cfg_array``.

| index | name | meaning | unit |
|---|---|---|---|
| ``C_DT`` | ``control_period`` | time between actions | s |
| ``C_TASK`` | ``task`` | ``GOAL`` or ``TRACK`` | - |
| ``C_RANGES`` .. ``+7`` | ``*_range`` | (low, high) of bias, amplitude, period, ratio | rad, rad, s, - |
| ``C_W_PROGRESS`` | ``progress_weight`` | goal: reward per metre of approach | 1/m |
| ``C_GOAL_BONUS`` | ``goal_bonus`` | goal: reward on reaching the goal | - |
| ``C_WALL`` | ``wall_penalty`` | penalty when the nose or tail leaves the tank | - |
| ``C_W_ENERGY`` | ``energy_weight`` | penalty per joule of fin work | 1/J |
| ``C_TIME`` | ``time_penalty`` | goal: penalty per step | - |
| ``C_W_TRACKING`` | ``tracking_weight`` | track: penalty per metre of distance per step | 1/m |
| ``C_GOAL_RADIUS`` | ``goal_radius`` | goal: success radius | m |
| ``C_REF_SPEED`` | ``ref_speed`` | track: speed of the reference point | m/s |
| ``C_START_INSET`` | ``start_inset`` | goal: least distance of a start from the walls | m |
| ``C_GOAL_INSET`` | ``goal_inset`` | goal: least distance of a goal from the walls | m |
| ``C_BAND`` | ``stop_band`` | 1.0: the stopping band ends the episode and prices ``O_COST`` | - |
| ``C_BAND_MARGIN`` .. ``+2`` | ``stop_rule`` | margin, reaction time, contact speed (``tank.StopRule``) | m, s, m/s |
| ``C_FIN_RATE`` | ``servo_limit`` | fastest fin rate; faster patterns run with a longer period (0: none) | rad/s |

``ep`` ``(n, N_EP)``: per-episode state, set at reset and updated every step
(:class:`ReferenceEllipse` names the ellipse block).

| index | meaning | unit |
|---|---|---|
| ``E_TX, E_TY`` | target position, tank frame | m |
| ``E_TVX, E_TVY`` | target velocity, tank frame (zero for ``goal``) | m/s |
| ``E_CX, E_CY`` | track: centre of the reference ellipse | m |
| ``E_A, E_B`` | track: semi-axes along X and Y | m |
| ``E_DIR`` | track: direction of travel, +1 (counter-clockwise) or -1 | - |
| ``E_PHASE`` | track: ellipse phase of the reference point, in [-pi, pi) | rad |
| ``E_DPREV`` | distance to the target after the previous step | m |

``fish`` ``(n, N_FISH)``: values derived from each env's ``FishParams``,
refilled when the parameters change (:func:`fish_array`, :class:`FishConstants`).

| index | meaning | unit |
|---|---|---|
| ``F_LENGTH`` | body length ``L`` (wall contact of nose and tail) | m |
| ``F_SPAN`` | fin span ``S_p`` | m |
| ``F_KDRAG`` | fin drag constant ``k`` of the mean fin power (``docs/model.md``) | kg |
| ``F_WIDTH`` | ``C_p``: the body's half-width and the fin pivots' lateral offset (the outline) | m |
| ``F_KCOAST`` | coasting rate ``c1 / max(m1, m2)`` of the stopping distance (``model.tank.coast_rate``) | 1/m |

``out`` ``(n, N_OUT)``: the result of the last step (zero after a reset).

| index | meaning | unit |
|---|---|---|
| ``O_REWARD`` | reward, the sum of the task's terms (``tasks.TERMS``) | - |
| ``O_PROGRESS, O_GOAL, O_WALL, O_ENERGY, O_TIME, O_TRACKING`` | reward terms (zero where the task has none) | - |
| ``O_DISTANCE`` | distance from the centre of mass to the target | m |
| ``O_TERMINATED`` | 1.0 if the episode ended (wall contact or goal reached) | - |
| ``O_SUCCESS`` | 1.0 if the goal was reached | - |
| ``O_COST`` | with ``stop_band``: 1.0 if any part of the fish is inside the stopping band | - |

``actions`` ``(n, ACTION_SIZE)``: normalised, in [-1, 1]; per fin (right fin
first) the four entries ``A_BIAS, A_AMPLITUDE, A_PERIOD, A_RATIO`` (offset
``FIN_ACTIONS`` for the left fin). ``beats`` ``(n, 2, 4)``: the commanded fin
patterns ``(bias [rad], amplitude [rad], period [s], ratio [-])``, right fin
first. ``draws`` ``(8,)`` per env: the random start of one episode, see
:func:`pectoral_gym.envs.tasks.kernels.draw_episode`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from pectoral_gym.model import tank
from pectoral_gym.model.params import FishParams, body_coefficients

__all__ = [
    "GOAL", "TRACK", "ACTION_SIZE", "FIN_ACTIONS", "A_BIAS", "A_AMPLITUDE", "A_PERIOD", "A_RATIO",
    "C_DT", "C_TASK", "C_RANGES", "C_W_PROGRESS", "C_GOAL_BONUS", "C_WALL", "C_W_ENERGY", "C_TIME",
    "C_W_TRACKING", "C_GOAL_RADIUS", "C_REF_SPEED", "C_START_INSET", "C_GOAL_INSET", "C_BAND", "C_BAND_MARGIN",
    "C_BAND_REACTION", "C_BAND_CONTACT", "C_FIN_RATE", "N_CFG",
    "E_TX", "E_TY", "E_TVX", "E_TVY", "E_CX", "E_CY", "E_A", "E_B", "E_DIR", "E_PHASE", "E_DPREV", "N_EP",
    "F_LENGTH", "F_SPAN", "F_KDRAG", "F_WIDTH", "F_KCOAST", "N_FISH",
    "O_REWARD", "O_PROGRESS", "O_GOAL", "O_WALL", "O_ENERGY", "O_TIME", "O_TRACKING", "O_DISTANCE",
    "O_TERMINATED", "O_SUCCESS", "O_COST", "N_OUT",
    "FishConstants", "ReferenceEllipse", "fish_array",
]

GOAL, TRACK = 0, 1  # task ids (cfg[C_TASK])

# actions
A_BIAS, A_AMPLITUDE, A_PERIOD, A_RATIO = 0, 1, 2, 3
FIN_ACTIONS = 4  # entries per fin
ACTION_SIZE = 2 * FIN_ACTIONS

# cfg
C_DT, C_TASK, C_RANGES = 0, 1, 2  # C_RANGES..C_RANGES+7: (low, high) of bias, amplitude, period, ratio
C_W_PROGRESS, C_GOAL_BONUS, C_WALL, C_W_ENERGY, C_TIME, C_W_TRACKING = 10, 11, 12, 13, 14, 15
C_GOAL_RADIUS, C_REF_SPEED = 16, 17
C_START_INSET, C_GOAL_INSET = 18, 19
C_BAND, C_BAND_MARGIN, C_BAND_REACTION, C_BAND_CONTACT = 20, 21, 22, 23
C_FIN_RATE = 24
N_CFG = 25

# ep
E_TX, E_TY, E_TVX, E_TVY = 0, 1, 2, 3
E_CX, E_CY, E_A, E_B, E_DIR, E_PHASE = 4, 5, 6, 7, 8, 9
E_DPREV = 10
N_EP = 11

# fish
F_LENGTH, F_SPAN, F_KDRAG, F_WIDTH, F_KCOAST = 0, 1, 2, 3, 4
N_FISH = 5

# out
O_REWARD, O_PROGRESS, O_GOAL, O_WALL, O_ENERGY, O_TIME, O_TRACKING = 0, 1, 2, 3, 4, 5, 6
O_DISTANCE, O_TERMINATED, O_SUCCESS, O_COST = 7, 8, 9, 10
N_OUT = 11


class FishConstants(NamedTuple):
    """The ``fish`` row of one env: values the task kernels take from its ``FishParams``."""

    body_length: float  # [m]
    fin_span: float  # [m]
    fin_drag_constant: float  # [kg]
    fin_offset: float  # C_p [m]
    coast_rate: float  # c1 / max(m1, m2) [1/m]

    @classmethod
    def of(cls, params: FishParams) -> FishConstants:
        """The constants of one parameter set."""
        return cls(float(params.body_length), float(params.fin_span), float(params.fin_drag_constant),
                   float(params.fin_offset), float(tank.coast_rate(body_coefficients(params))))


class ReferenceEllipse(NamedTuple):
    """The track task's reference ellipse of one env (``ep[E_CX:E_PHASE + 1]``); all zero for ``goal``."""

    cx: float  # centre X [m]
    cy: float  # centre Y [m]
    a: float  # semi-axis along X [m]
    b: float  # semi-axis along Y [m]
    direction: float  # +1 counter-clockwise, -1 clockwise [-]
    phase: float  # phase of the reference point [rad]: (cx + a cos phase, cy + b sin phase)


def fish_array(params: Sequence[FishParams]) -> np.ndarray:
    """The ``fish`` array ``(len(params), N_FISH)`` of a sequence of parameter sets (one per env)."""
    rows = [FishConstants.of(p) for p in params]
    return np.array(rows, dtype=np.float64).reshape(len(rows), N_FISH)
