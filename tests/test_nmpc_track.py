"""The NMPC's `track` planning: the reference's predicted path, the heading term's aim, the track candidates."""

import math

import numpy as np
import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.nmpc.problem import pack_decision, to_z
from pectoral_gym.agents.nmpc.reference import ReferencePredictor, fit_ellipse, reference_path
from pectoral_gym.agents.nmpc.settings import NMPCSettings
from pectoral_gym.envs.core import EnvConfig

TRACK = EnvConfig(model="averaged", task="track")
GOAL = EnvConfig(model="averaged", task="goal")
DT, HORIZON, SPEED = 0.5, 10, 0.03
CENTRE, A, B = np.array([1.15, 0.575]), 0.7, 0.3


def _ellipse_point(phase: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity (speed SPEED, counter-clockwise) on the test ellipse."""
    tangent = np.array([-A * math.sin(phase), B * math.cos(phase)])
    return CENTRE + np.array([A * math.cos(phase), B * math.sin(phase)]), SPEED * tangent / np.hypot(*tangent)


def _advance(phase: float, duration: float, steps: int = 2000) -> float:
    """The phase after moving ``duration`` seconds at SPEED along the ellipse (fine Euler steps on the arc length)."""
    h = duration / steps
    for _ in range(steps):
        phase += h * SPEED / math.hypot(A * math.sin(phase), B * math.cos(phase))
    return phase


@pytest.fixture(scope="module")
def track():
    return make_baseline("nmpc", TRACK, step_budget=1e6)


def test_reference_path_is_a_line_without_turn_and_an_arc_with_one():
    ref, vref = np.array([1.0, 0.5]), np.array([0.03, 0.0])
    positions, velocities = reference_path(ref, vref, 0.0, DT, HORIZON)
    t = DT * np.arange(1, HORIZON + 1)
    np.testing.assert_allclose(positions, ref[:, None] + vref[:, None] * t)
    np.testing.assert_allclose(velocities, np.repeat(vref[:, None], HORIZON, 1))
    # turning left at 0.1 rad/s: a circle of radius 0.3 m centred 0.3 m to the left of the start
    positions, velocities = reference_path(ref, vref, 0.1, DT, HORIZON)
    np.testing.assert_allclose(np.hypot(*(positions - np.array([[1.0], [0.8]]))), 0.3, atol=1e-12)
    np.testing.assert_allclose(np.arctan2(velocities[1], velocities[0]), 0.1 * t, atol=1e-12)
    np.testing.assert_allclose(np.hypot(*velocities), 0.03, atol=1e-12)


def test_fit_ellipse_recovers_the_conic_of_points_on_an_arc():
    points = np.array([_ellipse_point(p)[0] for p in np.linspace(-0.4, 0.8, 12)])  # a third of the way round
    coef = fit_ellipse(points)
    assert coef is not None
    # (x - cx)^2 / A^2 + (y - cy)^2 / B^2 - 1 = 0, expanded and scaled to unit norm (either sign)
    cx, cy = CENTRE
    expected = np.array([1 / A**2, 0.0, 1 / B**2, -2 * cx / A**2, -2 * cy / B**2, cx**2 / A**2 + cy**2 / B**2 - 1])
    expected /= np.linalg.norm(expected)
    np.testing.assert_allclose(coef * np.sign(coef[0]), expected, atol=1e-8)
    assert fit_ellipse(points[:5]) is None  # too few points
    line = np.column_stack([np.linspace(0, 1, 10), np.linspace(0, 0.5, 10)])
    assert fit_ellipse(np.vstack([line, line + [0.0, 0.1]])) is None  # two parallel lines: no ellipse


def test_predictor_follows_the_ellipse_once_enough_of_it_was_seen():
    predictor = ReferencePredictor(DT, HORIZON, "conic", min_turn=1.0)
    phase = -1.0
    for _ in range(40):  # 20 s, past the turn at the end of the major axis (phase 0)
        predictor.observe(*_ellipse_point(phase))
        phase = _advance(phase, DT)
    assert predictor.turned > 1.0
    ref, vref = _ellipse_point(phase)
    predictor.observe(ref, vref)
    positions, velocities = predictor.predict(ref, vref)
    assert predictor.coef is not None
    expected = np.array([_ellipse_point(_advance(phase, DT * (k + 1)))[0] for k in range(HORIZON)]).T
    np.testing.assert_allclose(positions, expected, atol=2e-4)  # within 0.2 mm over 5 s (15 cm of path)
    np.testing.assert_allclose(np.hypot(*velocities), SPEED, rtol=1e-9)
    # the arc and the line miss the same points by centimetres
    arc = ReferencePredictor(DT, HORIZON, "arc")
    arc.observe(*_ellipse_point(_advance(phase, -DT)))
    arc.observe(ref, vref)
    assert np.hypot(*(arc.predict(ref, vref)[0][:, -1] - expected[:, -1])) > 0.003
    line = ReferencePredictor(DT, HORIZON, "line").predict(ref, vref)[0]
    np.testing.assert_allclose(line[:, -1], ref + vref * DT * HORIZON)


def test_predictor_uses_the_arc_until_the_reference_has_turned_enough():
    predictor = ReferencePredictor(DT, HORIZON, "conic", min_turn=1.0)
    phase = 1.2  # along the flat side: little turn in 5 s
    for _ in range(10):
        predictor.observe(*_ellipse_point(phase))
        phase = _advance(phase, DT)
    ref, vref = _ellipse_point(phase)
    before = predictor._velocity
    predictor.observe(ref, vref)
    positions, _ = predictor.predict(ref, vref)
    assert predictor.coef is None and predictor.turned < 1.0
    turn = math.atan2(before[0] * vref[1] - before[1] * vref[0], float(before @ vref)) / DT
    np.testing.assert_allclose(positions, reference_path(ref, vref, turn, DT, HORIZON)[0])
    predictor.reset()
    assert predictor.points == [] and predictor.turned == 0.0
    with pytest.raises(ValueError, match="mode"):
        ReferencePredictor(DT, HORIZON, "spline")
    with pytest.raises(ValueError, match="reference"):
        NMPCSettings(reference="spline")
    with pytest.raises(ValueError, match="heading_lookahead"):
        NMPCSettings(heading_lookahead=-1.0)


def test_parameters_hold_a_goal_in_place_and_take_a_predicted_path(track):
    goal = make_baseline("nmpc", GOAL, step_budget=1e6)
    state, ref = np.array([1.0, 0.5, 0.0, 0.0, 0.0, 0.0]), np.array([1.3, 0.6])
    p = goal.problem.parameters(state, ref, np.zeros(2), to_z(goal._u_prev), goal.gains)
    n = goal.problem.horizon
    np.testing.assert_array_equal(p[6:6 + 2 * n].reshape(n, 2), np.repeat(ref[None], n, 0))
    path = (np.arange(2 * n, dtype=float).reshape(2, n), -np.arange(2 * n, dtype=float).reshape(2, n))
    p = track.problem.parameters(state, ref, np.array([0.03, 0.0]), to_z(track._u_prev), track.gains, path)
    np.testing.assert_array_equal(p[6:6 + 2 * n], path[0].ravel(order="F"))
    np.testing.assert_array_equal(p[6 + 2 * n:6 + 4 * n], path[1].ravel(order="F"))


def _on_path_cost(nmpc, lag: float) -> float:
    """The NLP's cost of states on a straight reference path (heading along it), ``lag`` metres behind it."""
    problem, n = nmpc.problem, nmpc.problem.horizon
    ref, vref = np.array([0.8, 0.575]), np.array([SPEED, 0.0])
    positions, velocities = reference_path(ref, vref, 0.0, DT, n)
    x = np.zeros((6, n + 1))
    x[0, 0], x[1, 0] = ref[0] - lag, ref[1]
    x[0, 1:], x[1, 1:] = positions[0] - lag, positions[1]
    x[3] = SPEED
    z = np.repeat(to_z(nmpc.u_rest)[:, None], problem.n_blocks, 1)  # the inputs' terms are the same in both
    p = problem.parameters(x[:, 0], ref, vref, to_z(nmpc.u_rest), nmpc.gains, (positions, velocities))
    return float(problem.cost(pack_decision(z, x), p))


def test_track_cost_prefers_the_reference_to_lagging_behind_it(track):
    """The heading term aims at the reference 5 s further along its path: no reward for hanging back.

    Before (aim at the reference point itself, fading out within 5 cm) 8 cm behind the reference cost
    less than on it, and the fish lagged 7-9 cm on the straight (docs/notes/2026-12-01-nmpc-rounds.md, fifth round).
    """
    assert _on_path_cost(track, 0.0) < _on_path_cost(track, 0.02) < _on_path_cost(track, 0.08)
    before = make_baseline("nmpc", TRACK, step_budget=1e6, heading_lookahead=0.0, heading_scale=0.05)
    assert _on_path_cost(before, 0.08) < _on_path_cost(before, 0.0)


def test_track_screens_held_turns_and_holds_the_biases(track):
    goal = make_baseline("nmpc", GOAL, step_budget=1e6)
    assert len(goal._fresh_guesses()) == 9  # straight; four turns, held or for 2 s then straight
    guesses = track._fresh_guesses()
    assert len(guesses) == 5  # straight; the four turns held
    for u in guesses:
        np.testing.assert_array_equal(u, np.repeat(u[:, :1], u.shape[1], 1))
    np.testing.assert_allclose([track.u_low[2:], track.u_high[2:]], np.pi / 2)
    assert len(make_baseline("nmpc", TRACK, step_budget=1e6, turn_then_straight=True)._fresh_guesses()) == 9


def test_track_controller_feeds_the_predictor_from_its_observations(track):
    obs = np.zeros(19)
    obs[:4] = 1.15, 0.575, 1.0, 0.0
    obs[7], obs[8], obs[9], obs[10] = 0.05, 0.0, SPEED, 0.0  # reference 5 cm ahead, swimming along X
    track.reset()
    track.act(obs)
    obs[0], obs[7] = 1.16, 0.055
    obs[9], obs[10] = SPEED * math.cos(0.05), SPEED * math.sin(0.05)  # its velocity turned 0.05 rad to the left
    track.act(obs)
    assert len(track.reference.points) == 2
    assert track.reference.turn == pytest.approx(0.05 / DT)
    np.testing.assert_allclose(track.reference.points[-1], [1.215, 0.575])
    assert track.failures == 0
