"""pectoral_gym.tank, the one home of the tank's rules, against the robot's geofence and the env's wall contact."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from agents.stop_band import StopBand, band_violation
from hardware.safety import Geofence
from pectoral_gym import tank
from pectoral_gym.params import FishParams


def test_outline_clearance_and_coasting_agree_with_the_geofence_on_random_poses_and_speeds():
    params = FishParams()
    fence = Geofence(params, margin=0.05, reaction_time=0.15, horizon=5.0)
    outline = tank.Outline.from_params(params)
    k = tank.coast_rate(params)
    assert k == pytest.approx(fence.k, rel=1e-15)
    assert (outline.half_length, outline.width, outline.span) == (fence.half_length, fence.width, fence.span)
    rng = np.random.default_rng(0)
    for _ in range(200):
        x, y = rng.uniform(-0.2, tank.TANK_LENGTH + 0.2), rng.uniform(-0.2, tank.TANK_WIDTH + 0.2)
        psi, speed = rng.uniform(-math.pi, math.pi), rng.uniform(-0.1, 0.5)
        centres, radii = tank.outline_arrays(x, y, psi, outline)
        fence_centres, fence_radii = fence.outline(x, y, psi)
        np.testing.assert_allclose(centres, fence_centres, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(radii, fence_radii)
        np.testing.assert_allclose(tank.clearance(x, y, psi, outline), fence.clearance(x, y, psi), rtol=0, atol=1e-15)
        assert tank.coast_distance(speed, k, fence.horizon) == pytest.approx(fence.coast(speed), rel=1e-14, abs=1e-18)


def test_the_stop_band_is_zero_exactly_where_the_geofence_lets_the_fish_swim_on():
    params = FishParams()
    fence = Geofence(params, margin=0.05, reaction_time=0.15, horizon=5.0)
    band = StopBand.from_params(params, 0.05, 0.15, 5.0)
    rng = np.random.default_rng(1)
    for _ in range(300):
        x, y, psi = rng.uniform(0, tank.TANK_LENGTH), rng.uniform(0, tank.TANK_WIDTH), rng.uniform(-math.pi, math.pi)
        vx, vy = rng.uniform(-0.2, 0.2, 2)
        c, s = math.cos(psi), math.sin(psi)
        breached = fence.breached(x, y, psi, c * vx - s * vy, s * vx + c * vy)
        violation = band_violation(x, y, psi, vx, vy, band, np)
        assert (violation > 0) == breached


def test_numpy_and_casadi_give_the_same_band_and_wall_terms():
    params = FishParams()
    band = StopBand.from_params(params, 0.05, 0.15, 5.0)
    sym = ca.SX.sym("s", 5)
    band_f = ca.Function("band", [sym], [band_violation(sym[0], sym[1], sym[2], sym[3], sym[4], band, ca)])
    wall_f = ca.Function("wall", [sym], [tank.wall_shortfall(sym[0], sym[1], ca.cos(sym[2]), ca.sin(sym[2]),
                                                             0.1, 0.08, ca, weight=3.0)])
    rng = np.random.default_rng(2)
    for _ in range(50):
        v = np.array([rng.uniform(0, tank.TANK_LENGTH), rng.uniform(0, tank.TANK_WIDTH), rng.uniform(-3, 3),
                      *rng.uniform(-0.3, 0.3, 2)])
        assert float(band_f(v)) == pytest.approx(band_violation(*v, band, np), rel=1e-12, abs=1e-18)
        assert float(wall_f(v)) == pytest.approx(
            tank.wall_shortfall(v[0], v[1], math.cos(v[2]), math.sin(v[2]), 0.1, 0.08, weight=3.0), rel=1e-12)


@pytest.mark.parametrize("psi", [0.0, 0.7, math.pi / 2, 2.5, -1.2])
def test_nose_tail_contact_is_the_point_test_of_nose_and_tail(psi):
    half = 0.1
    c, s = math.cos(psi), math.sin(psi)
    for x in np.linspace(-0.1, tank.TANK_LENGTH + 0.1, 13):
        for y in np.linspace(-0.1, tank.TANK_WIDTH + 0.1, 9):
            points = [(x + h * c, y + h * s) for h in (half, -half)]
            outside = any(not (0 <= px <= tank.TANK_LENGTH and 0 <= py <= tank.TANK_WIDTH) for px, py in points)
            assert tank.nose_tail_contact(x, y, c, s, half) == outside
            gaps = tank.wall_shortfall(x, y, c, s, half, 0.0)
            assert (gaps > 0) == outside
