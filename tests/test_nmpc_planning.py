"""The NMPC's planning aids: the hand law's closed-loop candidate and the turn-then-straight cost-to-go."""

import math

import numpy as np
import pytest

from pectoral_gym.agents.baselines import HandController, make_baseline
from pectoral_gym.agents.controllers.turning import circle_room, turn_path_length
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.observation import decode
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CONFIG = EnvConfig(model="averaged", task="goal")


def _obs(x: float, y: float, psi: float, gx: float, gy: float) -> np.ndarray:
    """An observation of a fish at rest at ``(x, y, psi)`` with the goal at ``(gx, gy)`` (tank frame)."""
    c, s = math.cos(psi), math.sin(psi)
    obs = np.zeros(19)
    obs[:4] = x, y, c, s
    obs[7], obs[8] = c * (gx - x) + s * (gy - y), -s * (gx - x) + c * (gy - y)
    return obs


@pytest.fixture(scope="module")
def nmpc():
    return make_baseline("nmpc", CONFIG, step_budget=1e6)


def test_hand_act_is_its_command_through_the_fin_map():
    hand, reference = HandController(CONFIG), HandController(CONFIG)
    first, second = _obs(1.0, 0.5, 0.3, 1.5, 0.9), _obs(1.01, 0.5, 0.35, 1.5, 0.9)
    hand.act(first)
    rate = 0.05 / CONFIG.control_period
    np.testing.assert_array_equal(hand.act(second), reference.fins.action(*reference.command(decode(second), rate)))


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_hand_candidate_turns_towards_the_goal_on_the_model(nmpc, side):
    """The candidate's first input turns the fish to the goal's side (right fin stronger: left), and the
    model's rollout under the whole candidate ends facing the goal more than it started."""
    nmpc.reset()
    psi = 0.0
    state = np.array([1.15, 0.575, psi, 0.0, 0.0, 0.0])
    goal = np.array([1.45, 0.575 + side * 0.25])
    u = nmpc._hand_guess(state, goal, np.zeros(2))
    assert u.shape == (4, nmpc.problem.horizon)
    assert side * (u[0, 0] - u[1, 0]) > 0  # amplitude right - left
    from pectoral_gym.agents.nmpc.problem import to_z

    x = np.asarray(nmpc.problem.rollout(state, to_z(u), to_z(nmpc._u_prev), nmpc.gains))
    bearing = [abs((math.atan2(goal[1] - x[1, k], goal[0] - x[0, k]) - x[2, k] + math.pi) % (2 * math.pi) - math.pi)
               for k in (0, -1)]
    assert bearing[1] < bearing[0]


def test_cost_to_go_is_the_extra_path_of_the_turn(nmpc):
    free = make_baseline("nmpc", CONFIG, step_budget=1e6, togo_wall_margin=0.0)
    goal = (1.15, 0.575)
    free._target_end = nmpc._target_end = goal
    behind = np.array([1.35, 0.575, 0.0, 0, 0, 0])  # the goal 0.2 m straight behind
    expected = turn_path_length(1.35, 0.575, 0.0, *goal, free.settings.turn_radius) - 0.2
    assert free._togo(behind) == pytest.approx(expected)
    assert expected > math.pi * free.settings.turn_radius - 0.2  # a half circle at least
    ahead = np.array([0.95, 0.575, 0.0, 0, 0, 0])
    assert free._togo(ahead) == pytest.approx(0.0, abs=1e-12)
    # with the wall rule: a turn along a wall costs more than the same turn in open water; a path
    # that needs no turn costs the same
    near_wall = np.array([0.4, 0.12, 0.0, 0, 0, 0])
    nmpc._target_end = free._target_end = (0.2, 0.2)  # behind: a half turn next to the wall
    assert nmpc._togo(near_wall) > free._togo(near_wall) + 0.1
    nmpc._target_end = free._target_end = (0.9, 0.12)  # straight ahead along the wall
    assert nmpc._togo(near_wall) == pytest.approx(free._togo(near_wall), abs=1e-12)


def test_circle_room_against_hand_values():
    r = 0.25
    # heading +X at mid-tank: the left circle's centre is r above the fish
    assert circle_room(1.15, 0.5, 0.0, 1.0, r) == pytest.approx(TANK_WIDTH - (0.5 + r) - r)
    assert circle_room(1.15, 0.5, 0.0, -1.0, r) == pytest.approx(0.5 - r - r)
    # heading +Y near the right end wall: the right circle's centre is r towards +X
    assert circle_room(TANK_LENGTH - 0.3, 0.575, math.pi / 2, -1.0, r) == pytest.approx(0.3 - 2 * r)


def test_continuation_prices_the_hand_law_beyond_the_horizon():
    """The hand law continued on the model: a goal reached at once costs one interval's distance; a goal
    behind costs more than the same goal ahead; a wall on the way costs more again."""
    nmpc = make_baseline("nmpc", CONFIG, step_budget=1e6, togo_steps=10)
    z_rest = np.array(nmpc._u_prev)
    from pectoral_gym.agents.nmpc.problem import to_z

    at_goal = np.array([1.15, 0.575, 0.0, 0, 0, 0])
    nmpc._target_end = (1.15, 0.575)
    assert nmpc._continuation(at_goal, to_z(z_rest)) < nmpc.settings.w_distance * CONFIG.goal_radius
    nmpc._target_end = (1.45, 0.575)
    ahead = nmpc._continuation(at_goal, to_z(z_rest))
    nmpc._target_end = (0.85, 0.575)
    behind = nmpc._continuation(at_goal, to_z(z_rest))
    assert behind > ahead > 0
    nose_at_wall = np.array([0.099, 0.575, math.pi, 0, 0, 0])  # nose on the x = 0 wall (half body 0.099 m)
    assert nmpc._wall_violation(nose_at_wall, 0.05) == pytest.approx(0.05**2, rel=1e-6)


def test_continuation_without_the_hand_candidate_still_plans():
    """hand_candidate=False with the continuation on: the hand law still prices the candidates (no fallback)."""
    from pectoral_gym.envs.observation import OBS_SIZE

    nmpc = make_baseline("nmpc", CONFIG, step_budget=1e6, hand_candidate=False, togo_steps=3)
    obs = np.zeros(OBS_SIZE)
    obs[:4] = 1.15, 0.575, 1.0, 0.0
    obs[7], obs[8] = 0.3, 0.1
    nmpc.reset()
    nmpc.act(obs)
    assert nmpc.failures == 0 and nmpc.plan is not None
