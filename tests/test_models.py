"""FullModel and AveragedModel: turning directions, symmetry, batching, dissipation, argument checks.

References are independent of the package's integrators (``tests/model_reference.py``): the closed-form
coast-down with fins at rest, ``m1 dvx/dt = -c1 vx^2`` gives ``vx = v0 / (1 + c1 v0 t / m1)`` and
``s = (m1/c1) ln(1 + c1 v0 t / m1)``; the energy balance ``dE/dt = -c1 |V|^3 - C_M |omega|^3`` for
``E = (m1 vx^2 + m2 vy^2 + J3 omega^2) / 2`` with fins at rest (the Coriolis terms of eq. 20 and the lift terms
do no work). The models against the ODE solved by scipy: ``tests/test_models_against_ode.py``.

Sign reasoning for a turn (x forward, y left, omega > 0 = left turn): the right
fin pivots at ``y = -C_p``; its mean thrust ``f_x > 0`` gives the moment
``tau = (r x f)_z = -(-C_p) f_x > 0``, so the right fin alone turns the fish left.
With bias 90 deg its mean side force is zero, and the sway equation at steady
state, ``0 = -m1 vx omega - (c1 + c2 ...) |V| vy``, forces ``vy`` to the sign of
``-vx omega``: the body skids outward, ``vy < 0``.
"""

import math

import numpy as np
import pytest
from model_reference import (
    C1,
    CM,
    FORWARD,
    J3,
    M1,
    M2,
    TURN,
    P,
    cycle_average,
    run,
)

from pectoral_gym import AveragedModel, FinBeat, FullModel

# --------------------------------------------------------------------------- turning directions, symmetry

MODELS = [lambda n=1: FullModel(n), lambda n=1: AveragedModel(n, scaling=None)]
MODEL_IDS = ["full", "averaged"]


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_right_fin_alone_turns_left(make):
    m = make()
    m.reset(right=TURN)
    m.advance(40.0)
    vx, vy, om = cycle_average(m, 1.0)[0]
    assert om > 0.02
    assert vx > 0.01
    assert vy < -0.001  # outward skid, see module docstring
    assert m.state[0, 2] > 2.0  # heading has turned counter-clockwise


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_left_fin_alone_turns_right(make):
    m = make()
    m.reset(left=TURN)
    m.advance(40.0)
    vx, vy, om = cycle_average(m, 1.0)[0]
    assert om < -0.02
    assert vx > 0.01
    assert vy > 0.001
    assert m.state[0, 2] < -2.0


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("beat", [TURN, FORWARD, FinBeat.from_degrees(60, 30, 0.5, 0.5)])
def test_equal_patterns_swim_straight(make, beat):
    m = make()
    m.reset(right=beat, left=beat)
    for _ in range(30):
        m.advance(0.37)
        assert abs(m.state[0, 4]) < 1e-12  # vy
        assert abs(m.state[0, 5]) < 1e-12  # omega
        assert abs(m.state[0, 1]) < 1e-12 and abs(m.state[0, 2]) < 1e-12  # Y, psi
    assert abs(m.state[0, 3]) > 1e-3


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("beat", [TURN, FORWARD, FinBeat.from_degrees(130, 40, 2.0, 3.0)])
def test_mirror_symmetry(make, beat):
    right = run(make(), 17.3, right=beat)[0]
    left = run(make(), 17.3, left=beat)[0]
    mirror = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])  # X, Y, psi, vx, vy, omega
    np.testing.assert_allclose(left, mirror * right, rtol=1e-12, atol=1e-15)
    assert abs(right[5]) > 1e-3


