"""The NMPC's commands through the backup shield (pectoral_gym.agents.nmpc.shield).

The band is pectoral_gym.agents.controllers.stop_band, the shield pectoral_gym.agents.controllers.band_shield.
"""

import math

import numpy as np
import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.controllers.band_study import run_episode
from pectoral_gym.agents.controllers.stop_band import band_violation
from pectoral_gym.agents.nmpc.problem import FinInputs
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.deploy import make_controller
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.model.tank import ROBOT_STOP_RULE, TANK_WIDTH
from pectoral_gym.registration import MEASUREMENT_MARGIN, registered_settings

CONFIG = EnvConfig(model="full", task="goal")
SAFETY = SafetyConfig()


def _nmpc(**kwargs):
    """The NMPC with the robot's band on the simulated full model, which latches the patterns as sent."""
    return make_baseline("nmpc", CONFIG, step_budget=1e6, stop_band=ROBOT_STOP_RULE, shield_firmware=False, **kwargs)


def test_shield_is_on_exactly_where_the_plan_has_a_band():
    assert _nmpc().shield is not None
    assert _nmpc(shield=False).shield is None
    assert make_baseline("nmpc", CONFIG, step_budget=1e6).shield is None  # v0: no band, no shield
    v1 = EnvConfig(**registered_settings("PectoralFish-Full-v1"))
    nmpc = make_baseline("nmpc", v1, step_budget=1e6)
    assert nmpc.shield is not None
    assert nmpc.shield.shield.band.rule.margin == pytest.approx(v1.stop_rule.margin + 0.02)
    robot = make_controller("nmpc", CONFIG, step_budget=1e6, safety=SAFETY)  # deploy: the supervisor's band, widened
    assert robot.shield.shield.band.rule.margin == pytest.approx(SAFETY.stop_rule.margin + MEASUREMENT_MARGIN + 0.02)
    assert robot.spin is None and robot.shield.shield.spins  # the plan's spins off, the shield's on (deploy)


def test_patterns_round_trip_the_fin_inputs():
    shield = _nmpc().shield
    u = np.array(FinInputs(0.2, 0.1, 1.4, 1.7))
    p = shield.patterns(u)
    assert p[0, :2] == pytest.approx([1.4, 0.2]) and p[1, :2] == pytest.approx([1.7, 0.1])
    assert p[:, 2:] == pytest.approx(np.array([[shield.fins.period, shield.fins.ratio]] * 2))


def test_a_command_that_leaves_a_backup_is_sent_as_it_is():
    nmpc = _nmpc()
    state = np.array([1.15, 0.5 * TANK_WIDTH, 0.0, 0.02, 0.0, 0.0])  # mid-tank, slow
    u = nmpc._straight
    assert nmpc.shield.filter(state, u, (2.0, state[1])) == pytest.approx(u)


def test_a_straight_run_at_a_wall_is_replaced_by_a_backup_that_keeps_out_of_the_band():
    """Heading for the wall Y = W at 0.06 m/s: straight on leaves no backup, the command sent does."""
    nmpc = _nmpc()
    shield = nmpc.shield.shield
    band = shield.band
    y = TANK_WIDTH - 0.45
    state = np.array([1.15, y, 0.5 * math.pi, 0.06, 0.0, 0.0])
    assert band_violation(*state[:5], band, np) == 0.0  # outside the band now
    u = nmpc._straight
    rows = shield.shortfalls(state, nmpc.shield.patterns(u)[None])
    assert np.min(rows[-1]) <= 0.0  # the premise: a backup exists from here
    assert np.min(rows[0]) > 0.0  # ... but none after a period of swimming straight on
    sent = nmpc.shield.filter(state, u, (1.15, y - 0.5))
    assert not np.allclose(sent, u)
    after = shield.shortfalls(state, nmpc.shield.patterns(sent)[None])
    assert np.min(after[0]) <= 0.0  # a backup remains after the command sent


def test_facing_a_wall_at_the_start_inset_the_shielded_nmpc_keeps_out_of_the_band():
    """At rest at the start inset, facing the wall, the goal behind (tests/test_hand_band's situation): on the
    full model, checked every 0.1 s, the shielded NMPC never enters the band the supervisor enforces and reaches
    the goal."""
    y = TANK_WIDTH - tk.START_INSET
    start, goal = (1.15, y, 0.5 * math.pi), (1.15, y - 0.5)
    r = run_episode(lambda config: make_baseline("nmpc", config, step_budget=1e6, stop_band=ROBOT_STOP_RULE,
                                                     shield_firmware=False), 0,
                    start=start, goal=goal, max_steps=120)
    assert r.band_time is None and r.worst == 0.0
    assert r.success and not r.wall


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_seeded_full_model_episodes_keep_out_of_the_band(seed):
    """Seeded full-model episodes with the robot's band: no band entry, checked every 0.1 s."""
    r = run_episode(lambda config: make_baseline("nmpc", config, step_budget=1e6, stop_band=ROBOT_STOP_RULE,
                                                     shield_firmware=False), seed,
                    goal_inset=0.3)
    assert r.band_time is None, (seed, r)


