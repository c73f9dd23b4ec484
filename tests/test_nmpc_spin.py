"""The NMPC's on-the-spot turns (pectoral_gym.agents.nmpc.spin).

Symmetry, the turn on the full model, the fin copy, pricing.
"""

import math

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.nmpc.problem import pack_decision, to_z
from pectoral_gym.agents.nmpc.spin import SPIN_CYCLE, SpinTurns, mirror
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.safety.rules import CommandFilter
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.servo import ServoLimits

CONFIG = EnvConfig(model="full", task="goal")


def _beats(u: np.ndarray) -> np.ndarray:
    """Patterns ``(n, 2, 4)`` of inputs ``(n, 4)`` (FinInputs order) at the NMPC's period and ratio."""
    u = np.atleast_2d(u)
    beats = np.zeros((len(u), 2, 4))
    beats[:, 0, :2] = u[:, [2, 0]]
    beats[:, 1, :2] = u[:, [3, 1]]
    beats[:, :, 2:] = (0.5, 5.0)
    return beats


def _spin(model: type, cycles: list[np.ndarray], steps: int) -> np.ndarray:
    """States ``(len(cycles), 6)`` after ``steps`` control periods of each cycle from rest."""
    m = model(n=len(cycles))
    m.reset()
    for k in range(steps):
        m.command_array(np.concatenate([_beats(c[k % len(c)]) for c in cycles]))
        m.advance(0.5)
    return m.state.copy()


@pytest.mark.parametrize("model", [AveragedModel, FullModel])
def test_mirrored_cycle_mirrors_the_motion(model):
    # the fish is symmetric about its body axis: y, psi, v_y and omega change sign, X and v_x do not
    steps = 12 if model is AveragedModel else 4
    left, right = _spin(model, [SPIN_CYCLE, mirror(SPIN_CYCLE)], steps)
    assert left[2] > 0.3  # the cycle turns left
    np.testing.assert_allclose(right, left * np.array([1, -1, -1, 1, -1, -1]), atol=1e-9)


def test_the_cycle_turns_the_full_model_on_the_spot():
    # 6 s of the cycle from rest: a quarter turn with the centre of mass within about half a body
    # length (the turning circle needs 0.5 m of room for a half turn, docs/notes/2026-12-01-nmpc-rounds.md)
    m = FullModel(n=1)
    m.reset()
    reach = 0.0
    for k in range(12):
        m.command_array(_beats(SPIN_CYCLE[k % 4]))
        m.advance(0.5)
        reach = max(reach, float(np.hypot(*m.state[0, :2])))
    assert math.degrees(m.state[0, 2]) > 80.0
    assert reach < 0.12


@pytest.mark.parametrize("phase", range(4))
def test_the_robot_servos_execute_the_cycle_as_commanded(phase):
    # the robot's command filter (clipping, period stretching of transitional strokes, rate limits)
    # lets every step of the repeated cycle through unchanged, in both directions
    for cycle in (SPIN_CYCLE, mirror(SPIN_CYCLE)):
        servo = CommandFilter(ServoLimits())
        servo.reset(_beats(cycle[(phase - 1) % 4])[0])
        for k in range(8):
            beats = _beats(cycle[(phase + k) % 4])[0]
            np.testing.assert_allclose(servo(beats, 0.5), beats, atol=1e-12)


def test_the_copy_follows_the_env_fins():
    # the controller's copy latches the patterns it sent as the env does: same fin angles and strokes
    env = gym.make("PectoralFish-Averaged-v0", transitions=True, ripple_offsets=True)
    config = env.unwrapped.config
    nmpc = make_baseline("nmpc", config, step_budget=1e6)
    spin = nmpc.spin
    assert spin is not None and spin.available
    env.reset(seed=3)
    spin.reset()
    rng = np.random.default_rng(0)
    for k in range(7):
        u = SPIN_CYCLE[k % 4] if k < 4 else np.array([rng.uniform(0, 0.5), rng.uniform(0, 0.5),
                                                      rng.uniform(0.8, 2.3), rng.uniform(0.8, 2.3)])
        env.step(nmpc.fins.action(u[2], u[0], u[3], u[1]))
        spin.applied(u)
        model = env.unwrapped.core.model
        np.testing.assert_allclose(spin._shadow.fins[0], model.fins[0], atol=1e-6)
        np.testing.assert_allclose(spin._shadow.pending[0], model.pending[0], atol=1e-6)
    env.close()


