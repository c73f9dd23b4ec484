"""Where an episode starts: the task geometry, an episode's random draws, and the start states it gives.

A reset runs in two parts, so that the single and the vector env draw the same numbers: per env,
:func:`draw_episode` takes the episode's random numbers from its own generator (in Python); then
:func:`start_states`, compiled and batched, turns the draws of all reset envs into targets
(``goal``: a point; ``track``: the reference ellipse, :mod:`pectoral_gym.envs.tasks.reference_ellipse`)
and fish start states. The observations of the reset envs follow
(:func:`pectoral_gym.envs.tasks.kernels.observe_reset`). Nothing here imports Gymnasium.

Units: metres, seconds, radians; the tank frame has its origin at a corner.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from pectoral_gym.envs.layout import (
    C_GOAL_INSET,
    C_REF_SPEED,
    C_START_INSET,
    C_TASK,
    E_A,
    E_B,
    E_CX,
    E_CY,
    E_DIR,
    E_PHASE,
    E_TVX,
    E_TVY,
    E_TX,
    E_TY,
    GOAL,
)
from pectoral_gym.envs.tasks.reference_ellipse import set_reference
from pectoral_gym.model.jit import entry_point, njit
from pectoral_gym.model.tank import TANK_LENGTH, TANK_WIDTH

__all__ = ["GOAL_CANDIDATES", "GOAL_MAX_BLOCKS", "GOAL_MAX_DISTANCE", "GOAL_MIN_DISTANCE",
           "START_INSET", "TANK_X", "TANK_Y", "TRACK_A_RANGE", "TRACK_B_RANGE", "TRACK_HEADING_NOISE",
           "TRACK_START_RADIUS", "draw_episode", "pin_start", "start_states"]

# Tank and task geometry [m], [rad].
TANK_X = TANK_LENGTH  # tank length along X [m], one source: pectoral_gym.model.tank
TANK_Y = TANK_WIDTH  # tank width along Y [m]
START_INSET = 0.3  # goal task: start this far from the walls [m] (EnvConfig.start_inset's default)
GOAL_MIN_DISTANCE = 0.3  # goal task: least start-goal distance [m]
GOAL_MAX_DISTANCE = 1.0  # goal task: largest start-goal distance [m]
GOAL_CANDIDATES = 16  # goal candidates drawn per rejection-sampling block
GOAL_MAX_BLOCKS = 64  # bounded rejection sampling
TRACK_A_RANGE = (0.5, 0.8)  # track task: semi-axis along X [m]
TRACK_B_RANGE = (0.25, 0.4)  # track task: semi-axis along Y [m]
TRACK_START_RADIUS = 0.1  # track task: start within this distance of the reference point [m]
TRACK_HEADING_NOISE = 0.3  # track task: start heading = tangent +- this [rad]


@njit
def _pick_goal(draws, candidates, inset):
    """Rejection sampling: the first candidate (uniforms in pairs) that is a valid goal for the start in ``draws``."""
    for k in range(candidates.shape[0] // 2):
        gx = inset + candidates[2 * k] * (TANK_X - 2.0 * inset)
        gy = inset + candidates[2 * k + 1] * (TANK_Y - 2.0 * inset)
        d = math.hypot(gx - draws[0], gy - draws[1])
        if GOAL_MIN_DISTANCE <= d <= GOAL_MAX_DISTANCE:
            draws[3] = gx
            draws[4] = gy
            return True
    return False


@functools.cache
def _pick_goal_call():
    """:func:`_pick_goal`'s compiled entry point for its one set of argument types (float64 C arrays, a float)."""
    return entry_point(_pick_goal, (np.zeros(8), np.zeros(2 * GOAL_CANDIDATES), 0.0))


