"""A fish whose two fins differ: per-fin force factor and servo map (``FishParams.fin_*_right/left``).

The references are independent of the per-fin code: the mirror image of the fish, a one-fin fish, the symmetric
fish commanded the mapped pattern, the closed-form average of ``docs/model.md`` 3.4 typed in here, and the full
model for the averaged one.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.special import j1

from pectoral_gym import AveragedModel, FinBeat, FullModel
from pectoral_gym.model.averaging import averaged_forcing
from pectoral_gym.model.kloading import load_scaling
from pectoral_gym.model.params import PER_FIN_DEFAULTS, FishParams, coefficient_vector, load_params
from pectoral_gym.model.steady import steady_state

MODELS = {"full": FullModel, "averaged": AveragedModel}
ASYMMETRIC = dict(fin_force_scale_right=0.8, fin_force_scale_left=1.1, fin_angle_offset_right=0.05,
                  fin_angle_offset_left=-0.03, fin_angle_scale_right=1.1, fin_angle_scale_left=0.95)
SWAPPED = dict(fin_force_scale_right=1.1, fin_force_scale_left=0.8, fin_angle_offset_right=-0.03,
               fin_angle_offset_left=0.05, fin_angle_scale_right=0.95, fin_angle_scale_left=1.1)
FIRST = (FinBeat.from_degrees(85, 20, 0.9, 4), FinBeat.from_degrees(100, 15, 0.7, 3))  # right, left
SECOND = (FinBeat.from_degrees(70, 25, 1.1, 2.5), FinBeat.from_degrees(90, 0, 1.0, 1))


def _run(kind: str, params: FishParams, first, second, t1: float = 3.0, t2: float = 3.5, **options) -> np.ndarray:
    """State after ``first`` for ``t1`` s from its own start, then ``second`` (a pattern change) for ``t2`` s."""
    model = MODELS[kind](n=1, params=params, **options)
    model.reset(right=first[0], left=first[1])
    model.command(right=first[0], left=first[1])
    model.advance(t1)
    model.command(right=second[0], left=second[1])
    model.advance(t2)
    return model.state[0].copy()


def test_a_file_without_per_fin_fields_loads_the_symmetric_fish(tmp_path):
    path = tmp_path / "robot.json"
    path.write_text(json.dumps({"fin_span": 0.05}))
    params = load_params(path)
    assert params.symmetric_fins and params.fin_span == 0.05
    row = coefficient_vector(params)
    assert row[-6:].tolist() == [1.0, 1.0, 0.0, 0.0, 1.0, 1.0]
    assert set(PER_FIN_DEFAULTS) <= {f for f in params.__dataclass_fields__}
    assert not FishParams(fin_angle_offset_left=0.01).symmetric_fins


@pytest.mark.parametrize("field, value", [("fin_force_scale_left", -0.1), ("fin_angle_scale_right", 0.0),
                                          ("fin_angle_offset_right", 1.6), ("fin_force_scale_right", math.nan)])
def test_bad_per_fin_values_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        FishParams(**{field: value})


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_the_mirrored_fish_swims_the_mirrored_path(kind):
    """Right and left swapped, patterns swapped: X, vx equal; Y, psi, vy, omega negated."""
    a = _run(kind, FishParams(**ASYMMETRIC), FIRST, SECOND)
    b = _run(kind, FishParams(**SWAPPED), FIRST[::-1], SECOND[::-1])
    assert abs(a[5]) > 0.02  # the fish turns: the check can fail
    np.testing.assert_allclose(b, a * np.array([1, -1, -1, 1, -1, -1]), rtol=0, atol=1e-10)
    # and the asymmetry matters: the symmetric fish swims elsewhere
    assert np.max(np.abs(_run(kind, FishParams(), FIRST, SECOND)[:2] - a[:2])) > 1e-3


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_a_fin_with_force_factor_zero_is_the_one_fin_fish(kind):
    """Without fin inertia (``fin_effective_mass = 0``), a blade-less left fin that beats = the left fin at rest.

    The beating fin's turning points split the integration differently: small steps keep that apart from the forces.
    """
    massless = dict(fin_mass=0.0, fin_effective_mass=0.0)
    steps = {"dt_max": 0.005}
    beating = _run(kind, FishParams(fin_force_scale_left=0.0, **massless), FIRST, SECOND, **steps)
    one_fin = _run(kind, FishParams(**massless), (FIRST[0], None), (SECOND[0], None), **steps)
    assert abs(one_fin[5]) > 0.02
    np.testing.assert_allclose(beating, one_fin, rtol=0, atol=2e-7)  # integration steps differ, not the forces


def test_the_averaged_forcing_is_linear_in_each_fins_force_factor_by_hand():
    """``docs/model.md`` 3.4 with the fin's factor and map typed in.

    ``fbar_hx = lambda_f k pi^2 (zeta^2-1)/(zeta T^2) a_1 gA J1(a_1 gA) sin(a_0 + a_1 g0)``.
    """
    beat = FinBeat.from_degrees(80, 20, 0.8, 3)
    params = FishParams(fin_force_scale_left=0.6, fin_angle_offset_left=0.1, fin_angle_scale_left=0.9)
    k = 4.1464 * 1000 * 0.041 * 0.061**3 / 6  # Table 1's k, typed in
    g0, ga = 0.1 + 0.9 * beat.bias, 0.9 * beat.amplitude
    c = 0.6 * k * math.pi**2 * (3**2 - 1) / (3 * 0.8**2)
    fx, fy, tau = averaged_forcing(beat, params, "left")
    assert fx == pytest.approx(c * ga * j1(ga) * math.sin(g0), rel=1e-12)
    assert fy == pytest.approx(-c * ga * j1(ga) * math.cos(g0), rel=1e-12)
    assert tau == pytest.approx(-0.03 * fx, rel=1e-12)
    assert averaged_forcing(beat, params, "right") == averaged_forcing(beat, FishParams(), "right")


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_a_servo_map_is_the_mapped_command_on_the_symmetric_fish(kind):
    """Offset ``a_0``, scale ``a_1``: commanding ``(g0, gA)`` = ``(a_0 + a_1 g0, a_1 gA)`` to the paper's fin."""
    mapped = FishParams(fin_angle_offset_right=0.1, fin_angle_scale_right=0.9, fin_angle_offset_left=-0.05)

    def actual(beats, side_maps=((0.1, 0.9), (-0.05, 1.0))):
        return tuple(FinBeat(o + s * b.bias, s * b.amplitude, b.period, b.ratio)
                     for b, (o, s) in zip(beats, side_maps, strict=True))

    got = _run(kind, mapped, FIRST, SECOND)
    expected = _run(kind, FishParams(), actual(FIRST), actual(SECOND))
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(_run(kind, FishParams(), FIRST, SECOND) - got)) > 1e-3  # the map matters