def test_state_and_input_terms_add_up_to_the_objective():
    # the split objective (state terms + the candidates' input terms in numpy) equals the NLP's cost
    nmpc = make_baseline("nmpc", CONFIG, step_budget=1e6, blocks=None)
    problem, n = nmpc.problem, nmpc.problem.horizon
    rng = np.random.default_rng(1)
    u = np.column_stack([rng.uniform(0.0, 0.5, (n, 2)), np.full((n, 2), math.pi / 2)])  # biases at 90 deg
    u_prev = np.array([0.1, 0.2, math.pi / 2, math.pi / 2])
    x = np.asarray(problem.rollout(np.array([0.5, 0.5, 0.3, 0.02, 0.0, 0.0]), to_z(u.T), to_z(u_prev), nmpc.gains))
    p = problem.parameters(x[:, 0], np.array([1.2, 0.6]), np.zeros(2), to_z(u_prev), nmpc.gains)
    total = float(problem.cost(pack_decision(to_z(u.T), x), p))
    spin = SpinTurns(CONFIG, nmpc.fins, nmpc.scaling, n, u[-1])
    changes = spin.input_cost(u[None], u_prev, problem.input_width, nmpc.settings.w_change)[0]
    work = problem.energy_rate * spin.beat_work(u[None])[0]
    assert float(problem.state_cost(x, p)) + work + changes == pytest.approx(total, rel=1e-10)
    # the input terms by hand: fin work of every interval, changes between intervals
    z = np.column_stack([u[:, :2] ** 2, u[:, 2:]])
    dz = np.diff(np.vstack([to_z(u_prev), z]), axis=0) / problem.input_width
    assert changes == pytest.approx(nmpc.settings.w_change * np.sum(dz**2), rel=1e-12)
    assert work == pytest.approx(problem.energy_rate * CONFIG.control_period * np.sum(u[:, :2] ** 3), rel=1e-12)


def test_rollout_work_is_the_swept_work_of_the_model():
    # the candidates' fin work equals that of the same commands on a fresh model (strokes actually swept)
    nmpc = make_baseline("nmpc", CONFIG, step_budget=1e6)
    spin = nmpc.spin
    spin.reset()
    state = np.array([0.6, 0.5, 0.0, 0.0, 0.0, 0.0])
    u, x, work = spin.rollouts(state, np.array([0.3, 0.5]))
    i = 5
    m = AveragedModel(n=1)
    m.reset(state[None])
    for k in range(u.shape[1]):
        m.command_array(spin._patterns(u[i, k])[None])
        m.advance(CONFIG.control_period)
    assert work[i] == pytest.approx(m.fin_work().sum(), rel=1e-9)
    np.testing.assert_allclose(x[i][:, -1], m.state[0], atol=1e-9)
    assert work[i] > 0


def test_nmpc_spins_towards_a_goal_behind_it_near_a_wall():
    # facing the x = 0 wall 0.3 m ahead with the goal 0.3 m behind: no turning circle fits, the spin does
    nmpc = make_baseline("nmpc", CONFIG, step_budget=1e6)
    state = np.array([0.35, 0.6, math.pi, 0.0, 0.0, 0.0])
    nmpc.reset()
    u = nmpc._plan_step(state, np.array([0.65, 0.6]), np.zeros(2))
    assert nmpc._plan_spins
    assert np.any(np.all(np.isclose(u, np.vstack([SPIN_CYCLE, mirror(SPIN_CYCLE)])), axis=1))


def test_spin_is_off_for_track_by_setting_and_without_transitional_strokes():
    assert make_baseline("nmpc", EnvConfig(model="full", task="track"), step_budget=1e6).spin is None
    assert make_baseline("nmpc", CONFIG, step_budget=1e6, spin=False).spin is None
    # a period range whose shortest period is not the cycle's: no candidates
    other = EnvConfig(model="full", task="goal", period_range=(0.6, 2.0))
    assert make_baseline("nmpc", other, step_budget=1e6).spin is None
    # the averaged env without transitional strokes (its registered default) cannot spin; with them it can
    assert make_baseline("nmpc", EnvConfig(model="averaged", task="goal"), step_budget=1e6).spin is None
    with_strokes = EnvConfig(model="averaged", task="goal", transitions=True)
    assert make_baseline("nmpc", with_strokes, step_budget=1e6).spin is not None