def test_mirror_symmetry_two_fins_swapped():
    other = FinBeat.from_degrees(70, 25, 0.7, 2.0)
    a = run(FullModel(1), 9.1, right=FORWARD, left=other)[0]
    b = run(FullModel(1), 9.1, right=other, left=FORWARD)[0]
    np.testing.assert_allclose(b, a * np.array([1, -1, -1, 1, -1, -1]), rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------- batching

BATCH = [
    (TURN, None),
    (None, FORWARD),
    (FORWARD, FORWARD),
    (FinBeat.from_degrees(130, 40, 2.0, 3.0), FinBeat.from_degrees(60, 30, 0.5, 0.5)),
    (FinBeat.from_degrees(95, 12, 0.66, 5.0), TURN),
]


def _beats_array(pairs):
    rest = FinBeat.rest().as_array()
    return (np.array([(r or FinBeat.rest()).as_array() for r, _ in pairs]),
            np.array([(lf.as_array() if lf else rest) for _, lf in pairs]))


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_batch_equals_each_fish_alone(make):
    right, left = _beats_array(BATCH)
    batch = make(len(BATCH))
    batch.reset(right=right, left=left)
    for _ in range(4):
        batch.advance(1.3)
    for i, (r, lf) in enumerate(BATCH):
        one = make()
        one.reset(right=r, left=lf)
        for _ in range(4):
            one.advance(1.3)
        np.testing.assert_array_equal(batch.state[i], one.state[0])
        np.testing.assert_array_equal(batch.integral[i], one.integral[0])


def test_large_batch_parallel_path_equals_each_alone():
    n = 70  # above the parallel threshold
    rng = np.random.default_rng(3)
    bias = rng.uniform(math.radians(60), math.radians(120), (n, 2))
    amp = rng.uniform(0.0, math.radians(25), (n, 2))
    period = rng.choice([0.5, 0.8, 1.0], (n, 2))
    ratio = rng.choice([0.5, 2.0, 4.0], (n, 2))
    beats = np.stack([bias, amp, period, ratio], axis=-1)
    batch = FullModel(n)
    batch.reset(right=beats[:, 0], left=beats[:, 1])
    batch.advance(2.0)
    for i in (0, 17, 69):
        one = FullModel(1)
        one.reset(right=beats[i, 0], left=beats[i, 1])
        one.advance(2.0)
        np.testing.assert_allclose(batch.state[i], one.state[0], rtol=1e-13, atol=1e-16)


def test_batch_with_per_fish_params():
    heavy = P.replace(body_mass=1.5, drag_coef=0.6)
    batch = FullModel(2, params=[P, heavy])
    batch.reset(right=TURN, left=FORWARD)
    batch.advance(3.0)
    alone = FullModel(1, params=heavy)
    alone.reset(right=TURN, left=FORWARD)
    alone.advance(3.0)
    np.testing.assert_array_equal(batch.state[1], alone.state[0])
    assert not np.allclose(batch.state[0], batch.state[1])


def test_reset_index_only_resets_selected_fish():
    m = FullModel(3)
    m.reset(right=TURN, left=TURN)
    m.advance(2.0)
    before = m.state.copy()
    m.reset(right=TURN, left=TURN, index=np.array([1]))
    np.testing.assert_array_equal(m.state[[0, 2]], before[[0, 2]])
    np.testing.assert_array_equal(m.state[1], 0.0)


# --------------------------------------------------------------------------- dissipation and kinematics


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_coast_down_straight_closed_form(make):
    v0, psi0 = 0.12, 0.7
    m = make()
    m.dt_max = 0.005  # fine steps, so the closed form is matched to 1e-7
    m.reset(state=np.array([0.3, -0.2, psi0, v0, 0.0, 0.0]))
    for t in np.arange(1, 21) * 0.5:
        m.advance(0.5)
        x, y, psi, vx, vy, om = m.state[0]
        assert vx == pytest.approx(v0 / (1 + C1 * v0 * t / M1), rel=1e-7)
        dist = M1 / C1 * math.log(1 + C1 * v0 * t / M1)
        assert x == pytest.approx(0.3 + dist * math.cos(psi0), rel=1e-7)
        assert y == pytest.approx(-0.2 + dist * math.sin(psi0), rel=1e-7)
        assert psi == psi0 and vy == 0.0 and om == 0.0


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
def test_speed_and_energy_decay_with_fins_at_rest(make):
    m = make()
    m.reset(state=np.array([0.0, 0.0, 0.0, 0.1, -0.04, 0.8]))
    dt = 0.002
    energy, dissipation = [], []
    for _ in range(1500):
        _, _, _, vx, vy, om = m.state[0]
        energy.append(0.5 * (M1 * vx**2 + M2 * vy**2 + J3 * om**2))
        dissipation.append(C1 * math.hypot(vx, vy) ** 3 + CM * abs(om) ** 3)
        m.advance(dt)
    energy, dissipation = np.array(energy), np.array(dissipation)
    assert np.all(np.diff(energy) < 0)
    # energy balance: E(t) - E(0) = -integral of the dissipation (trapezoid, O(dt^2))
    lost = np.concatenate([[0.0], np.cumsum(0.5 * (dissipation[1:] + dissipation[:-1]) * dt)])
    np.testing.assert_allclose(energy[0] - energy, lost, rtol=0, atol=1e-4 * energy[0])
    assert energy[-1] < 0.3 * energy[0]


def test_speed_decays_monotonically_straight():
    m = FullModel(1)
    m.reset(state=np.array([0, 0, 0, 0.2, 0, 0]))
    speeds = []
    for _ in range(200):
        m.advance(0.05)
        speeds.append(math.hypot(m.state[0, 3], m.state[0, 4]))
    assert np.all(np.diff(speeds) < 0) and speeds[-1] > 0


def test_position_integrates_body_velocity_in_heading_direction():
    # omega = 0, no fin forcing, vx only: the fish moves along its heading by the integral of vx.
    m = AveragedModel(1, scaling=None)
    psi0 = -2.0
    m.reset(state=np.array([0.0, 0.0, psi0, 0.08, 0.0, 0.0]))
    m.advance(6.0)
    travelled = m.integral[0, 0]  # integral of vx
    np.testing.assert_allclose(m.state[0, :2], travelled * np.array([math.cos(psi0), math.sin(psi0)]), rtol=1e-9)


# --------------------------------------------------------------------------- argument validation


@pytest.mark.parametrize("kwargs,match", [({"n": 0}, "n"), ({"dt_max": 0.0}, "dt_max"), ({"dt_max": -1.0}, "dt_max"),
                                          ({"min_substeps": 0}, "min_substeps"),
                                          ({"integration": "rk45"}, "integration")])
def test_full_model_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FullModel(**kwargs)


@pytest.mark.parametrize("kwargs,match", [({"forcing": "fourier"}, "forcing"), ({"scaling": "paper"}, "scaling")])
def test_averaged_model_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        AveragedModel(**kwargs)


def test_negative_duration_rejected():
    with pytest.raises(ValueError, match="duration"):
        FullModel().advance(-0.1)


@pytest.mark.parametrize("beat,field", [((1.0, -0.1, 1.0, 4.0), "amplitude"), ((1.0, 0.1, 0.0, 4.0), "period"),
                                        ((1.0, 0.1, 1.0, -4.0), "ratio"), ((0.1, 0.3, 1.0, 4.0), "bias"),
                                        ((math.nan, 0.1, 1.0, 4.0), "bias"), ((1.0, 0.1, math.inf, 4.0), "period")])
def test_command_validates_patterns(beat, field):
    m = FullModel(2)
    with pytest.raises(ValueError, match=field):
        m.command(right=np.array([TURN.as_array(), beat]))
    with pytest.raises(ValueError, match=field):
        m.reset(left=np.array(beat))


def test_command_array_shape_checked():
    with pytest.raises(ValueError, match="shape"):
        FullModel(2).command_array(np.zeros((1, 2, 4)))


def test_params_count_must_match_fish():
    with pytest.raises(ValueError, match="FishParams"):
        FullModel(3, params=[P, P])