def test_fin_work_follows_each_fins_factor_and_scale():
    """Eq. (14)'s power ``(3 k S_p / 4)|g'|^3``: times ``lambda_f``, and times ``a_1^3`` through the actual rate."""
    beat = FinBeat.from_degrees(90, 20, 1.0, 3)
    model = FullModel(n=1, params=FishParams(fin_force_scale_left=0.5, fin_angle_scale_left=1.2))
    model.reset(right=beat, left=beat)
    model.command(right=beat, left=beat)
    model.advance(2.0)
    right, left = model.fin_work()[0]
    assert right > 0 and left == pytest.approx(0.5 * 1.2**3 * right, rel=1e-12)


@pytest.mark.parametrize("params, right, left", [
    (FishParams(fin_force_scale_right=0.75), FinBeat.from_degrees(80, 22, 1.0, 4), None),
    (FishParams(fin_force_scale_left=0.75), FinBeat.from_degrees(80, 22, 1.0, 4), FinBeat.from_degrees(80, 22, 1.0, 4)),
])
def test_the_averaged_model_follows_the_full_one_on_an_asymmetric_fish(params, right, left):
    """The shipped K on a fish with a weaker fin, within the tolerance of the symmetric fish's K test
    (``test_scaling_functions``: speed 5 %, turn rate 10 %); measured 0.2 %/0.2 % and 1.7 %/9.3 %."""
    full = steady_state("full", right=right, left=left, params=params)
    averaged = steady_state("averaged", right=right, left=left, params=params)
    assert abs(full.omega) > 0.05
    assert averaged.speed == pytest.approx(full.speed, rel=0.05)
    assert averaged.omega == pytest.approx(full.omega, rel=0.1)


def test_the_k_check_ignores_the_per_fin_fields_only():
    load_scaling("identified", params=FishParams(fin_force_scale_left=0.75, fin_angle_offset_right=0.05))
    with pytest.raises(ValueError, match="fin_force_coef"):
        load_scaling("identified", params=FishParams(fin_force_coef=4.0))


@pytest.mark.parametrize("env_id", ["PectoralFish-Averaged-v2", "PectoralFish-Full-v2"])
def test_the_envs_take_a_fish_whose_fins_differ(env_id):
    """``gym.make(id, params=...)`` with per-fin fields: the same seeded actions swim another path."""
    import gymnasium as gym

    def final_obs(params):
        env = gym.make(env_id, params=params)
        env.reset(seed=3)
        for _ in range(10):
            obs = env.step(np.full(env.action_space.shape, 0.3, dtype=np.float32))[0]
        env.close()
        return obs

    symmetric = final_obs(None)
    np.testing.assert_array_equal(symmetric, final_obs({"fin_force_scale_left": 1.0}))  # the default, exactly
    assert np.max(np.abs(final_obs({"fin_force_scale_left": 0.75}) - symmetric)) > 1e-3
