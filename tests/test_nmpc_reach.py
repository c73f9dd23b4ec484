"""The NMPC's goal-reach pricing (a plan that enters the goal costs only the intervals up to there) and bias span."""

import numpy as np
import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.nmpc.problem import to_z
from pectoral_gym.agents.nmpc.settings import NMPCSettings
from pectoral_gym.envs.core import EnvConfig

CONFIG = EnvConfig(model="averaged", task="goal")
GOAL = (1.15, 0.575)


def _rollout(distances: list[float]) -> np.ndarray:
    """States ``(6, len + 1)`` at mid-tank heading +X, the interval ends at ``distances`` [m] before the goal."""
    x = np.zeros((6, len(distances) + 1))
    x[0, 0] = GOAL[0] - 1.0
    x[0, 1:] = [GOAL[0] - d for d in distances]
    x[1] = GOAL[1]
    return x


@pytest.fixture(scope="module")
def nmpc():
    controller = make_baseline("nmpc", CONFIG, step_budget=1e6, reach_fraction=0.75)
    controller._target_end = GOAL
    return controller


def test_reach_cost_sums_the_distances_up_to_the_first_interval_inside(nmpc):
    # threshold 0.75 * 0.08 m = 0.06 m: the third interval end (0.05 m) is the first inside
    x = _rollout([0.30, 0.20, 0.05, 0.0, 0.02])
    assert nmpc._reach_cost(x) == pytest.approx(nmpc.settings.w_distance * (0.30 + 0.20 + 0.05))
    # just outside the threshold (0.061 m) the plan does not count as reaching
    assert nmpc._reach_cost(_rollout([0.30, 0.20, 0.061])) is None


def test_reach_cost_adds_the_wall_term_of_the_intervals_before(nmpc):
    half = 0.5 * CONFIG.params.body_length
    x = _rollout([0.30, 0.05])
    x[1, 1], x[2, 1] = half + 0.01, np.pi / 2  # heading +Y with the tail 1 cm from the y = 0 wall
    margin = nmpc.settings.wall_margin
    distance_1 = np.hypot(GOAL[0] - x[0, 1], GOAL[1] - x[1, 1])
    expected = nmpc.settings.w_distance * (distance_1 + 0.05) + nmpc.settings.w_wall * (margin - 0.01) ** 2
    assert nmpc._reach_cost(x) == pytest.approx(expected, rel=1e-9)


def test_reach_cost_is_off_by_setting_and_for_track():
    off = make_baseline("nmpc", CONFIG, step_budget=1e6, reach_fraction=0.0)
    off._target_end = GOAL
    assert off._reach_cost(_rollout([0.3, 0.0])) is None
    track = make_baseline("nmpc", EnvConfig(model="averaged", task="track"), step_budget=1e6, reach_fraction=0.75)
    track._target_end = GOAL
    assert track._reach_cost(_rollout([0.3, 0.0])) is None
    with pytest.raises(ValueError, match="reach_fraction"):
        NMPCSettings(reach_fraction=1.5)


def test_rollout_cost_of_a_plan_into_the_goal_is_its_reach_cost(nmpc):
    """Swimming straight at a goal 5 cm ahead: the model's rollout enters it, and the price is the reach cost
    of that rollout, below the distance cost of staying put for the whole horizon."""
    nmpc.reset()
    state = np.array([GOAL[0] - 0.05, GOAL[1], 0.0, 0.05, 0.0, 0.0])
    p = nmpc.problem.parameters(state, np.array(GOAL), np.zeros(2), to_z(nmpc._u_prev), nmpc.gains)
    straight = nmpc._fresh_guesses()[0]
    cost, _ = nmpc._rollout_cost(state, p, straight)
    problem = nmpc.problem
    z = problem.blocked(np.clip(to_z(straight), nmpc.z_low[:, None], nmpc.z_high[:, None]))
    x = np.asarray(problem.rollout(state, z[:, problem.block_of], to_z(nmpc._u_prev), nmpc.gains))
    reach = nmpc._reach_cost(x)
    assert reach is not None and cost == pytest.approx(reach)
    assert cost < nmpc.settings.w_distance * 0.05 * problem.horizon


def test_bias_span_zero_holds_both_biases_at_ninety_degrees():
    """bias_span=0: the planner's bias bounds collapse to 90 deg, so every planned input has both biases there."""
    held = make_baseline("nmpc", CONFIG, step_budget=1e6, bias_span=0.0)
    for bounds in (held.u_low, held.u_high):
        assert bounds[2] == pytest.approx(np.pi / 2) and bounds[3] == pytest.approx(np.pi / 2)
    obs = np.zeros(19)
    obs[:4] = 1.15, 0.575, 1.0, 0.0
    obs[7], obs[8] = 0.3, 0.2  # goal ahead-left: the unrestricted planner would tilt the biases
    held.reset()
    held.act(obs)
    assert held.failures == 0
    np.testing.assert_allclose(held.plan[:, 2:], np.pi / 2, atol=1e-9)
    span = np.radians(10.0)
    narrow = make_baseline("nmpc", CONFIG, step_budget=1e6, bias_span=span)
    # the env's range (45-135 deg) holds 80-100 deg, so the bounds are those
    np.testing.assert_allclose(narrow.u_low[2:], np.radians(80.0))
    np.testing.assert_allclose(narrow.u_high[2:], np.radians(100.0))
    for bad in (-0.1, "wide"):
        with pytest.raises(ValueError, match="bias_span"):
            NMPCSettings(bias_span=bad)


def test_bias_span_auto_holds_the_biases_for_both_tasks():
    """The default ("auto"): goal and (since the fifth round) track plans hold 90 deg; ``None`` keeps the whole
    identified range (45-135 deg)."""
    goal = make_baseline("nmpc", CONFIG, step_budget=1e6)
    np.testing.assert_allclose([goal.u_low[2], goal.u_high[2]], np.pi / 2)
    track = make_baseline("nmpc", EnvConfig(model="averaged", task="track"), step_budget=1e6)
    np.testing.assert_allclose([track.u_low[2], track.u_high[2]], np.pi / 2)
    free = make_baseline("nmpc", EnvConfig(model="averaged", task="track"), step_budget=1e6, bias_span=None)
    np.testing.assert_allclose([free.u_low[2], free.u_high[2]], np.radians([45.0, 135.0]))