def test_plans_that_rest_too_long_away_from_the_goal_hand_over_to_the_hand_law():
    nmpc = _nmpc(stall_steps=3)
    state = np.array([1.15, 0.5 * TANK_WIDTH, 0.0, 0.005, 0.0, 0.0])  # nearly at rest
    goal, still = np.array([0.8, 0.5 * TANK_WIDTH]), np.zeros(2)  # behind the fish
    rest = nmpc.u_rest
    assert [np.array_equal(nmpc._unstall(state, goal, still, rest), rest) for _ in range(3)] == [True, True, False]
    hand = nmpc._hand_input(state, goal, still, 0.0)
    assert nmpc._unstall(state, goal, still, rest) == pytest.approx(hand)
    assert np.max(FinInputs(*hand)[:2]) > nmpc._rest_amplitude  # the hand law moves off
    assert nmpc._unstall(state, goal, still, nmpc._straight) == pytest.approx(nmpc._straight)  # a moving plan: its own
    moving = state.copy()
    moving[3] = 0.05  # coasting on: not a stall
    assert np.array_equal(nmpc._unstall(moving, goal, still, rest), rest)
    assert nmpc.unstalled == 2


def test_a_fallback_rest_is_not_handed_over(monkeypatch):
    """Steps whose solves failed or came late send the safe rest command, not the hand law's."""
    nmpc = _nmpc(stall_steps=1)
    obs = np.zeros(19, dtype=np.float32)
    obs[:4] = (1.15, 0.5 * TANK_WIDTH, 1.0, 0.0)  # at rest mid-tank, heading +X
    obs[7] = -0.4  # the goal 0.4 m behind

    def failed(state, ref, vref):
        nmpc.failures += 1
        return nmpc.u_rest.copy()

    monkeypatch.setattr(nmpc, "_plan_step", failed)
    rest = nmpc.fins.action(nmpc.bias_mid, FinInputs(*nmpc.u_rest).amplitude_right, nmpc.bias_mid,
                            FinInputs(*nmpc.u_rest).amplitude_left)
    for _ in range(3):
        assert nmpc.act(obs) == pytest.approx(rest)
    assert nmpc.unstalled == 0
    monkeypatch.setattr(nmpc, "_plan_step", lambda state, ref, vref: nmpc.u_rest.copy())  # a plan that rests
    assert nmpc.act(obs) != pytest.approx(rest) and nmpc.unstalled == 1


def test_circle_hand_over_waits_for_no_progress_then_the_hand_law_drives_to_the_end():
    nmpc = _nmpc(circle_steps=2, circle_progress=0.02)
    state = np.array([1.15, 0.5 * TANK_WIDTH, 0.0, 0.01, 0.0, 0.0])  # heading +X, creeping
    goal, still = np.array([1.15, 0.5 * TANK_WIDTH - 0.15]), np.zeros(2)  # abeam to the right: inside the circle
    u = nmpc._straight * 0.1
    assert [np.array_equal(nmpc._unstall(state, goal, still, u), u) for _ in range(2)] == [True, True]  # too soon
    hand = nmpc._unstall(state, goal, still, u)  # 2 steps without progress: the hand law drives
    assert nmpc.circled == 1 and hand == pytest.approx(nmpc._hand_input(state, goal, still, 0.0))
    facing = state.copy()
    facing[2] = -0.5 * math.pi  # facing the goal, out of the circle: still the hand law's, it steers all the way in
    assert nmpc._unstall(facing, goal, still, u) == pytest.approx(nmpc._hand_input(facing, goal, still, 0.0))
    assert nmpc.circled == 2
    nmpc.reset()  # a new episode: the plan drives again
    assert np.array_equal(nmpc._unstall(facing, goal, still, u), u) and nmpc.circled == 2
    closing = _nmpc(circle_steps=2, circle_progress=0.02)
    for k in range(4):  # closing in by 3 cm a step: progress, the plan keeps driving
        moved = state.copy()
        moved[1] -= 0.03 * k
        assert np.array_equal(closing._unstall(moved, goal, still, u), u)
    assert closing.circled == 0


@pytest.mark.parametrize("circle_steps", [4, 0])
def test_a_goal_inside_the_turning_circle_is_reached_on_the_full_model(circle_steps):
    """At rest, the goal 0.2 m away 80 deg to the right: inside the right turning circle (0.25 m radius). As on
    the robot, the plan makes no spins of its own (``spin=False``). With the circle hand-over the hand law swims
    out of the circle, turns back and steers in, and the fish arrives within 40 s; without it (``circle_steps=0``)
    the plan creeps by the goal for the episode's 60 s (the situation of the time-outs on the emulated robot)."""
    start = (1.15, 0.5 * TANK_WIDTH, 0.0)
    angle = math.radians(-80.0)
    goal = (1.15 + 0.2 * math.cos(angle), 0.5 * TANK_WIDTH + 0.2 * math.sin(angle))
    r = run_episode(lambda config: make_baseline("nmpc", config, step_budget=1e6, stop_band=ROBOT_STOP_RULE, spin=False,
                                                 shield_firmware=False, circle_steps=circle_steps),
                    0, start=start, goal=goal, max_steps=120)
    assert r.band_time is None and not r.wall
    if circle_steps:
        assert r.success and r.time <= 40.0, r
    else:
        assert not r.success, r