def draw_episode(rng: np.random.Generator, task: int, cfg: np.ndarray) -> np.ndarray:
    """Draw one episode's random start from ``rng``; the same sequence of draws for single and vector envs.

    Args:
        rng: The episode's generator.
        task: ``GOAL`` or ``TRACK``.
        cfg: The packed settings (``goal``: ``C_START_INSET``, ``C_GOAL_INSET``).

    Returns:
        8 numbers: for ``GOAL`` ``(X, Y, psi, goal X, goal Y, 0, 0, 0)``;
        for ``TRACK`` ``(a, b, direction, phase, offset radius, offset angle, heading noise, 0)``.
    """
    draws = np.zeros(8)
    if task == GOAL:
        u = rng.random(3 + 2 * GOAL_CANDIDATES)
        # Python floats: the same IEEE double arithmetic as numpy's scalars, at a fraction of their cost
        start_inset, goal_inset = float(cfg[C_START_INSET]), float(cfg[C_GOAL_INSET])
        u0, u1, u2 = u[:3].tolist()
        draws[0] = start_inset + u0 * (TANK_X - 2.0 * start_inset)
        draws[1] = start_inset + u1 * (TANK_Y - 2.0 * start_inset)
        draws[2] = -math.pi + 2.0 * math.pi * u2
        candidates = u[3:]  # C-contiguous, as every rng.random array: the entry point's types
        pick = _pick_goal_call()
        for _ in range(GOAL_MAX_BLOCKS):
            if pick(draws, candidates, goal_inset):
                return draws
            candidates = rng.random(2 * GOAL_CANDIDATES)
        raise RuntimeError("could not place a goal at the required distance from the start")  # pragma: no cover
    u = rng.random(7)
    draws[0] = TRACK_A_RANGE[0] + u[0] * (TRACK_A_RANGE[1] - TRACK_A_RANGE[0])
    draws[1] = TRACK_B_RANGE[0] + u[1] * (TRACK_B_RANGE[1] - TRACK_B_RANGE[0])
    draws[2] = 1.0 if u[2] < 0.5 else -1.0
    draws[3] = -math.pi + 2.0 * math.pi * u[3]
    draws[4] = TRACK_START_RADIUS * math.sqrt(u[4])  # uniform in the disc
    draws[5] = -math.pi + 2.0 * math.pi * u[5]
    draws[6] = TRACK_HEADING_NOISE * (2.0 * u[6] - 1.0)
    return draws


def pin_start(options: dict | None, task: int) -> np.ndarray | None:
    """The draws ``reset(options=...)`` fixes: ``(8,)``, NaN where the episode's own draw stays; ``None``: none.

    ``options`` (goal task): ``"start"``, the fish's pose ``(X [m], Y [m], psi [rad])``, and ``"goal"``, the
    goal ``(X [m], Y [m])``, either or both; both positions inside the tank. The fish starts at rest, as
    always; a start or goal drawn where the other is pinned keeps its own distribution, not the start-goal
    distance (a deploy's logged episode, a scenario of one's own).

    Raises:
        ValueError: Unknown keys, the track task, or a start or goal that is not finite numbers in the tank.
    """
    if not options:
        return None
    unknown = sorted(set(options) - {"start", "goal"})
    if unknown:
        raise ValueError(f"reset options: unknown keys {unknown}; the goal task takes 'start' (X, Y, psi) and 'goal' "
                         "(X, Y)")
    if task != GOAL:
        raise ValueError("reset options 'start' and 'goal' are the goal task's; the track task draws its ellipse")
    pinned = np.full(8, np.nan)
    for key, size, slot in (("start", 3, 0), ("goal", 2, 3)):
        if key not in options:
            continue
        try:
            values = np.asarray(options[key], dtype=float).reshape(size)
        except (TypeError, ValueError):
            raise ValueError(f"reset options[{key!r}] must be {size} numbers, got {options[key]!r}") from None
        x, y = values[0], values[1]
        if not (np.all(np.isfinite(values)) and 0.0 < x < TANK_X and 0.0 < y < TANK_Y):
            raise ValueError(f"reset options[{key!r}] must be finite with its position inside the "
                             f"{TANK_X} x {TANK_Y} m tank, got {options[key]!r}")
        pinned[slot:slot + size] = values
    return pinned


@njit
def start_states(index, draws, cfg, ep, start):
    """Set the targets of the envs in ``index`` from ``draws`` (see :func:`draw_episode`); write start states.

    ``start`` ``(len(index), 6)`` receives the fish states (at rest).
    """
    task = int(cfg[C_TASK])
    for k in range(index.shape[0]):
        i = index[k]
        d = draws[k]
        start[k, 3:] = 0.0
        if task == GOAL:
            start[k, 0], start[k, 1], start[k, 2] = d[0], d[1], d[2]
            ep[i, E_TX], ep[i, E_TY], ep[i, E_TVX], ep[i, E_TVY] = d[3], d[4], 0.0, 0.0
            ep[i, E_CX] = ep[i, E_CY] = ep[i, E_A] = ep[i, E_B] = ep[i, E_DIR] = ep[i, E_PHASE] = 0.0
        else:
            ep[i, E_CX], ep[i, E_CY] = 0.5 * TANK_X, 0.5 * TANK_Y
            ep[i, E_A], ep[i, E_B], ep[i, E_DIR], ep[i, E_PHASE] = d[0], d[1], d[2], d[3]
            set_reference(i, ep, cfg[C_REF_SPEED])
            tangent = math.atan2(d[2] * d[1] * math.cos(d[3]), -d[2] * d[0] * math.sin(d[3]))
            start[k, 0] = ep[i, E_TX] + d[4] * math.cos(d[5])
            start[k, 1] = ep[i, E_TY] + d[4] * math.sin(d[5])
            start[k, 2] = tangent + d[6]
