"""Turn-then-straight path lengths against closed forms and a brute-force search over the arc."""

import math

import numpy as np
import pytest

from pectoral_gym.agents.controllers.turning import turn_path_length

R = 0.25


def _brute_force(bx: float, by: float, radius: float) -> float:
    """Shortest arc-then-straight path by sampling the arc angle (either turn) until the point lies ahead."""
    best = math.inf
    for side in (1.0, -1.0):
        for theta in np.linspace(0.0, 2.0 * math.pi, 200001):
            # pose after turning by theta on the circle of centre (0, side R)
            px, py = radius * math.sin(theta), side * radius * (1.0 - math.cos(theta))
            hx, hy = math.cos(theta), side * math.sin(theta)
            rx, ry = bx - px, by - py
            along = rx * hx + ry * hy
            if along >= 0 and abs(rx * hy - ry * hx) < 2e-4:  # the point lies on the ray ahead
                best = min(best, radius * theta + along)
                break
    return best


def test_closed_forms():
    assert turn_path_length(0, 0, 0, 0.7, 0, R) == pytest.approx(0.7)  # straight ahead
    assert turn_path_length(0, 0, 0, 0, 2 * R, R) == pytest.approx(math.pi * R)  # beside: half a circle
    assert turn_path_length(0, 0, 0, R, -R, R) == pytest.approx(0.5 * math.pi * R)  # a quarter circle right
    # heading and position are only a change of frame: the same point seen from a rotated, moved fish
    psi = 1.1
    gx, gy = 0.3 + R * math.cos(psi) - R * math.sin(psi), -0.2 + R * math.sin(psi) + R * math.cos(psi)
    assert turn_path_length(0.3, -0.2, psi, gx, gy, R) == pytest.approx(0.5 * math.pi * R)


@pytest.mark.parametrize("point", [(-0.3, 0.05), (0.1, 0.3), (0.0, 0.25), (-0.05, -0.1), (0.6, -0.4), (-1.0, 0.0)])
def test_matches_brute_force(point):
    bx, by = point
    assert turn_path_length(0, 0, 0, bx, by, R) == pytest.approx(_brute_force(bx, by, R), abs=2e-3)


def test_inside_a_circle_turns_the_other_way():
    # the centre of the left circle is only reachable by a right turn first: longer than the half circle
    assert turn_path_length(0, 0, 0, 0, R, R) > math.pi * R
    assert turn_path_length(0, 0, 0, 0, R, R) == pytest.approx(turn_path_length(0, 0, 0, 0, -R, R))


def test_rejects_bad_radius():
    with pytest.raises(ValueError, match="radius"):
        turn_path_length(0, 0, 0, 1, 1, 0.0)
