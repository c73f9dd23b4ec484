"""The hand law keeps the fish out of the robot's stopping band (agents.controllers.band_shield, band_study)."""

from __future__ import annotations

import math

import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.controllers.band_shield import band_speed
from pectoral_gym.agents.controllers.band_study import run_episode
from pectoral_gym.agents.controllers.stop_band import StopBand
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model.tank import ROBOT_STOP_RULE, TANK_WIDTH, coast_distance


def _hand(shield: bool):
    return lambda config: make_baseline("hand", config, shield=shield)


def test_study_substeps_reproduce_the_env_episode():
    """Holding each action for 5 substeps of control_period / 5 gives the env's own episode (same goal time)."""
    for seed in (2, 4):
        coarse = run_episode(_hand(False), seed, substeps=1)
        fine = run_episode(_hand(False), seed, substeps=5)
        assert coarse.success and fine.success
        assert fine.time == coarse.time


def test_band_speed_solves_the_band_need():
    """``band_speed`` inverts the need ``margin + v t_r + ln(max(v, v_c) / v_c) / k`` (Geofence's rule)."""
    band = StopBand.from_params(EnvConfig().params, ROBOT_STOP_RULE)
    rule = band.rule
    assert band_speed(rule.margin, band) == 0.0  # at rest the need is the margin
    for clearance in (0.1, 0.2, 0.3):
        v = band_speed(clearance, band)
        coast = math.log(max(v, rule.contact_speed) / rule.contact_speed) / band.k
        need = rule.margin + v * rule.reaction_time + coast
        assert need == pytest.approx(clearance, abs=1e-9)
    assert band_speed(0.1, band) < band_speed(0.2, band) < band_speed(0.3, band)


def test_facing_a_wall_at_the_start_inset_with_the_goal_behind():
    """The fish at rest at the start inset from a wall, facing it, the goal behind: the old law turns on its
    turning circle (~0.25 m, close to the inset) into the band; the shielded law turns away outside it."""
    y = TANK_WIDTH - tk.START_INSET
    start, goal = (1.15, y, 0.5 * math.pi), (1.15, y - 0.5)
    old = run_episode(_hand(False), 0, start=start, goal=goal)
    assert old.band_time is not None  # the premise: this situation puts the old law in the band
    new = run_episode(_hand(True), 0, start=start, goal=goal)
    assert new.band_time is None and new.worst == 0.0
    assert new.success and not new.wall


@pytest.mark.slow
def test_seeded_episodes_where_the_old_law_entered_the_band():
    """On seeded full-model episodes in which the old law entered the band, the shielded one does not."""
    seeds = [s for s in range(12) if run_episode(_hand(False), s).band_time is not None]
    assert seeds  # the premise
    for seed in seeds:
        r = run_episode(_hand(True), seed)
        assert r.band_time is None and r.success, seed


def test_spin_cycle_has_one_home():
    """The NMPC's spin module re-exports the cycle the hand law's shield uses (one definition)."""
    pytest.importorskip("casadi")
    from pectoral_gym.agents.controllers import turning
    from pectoral_gym.agents.nmpc import spin

    assert spin.SPIN_CYCLE is turning.SPIN_CYCLE and spin.mirror is turning.mirror


def test_shield_speed_spread_counts_towards_every_wall():
    """At rest, the tail ``need(w) -+ 5 mm`` from the wall X = 0: inside the band with a spread ``w``, outside
    just beyond it (``Geofence.breached`` adds the spread to the speed towards every wall)."""
    import numpy as np

    from pectoral_gym.agents.controllers.band_shield import BandShield
    from pectoral_gym.agents.controllers.fin_map import FinMap

    config = EnvConfig()
    w = 0.02
    shield = BandShield(config, FinMap(config), extra_margin=0.0, speed_spread=w)
    band = shield.band
    rule = band.rule
    need = rule.margin + w * rule.reaction_time + float(coast_distance(w, band.k, rule.contact_speed))
    for offset, inside in ((-0.005, True), (0.005, False)):
        x = band.outline.half_length + band.outline.width + need + offset  # the tail's clearance is need + offset
        state = np.array([[x, 0.5 * TANK_WIDTH, 0.0, 0.0, 0.0, 0.0]])
        assert (shield._violation(state, band)[0] > 0) == inside
