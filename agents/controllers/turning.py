"""Turning-circle geometry for the model-based controllers: the path length to a point, turning at most so tight.

A fish that turns no tighter than a radius ``R`` (the full model: about 0.23-0.25 m, see
``docs/notes/2026-12-01-nmpc-rounds.md``) reaches a point target fastest along a turn-then-straight path (a Dubins path
to a point, free terminal heading). In the body frame (x ahead, y to the left) the left turning
circle has its centre at ``C = (0, R)``; a target ``G`` outside it (``d = |G - C| >= R``) is reached
by an arc to the tangent point ``T`` and the tangent ``|G - T| = sqrt(d^2 - R^2)``. ``T`` lies at the
angle ``atan2(G_y - R, G_x) - acos(R / d)`` seen from ``C``, and the start point at ``-pi/2``; the arc
runs anticlockwise between the two. The right turn is the mirror image (``y -> -y``). A target inside
one circle lies outside the other (the circles touch only at the fish), so at least one of the two
paths exists; the length is the shorter one. (The exact Dubins optimum inside a circle is sometimes a
shorter turn-turn path; the turn-then-straight length is an upper bound there.)
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model import tank

__all__ = ["SPIN_CYCLE", "circle_room", "inside_turning_circle", "mirror", "turn_path_length", "turn_paths"]

# The on-the-spot turn of pectoral_gym.agents.nmpc.spin (which explains it; found by docs/validation/nmpc/spin_cycle.py
# for a 0.5 s period and ratio 5). Left turn (omega > 0), one row per control period: amplitude right/left, bias
# right/left [deg] (the FinInputs order). The left fin parks and only swings its bias: its sweeps are the
# transitional strokes that cancel the right fin's thrust.
SPIN_CYCLE = np.radians([
    [6.3, 0.1, 80.8, 66.3],
    [7.8, 0.1, 92.2, 80.3],
    [8.4, 0.0, 108.1, 93.9],
    [6.1, 0.0, 70.9, 54.4],
])


def inside_turning_circle(distance: float, bearing: float, radius: float) -> bool:
    """Whether a point at ``distance`` [m] and body-frame ``bearing`` [rad] lies inside a turning circle of ``radius``.

    The circle on the point's side passes through the fish, its centre ``radius`` abeam: the point lies inside it
    when ``distance < 2 radius |sin bearing|``; the fish cannot turn into it and must swim on first.
    """
    return distance < 2.0 * radius * abs(math.sin(bearing))


def mirror(u: np.ndarray) -> np.ndarray:
    """The mirror image of fin inputs ``(..., 4)`` (FinInputs order): the fins swap patterns.

    A fin's lateral force and moment change sign with its side (eq. 25's side sign), its thrust does
    not, so swapping the two fins' patterns mirrors the motion about the body axis.
    """
    u = np.asarray(u)
    return u[..., [1, 0, 3, 2]]


def _left_turn_path(gx: float, gy: float, radius: float) -> tuple[float, float]:
    """Arc angle [rad] and straight length [m] of the left-turn path to the body-frame point ``(gx, gy)``.

    ``(inf, inf)`` if the point is inside the circle.
    """
    dx, dy = gx, gy - radius
    d = math.hypot(dx, dy)
    if d < radius:
        return math.inf, math.inf
    tangent = math.atan2(dy, dx) - math.acos(min(1.0, radius / d))
    arc = (tangent + 0.5 * math.pi) % (2.0 * math.pi)
    if arc > 2.0 * math.pi - 1e-9:  # straight ahead: rounding must not make it a full circle
        arc = 0.0
    return arc, math.sqrt(max(d * d - radius * radius, 0.0))


def turn_paths(x: float, y: float, psi: float, gx: float, gy: float,
               radius: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Arc angle [rad] and straight length [m] of the left-turn and of the right-turn path.

    Arguments as :func:`turn_path_length`; ``(inf, inf)`` for a turn whose circle holds the target.
    """
    if not radius > 0:
        raise ValueError(f"radius must be > 0 m, got {radius!r}")
    c, s = math.cos(psi), math.sin(psi)
    ex, ey = gx - x, gy - y
    bx, by = c * ex + s * ey, -s * ex + c * ey
    return _left_turn_path(bx, by, radius), _left_turn_path(bx, -by, radius)


def circle_room(x: float, y: float, psi: float, side: float, radius: float) -> float:
    """Least distance [m] from the turning circle (``side`` +1 left, -1 right) to a tank wall (< 0: it crosses one).

    The circle of radius ``radius`` touches the pose ``(x, y, psi)``; its centre lies ``radius`` to that side.
    """
    cx, cy = x - side * radius * math.sin(psi), y + side * radius * math.cos(psi)
    return min(tank.wall_gaps(cx, cy, radius))


def turn_path_length(x: float, y: float, psi: float, gx: float, gy: float, radius: float) -> float:
    """Shortest turn-then-straight path [m] from the pose ``(x, y, psi)`` to the point ``(gx, gy)`` (tank frame).

    Args:
        x: Position of the fish [m].
        y: Position of the fish [m].
        psi: Heading [rad].
        gx: Target position [m].
        gy: Target position [m].
        radius: Smallest turning radius [m], > 0.

    Returns:
        The length of the shorter of the left-turn and right-turn paths (module docstring).

    Raises:
        ValueError: If ``radius`` is not positive.
    """
    return min(radius * arc + straight for arc, straight in turn_paths(x, y, psi, gx, gy, radius))
