"""The NMPC's stopping-distance band against the robot env's geofence.

The band is pectoral_gym.agents.controllers.stop_band, the geofence pectoral_gym.hardware.safety.geofence.
"""

import math

import casadi as ca
import numpy as np
import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.controllers.stop_band import StopBand, band_violation
from pectoral_gym.agents.nmpc.settings import NMPCSettings
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.deploy import make_controller
from pectoral_gym.hardware.safety.geofence import Geofence
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FishParams
from pectoral_gym.model.tank import StopRule
from pectoral_gym.registration import MEASUREMENT_MARGIN, registered_settings

SAFETY = SafetyConfig()
RULE = SAFETY.stop_rule
BAND = StopBand.from_params(FishParams(), RULE)


def test_violation_is_positive_exactly_where_the_geofence_stops_the_fish():
    # the geofence's own implementation decides; poses and velocities drawn over the tank
    fence = Geofence(FishParams(), RULE)
    rng = np.random.default_rng(0)
    breached = 0
    for _ in range(2000):
        x, y = rng.uniform(0.05, TANK_LENGTH - 0.05), rng.uniform(0.05, TANK_WIDTH - 0.05)
        psi, vx, vy = rng.uniform(-math.pi, math.pi), rng.uniform(-0.05, 0.2), rng.uniform(-0.05, 0.05)
        c, s = math.cos(psi), math.sin(psi)
        stop = fence.breached(x, y, psi, c * vx - s * vy, s * vx + c * vy)
        assert (band_violation(x, y, psi, vx, vy, BAND, np) > 0) == stop
        breached += stop
    assert 200 < breached < 1800  # both kinds of state were drawn


def test_violation_by_hand_and_in_casadi():
    # heading +Y at 0.1 m/s, centre 0.35 m from the wall Y = W: only the nose circle and the fin discs can
    # fall short of that wall's need; nothing moves towards the other walls (need = margin there)
    d = 0.35
    y = TANK_WIDTH - d
    need = RULE.margin + 0.1 * RULE.reaction_time + math.log(0.1 / RULE.contact_speed) / BAND.k
    half, width, span = BAND.outline
    gaps = [d - half - width, d + half - width, d - span, d - span]
    expected = sum(max(need - g, 0.0) ** 2 for g in gaps)
    assert expected > 0
    got = band_violation(1.0, y, math.pi / 2, 0.1, 0.0, BAND, np)
    assert got == pytest.approx(expected, rel=1e-12)
    sym = ca.SX.sym("s", 5)
    f = ca.Function("f", [sym], [band_violation(sym[0], sym[1], sym[2], sym[3], sym[4], BAND, ca)])
    assert float(f([1.0, y, math.pi / 2, 0.1, 0.0])) == pytest.approx(expected, rel=1e-12)


def test_deploy_plans_with_the_geofence_band_widened_as_v1_and_the_sim_only_where_its_band_is_on():
    config = EnvConfig(model="full", task="goal")
    wide = StopBand.from_params(FishParams(), StopRule(RULE.margin + MEASUREMENT_MARGIN, RULE.reaction_time,
                                                       RULE.contact_speed))
    nmpc = make_controller("nmpc", config, step_budget=1e6, safety=SAFETY)
    assert nmpc.problem.stop_band == wide
    x = np.array([1.0, TANK_WIDTH - 0.4, math.pi / 2, 0.1, 0.0, 0.0])
    assert nmpc._wall_violation(x, 0.03) == pytest.approx(band_violation(*x[[0, 1, 2, 3, 4]], wide, np))
    hand = make_controller("hand", config, step_budget=1e6, safety=SAFETY)
    assert hand.shield.band.rule.margin == pytest.approx(wide.rule.margin + 0.02)  # the shield adds its own
    assert make_baseline("nmpc", config, step_budget=1e6).problem.stop_band is None
    v1 = EnvConfig(**registered_settings("PectoralFish-Full-v1"))
    assert make_baseline("nmpc", v1, step_budget=1e6).problem.stop_band == StopBand.from_params(
        FishParams(), v1.stop_rule)
    assert NMPCSettings(stop_band=(0.05, 0.15, 0.03)).stop_band == StopRule(0.05, 0.15, 0.03)  # given as numbers
    with pytest.raises(ValueError, match="stop_band: StopRule.reaction_time"):
        NMPCSettings(stop_band=(0.05, -1.0, 0.03))
    with pytest.raises(ValueError, match="stop_band: StopRule.contact_speed"):
        NMPCSettings(stop_band=(0.05, 0.15, 0.0))
