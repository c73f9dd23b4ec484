"""The tank: its size, the fish's outline in it, wall contact and the stopping distance, written once.

Every rule about the walls lives here and is used by the task kernels (wall contact of nose and tail,
:mod:`pectoral_gym.envs.tasks.kernels`), the NMPC's wall and stopping-band terms (``agents/controllers/stop_band.py``,
``agents/nmpc/problem.py``) and the robot's geofence (``pectoral_gym.hardware.safety.geofence.Geofence`` uses the same
numbers: ``tests/test_tank.py``).

The formulas are written once as arithmetic on their arguments (:func:`outline_circles`,
:func:`wall_gaps`, :func:`coast_distance` with ``ops``), so the same function serves Python floats,
numpy arrays and CasADi expressions; :func:`nose_tail_contact` is a compiled kernel (numba, inlined into
the task kernels) and callable from Python.

Frame and units: metres, seconds, radians; the tank frame has its origin at a corner, X along the long
side (``0 <= X <= TANK_LENGTH``, ``0 <= Y <= TANK_WIDTH``); ``psi`` is the heading from the X axis.

The outline (the robot's geofence): a capsule from nose to tail of radius ``C_p`` (the body's
half-width, also the fin pivots' lateral offset) and a disc of radius ``S_p`` (the fin span) around each
fin pivot ``(0, +-C_p)`` in the body frame, which holds the fin tip wherever the fin points.

The stopping distance: coasting with the fins still along one axis, eq. (19) with no fin force, is
``m dv/dt = -c1 v |v|``, so ``v dv/dx = -k v^2``, ``v(x) = v0 exp(-k x)``, and the distance a fish
coasting from ``v0`` covers before it has slowed to ``v_c`` is ``ln(v0 / v_c) / k`` (0 when ``v0 <= v_c``),
with ``k = c1 / max(m1, m2)`` (the larger mass: the slower decay). The band keeps that distance plus a
margin: a stopped fish crosses the margin line, if ever, no faster than ``v_c`` (the rule's
``contact_speed``), and the band is invariant while it coasts (``docs/guide/safety.md``, "Geofence").
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
from typing import Any, NamedTuple

import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["ROBOT_STOP_RULE", "TANK_LENGTH", "TANK_WIDTH", "Outline", "StopRule", "band_shortfall", "clearance",
           "coast_distance", "coast_rate", "distance_ahead", "nose_tail_contact", "outline_arrays", "outline_circles",
           "stop_need", "wall_gaps", "wall_shortfall"]

# The paper's tank (Sec. 4.1): the fish swims in a 2.30 m x 1.15 m area.
TANK_LENGTH = 2.30  # m, along the tank X axis
TANK_WIDTH = 1.15  # m, along the tank Y axis


class Outline(NamedTuple):
    """The fish's outline in the tank (module docstring).

    Attributes:
        half_length: Half the body length ``L / 2`` [m]: nose and tail on the body axis.
        width: ``C_p`` [m]: the capsule's radius and the fin pivots' lateral offset.
        span: ``S_p`` [m]: the radius of the fin discs.
    """

    half_length: float
    width: float
    span: float

    @classmethod
    def from_params(cls, params: Any) -> Outline:
        """The outline of a fish with these :class:`~pectoral_gym.model.params.FishParams`."""
        return cls(0.5 * float(params.body_length), float(params.fin_offset), float(params.fin_span))


@dataclass(frozen=True)
class StopRule:
    """The stopping band's rule: any part of the outline must keep ``stop_need(v)`` from each wall (module docstring).

    The one container of the rule's three numbers, and the one place they are checked: the envs (``EnvConfig``'s
    ``stop_rule``), the robot's supervisor (``SafetyConfig.stop_rule``, its ``Geofence``) and the controllers'
    band (``StopBand``, ``BandShield``, ``NMPCSettings.stop_band``) all hold one. The bounds are those under
    which the rule is a band at all:

    * every field finite: a NaN makes every comparison of the clearance against the need false, so a fish
      would never be inside the band and never be stopped; an infinite one makes the whole tank the band;
    * ``margin >= 0``: a negative margin lets the stopped fish's outline end past the wall line;
    * ``reaction_time >= 0``: the fins run on for ``t_r`` after a pose; a negative time would subtract distance;
    * ``contact_speed > 0``: quadratic drag never brings a coasting fish to rest (``v(x) = v0 exp(-k x)``), so
      the coast distance ``ln(v / v_c) / k`` is finite only for a speed ``v_c > 0`` to coast down to.

    Which values are safe enough (:data:`ROBOT_STOP_RULE`) is the safety design's choice, not this type's.
    Change a field with ``dataclasses.replace`` (checked again).

    Attributes:
        margin: Clearance kept on top of the stopping distance [m], >= 0.
        reaction_time: ``t_r`` [s], >= 0: from a pose to the fins halting (frame age, polling, radio).
        contact_speed: ``v_c`` [m/s], > 0: after a stop the fish crosses the margin line no faster than this.

    Raises:
        ValueError: Naming the field, for a value that is not a finite real number within its bound.
    """

    margin: float
    reaction_time: float
    contact_speed: float

    def __post_init__(self) -> None:
        for name, low, strict in (("margin", "0 m", False), ("reaction_time", "0 s", False),
                                  ("contact_speed", "0 m/s", True)):
            value = getattr(self, name)
            number = float(value) if isinstance(value, numbers.Real) and not isinstance(value, bool) else math.nan
            if not (math.isfinite(number) and (number > 0 if strict else number >= 0)):
                raise ValueError(f"StopRule.{name} must be a finite number {'>' if strict else '>='} {low}, "
                                 f"got {value!r}")
            object.__setattr__(self, name, number)

    @classmethod
    def coerce(cls, value: Any) -> StopRule:
        """``value`` as a :class:`StopRule`: one as it is, ``(margin, reaction_time, contact_speed)`` or a mapping.

        For the settings that arrive as plain data (env keyword arguments, YAML, JSON).

        Raises:
            ValueError: For another shape, or a value the rule refuses.
        """
        if isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            names = [f.name for f in fields(cls)]
            if set(value) != set(names):
                raise ValueError(f"a stop rule needs exactly the keys {names}, got {sorted(value)}")
            return cls(**value)
        if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
            raise ValueError(f"a stop rule is (margin, reaction_time, contact_speed), got {value!r}")
        values = tuple(value)
        if len(values) != 3:
            raise ValueError(f"a stop rule is (margin, reaction_time, contact_speed), got {value!r}")
        return cls(*values)

    def as_tuple(self) -> tuple[float, float, float]:
        """``(margin [m], reaction_time [s], contact_speed [m/s])``: the kernels' packed form, and JSON's."""
        return self.margin, self.reaction_time, self.contact_speed


#: The robot's rule (its safety supervisor's defaults, ``pectoral_gym.hardware.safety.rules.SafetyConfig``), which
#: the simulated envs' ``stop_band`` applies too (``docs/guide/safety.md``, "Geofence"). 0.03 m/s is the speed a Table-1
#: fish coasting from any speed is below after 5 s (``1 / (k T)`` = 0.031 m/s), the earlier rule's bound.
ROBOT_STOP_RULE = StopRule(margin=0.05, reaction_time=0.15, contact_speed=0.03)


def coast_rate(params: Any) -> float:
    """``k = c1 / max(m1, m2)`` [1/m] of a :class:`~pectoral_gym.model.params.FishParams` (eq. 19, fins still)."""
    return params.c1 / max(params.m1, params.m2)


def coast_distance(speed: Any, k: float, contact_speed: float, ops: Any = np) -> Any:
    """Distance [m] a fish coasting from ``speed`` [m/s] with its fins still covers until down to ``contact_speed``.

    ``ln(max(v, v_c) / v_c) / k`` (module docstring): 0 at or below ``v_c``, also for a negative speed.

    Args:
        speed: Speed towards the wall [m/s].
        k: :func:`coast_rate` [1/m], > 0.
        contact_speed: ``v_c`` [m/s], > 0.
        ops: ``numpy`` (floats and arrays) or ``casadi`` (``fmax``, ``log``).
    """
    return ops.log(ops.fmax(speed, contact_speed) / contact_speed) / k


def stop_need(speed: Any, k: float, rule: StopRule, react: Any = None, ops: Any = np) -> Any:
    """Clearance [m] a fish at ``speed`` [m/s] towards a wall needs: ``margin + v t_r + ln(max(v, v_c) / v_c) / k``.

    The speed held for the reaction time (the fins still run until the stop arrives), then the coast of
    :func:`coast_distance` down to the rule's contact speed.

    Args:
        speed: Speed towards the wall [m/s]; negative counts as 0.
        k: :func:`coast_rate` [1/m].
        rule: The :class:`StopRule`.
        react: Reaction time [s] to use instead of ``rule.reaction_time`` (the geofence adds a pose's age).
        ops: ``numpy`` or ``casadi``.
    """
    v = ops.fmax(speed, 0.0)
    t_r = rule.reaction_time if react is None else react
    return rule.margin + v * t_r + coast_distance(v, k, rule.contact_speed, ops)


def outline_circles(x: Any, y: Any, c: Any, s: Any, outline: Outline) -> tuple[tuple[Any, Any, float], ...]:
    """The outline's four circles ``(centre X, centre Y, radius)``: nose, tail, right and left fin pivot [m].

    Args:
        x, y: Centre of mass in the tank frame [m].
        c, s: ``cos psi``, ``sin psi`` of the heading.
        outline: The fish's :class:`Outline`.
    """
    h, w, span = outline
    return ((x + c * h, y + s * h, w), (x - c * h, y - s * h, w),  # nose, tail
            (x + s * w, y - c * w, span), (x - s * w, y + c * w, span))  # right pivot (0, -C_p), left (0, +C_p)


def wall_gaps(px: Any, py: Any, r: Any = 0.0) -> tuple[Any, Any, Any, Any]:
    """Distances [m] of a circle (centre ``(px, py)``, radius ``r``) to the walls ``X = 0, X = L, Y = 0, Y = W``.

    Negative: across the wall.
    """
    return px - r, TANK_LENGTH - px - r, py - r, TANK_WIDTH - py - r


def distance_ahead(x: float, y: float, c: float, s: float) -> float:
    """Distance [m] from ``(x, y)`` along the unit direction ``(c, s)`` to the first wall (inf: none ahead)."""
    ahead = []
    for position, direction, size in ((x, c, TANK_LENGTH), (y, s, TANK_WIDTH)):
        if direction > 1e-9:
            ahead.append((size - position) / direction)
        elif direction < -1e-9:
            ahead.append(-position / direction)
    return min(ahead, default=math.inf)


def outline_arrays(x: float, y: float, psi: float, outline: Outline) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``(4, 2)`` (nose, tail, right and left fin pivot) and radii ``(4,)`` of the outline [m]."""
    circles = outline_circles(x, y, math.cos(psi), math.sin(psi), outline)
    return np.array([[px, py] for px, py, _ in circles]), np.array([r for _, _, r in circles])


def clearance(x: float, y: float, psi: float, outline: Outline) -> np.ndarray:
    """Distance [m] from the outline to the walls ``X = 0, X = L, Y = 0, Y = W`` (negative: across), ``(4,)``."""
    gaps = [wall_gaps(px, py, r) for px, py, r in outline_circles(x, y, math.cos(psi), math.sin(psi), outline)]
    return np.min(np.array(gaps), axis=0)


def wall_shortfall(x: Any, y: Any, c: Any, s: Any, half_length: float, margin: float, ops: Any = np,
                   total: Any = 0.0, weight: float = 1.0) -> Any:
    """``total`` plus ``weight`` times the squared shortfalls [m^2] of nose and tail below ``margin`` from each wall.

    The NMPC's wall term without the stopping band: per point (nose, then tail) and wall
    (:func:`wall_gaps` order), ``fmax(margin - gap, 0)^2``, added to ``total`` one by one.

    Args:
        x, y: Centre of mass [m]. c, s: ``cos psi``, ``sin psi``.
        half_length: Half the body length [m]. margin: Wanted clearance [m].
        ops: ``numpy`` or ``casadi`` (``fmax``).
        total: What the terms are added to (a float or an expression).
        weight: Factor of each term.
    """
    for sign in (1.0, -1.0):  # nose, tail
        for gap in wall_gaps(x + sign * half_length * c, y + sign * half_length * s):
            term = ops.fmax(margin - gap, 0.0) ** 2
            total = total + (term if weight == 1.0 else weight * term)
    return total


@njit(inline="always")
def nose_tail_contact(x, y, c, s, half_length):
    """Whether the nose or the tail (``(x, y) +- half_length (c, s)``) is outside the tank (on a wall: inside).

    The env's wall contact (``wall_penalty``, termination). Args: position [m], ``cos psi``, ``sin psi``,
    half the body length [m]. Returns a bool.
    """
    contact = False
    for sign in (1.0, -1.0):  # nose, tail
        px = x + sign * half_length * c
        py = y + sign * half_length * s
        if not (0.0 <= px <= TANK_LENGTH and 0.0 <= py <= TANK_WIDTH):
            contact = True
    return contact


@njit(inline="always")
def band_shortfall(x, y, c, s, toward, outline, k, margin, react, contact_speed):
    """The largest shortfall [m] of the outline's clearance below the stopping need over the four walls (> 0: inside).

    The compiled form of :func:`stop_need` against :func:`outline_circles` and :func:`wall_gaps` (the robot's
    geofence and the envs' ``stop_band``; ``tests/test_tank.py`` checks it against them).

    Args:
        x, y: Centre of mass [m]. c, s: ``cos psi``, ``sin psi``.
        toward: Speeds ``(4,)`` towards the walls ``X = 0, X = L, Y = 0, Y = W`` [m/s] (negative counts as 0).
        outline: ``(half_length, width, span)`` [m] (:class:`Outline`).
        k: :func:`coast_rate` [1/m]. margin, react, contact_speed: The :class:`StopRule`'s margin [m], reaction
            time [s] and contact speed [m/s].
    """
    h, w, span = outline[0], outline[1], outline[2]
    needs = (_need(toward[0], k, margin, react, contact_speed), _need(toward[1], k, margin, react, contact_speed),
             _need(toward[2], k, margin, react, contact_speed), _need(toward[3], k, margin, react, contact_speed))
    worst = -math.inf
    for q in range(4):  # nose, tail, right pivot (0, -C_p), left pivot (0, +C_p): outline_circles' order
        if q == 0:
            px, py, r = x + c * h, y + s * h, w
        elif q == 1:
            px, py, r = x - c * h, y - s * h, w
        elif q == 2:
            px, py, r = x + s * w, y - c * w, span
        else:
            px, py, r = x - s * w, y + c * w, span
        gaps = (px - r, TANK_LENGTH - px - r, py - r, TANK_WIDTH - py - r)  # wall_gaps' order
        for j in range(4):
            worst = max(worst, needs[j] - gaps[j])
    return worst


@njit(inline="always")
def _need(speed, k, margin, react, contact_speed):
    """:func:`stop_need` for floats, compiled."""
    v = max(speed, 0.0)
    return margin + v * react + math.log(max(v, contact_speed) / contact_speed) / k
