"""The fins' hydrodynamic work over the strokes actually swept (FishModel.fin_work, eq. 14)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pectoral_gym.model.averaging import mean_fin_power
from pectoral_gym.model.dynamics import stroke_kinematics
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.params import FinBeat, FishParams

PARAMS = FishParams()
POWER = 0.75 * PARAMS.fin_drag_constant * PARAMS.fin_span  # 3 k S_p / 4, eq. (14)


@pytest.mark.parametrize("model", [FullModel, AveragedModel])
def test_regular_beats_do_the_mean_fin_power_times_the_time(model):
    beat = FinBeat.from_degrees(80, 20, 0.9, 3.0)
    fish = model(1, PARAMS)
    fish.reset(right=beat)
    for _ in range(7):  # uneven steps: the work is additive over segments
        fish.advance(3 * beat.period / 7)
    expected = 3 * beat.period * mean_fin_power(beat.amplitude, beat.period, beat.ratio, PARAMS.fin_span,
                                                PARAMS.fin_drag_constant)
    assert fish.fin_work()[0, 0] == pytest.approx(expected, rel=1e-12)
    assert fish.fin_work()[0, 1] == 0.0  # the left fin rests


def test_a_transitional_stroke_is_priced_by_quadrature_and_both_models_agree():
    """From rest at 90 deg, the first power stroke sweeps to 80 + 20 = 100 deg; then a regular recovery."""
    beat = FinBeat.from_degrees(80, 20, 0.9, 3.0)
    d1 = beat.period / (beat.ratio + 1)
    works = []
    for model in (FullModel(1, PARAMS), AveragedModel(1, PARAMS)):
        model.reset()
        model.command(right=beat)
        model.advance(0.6 * d1)  # part of the transitional stroke
        works.append(model.fin_work()[0, 0])
    cube = quad(lambda s: abs(stroke_kinematics(s, d1, math.radians(90), math.radians(100))[1]) ** 3, 0, 0.6 * d1,
                epsabs=1e-14, epsrel=1e-12)[0]
    assert works[0] == pytest.approx(POWER * cube, rel=1e-10)
    assert works[1] == works[0]


def test_the_envs_energy_term_misses_the_strokes_between_rest_patterns():
    """Commanding patterns of zero amplitude at other biases moves the fin, at no price in the envs'
    energy term (the regular beat of a still pattern has no power); its swept work is not zero."""
    model = AveragedModel(1, PARAMS)
    model.reset()
    for bias in (45, 135, 45, 135):
        model.command(right=FinBeat.from_degrees(bias, 0.0, 0.5, 5.0))
        model.advance(1.0)
    assert mean_fin_power(0.0, 0.5, 5.0, PARAMS.fin_span, PARAMS.fin_drag_constant) == 0.0
    sweep = POWER * 4.0 / 3.0 * math.radians(45) ** 3 * (math.pi / (0.5 / 6)) ** 2  # 90 -> 45 deg in T/(zeta+1)
    assert model.fin_work()[0, 0] > sweep
    model.reset()
    assert model.fin_work()[0, 0] == 0.0


def test_fin_work_uses_each_fishs_own_parameters():
    small = PARAMS.replace(fin_span=0.05)
    model = AveragedModel(2, PARAMS, scaling="none")
    model.set_params(small, index=np.array([1]))
    beat = FinBeat.from_degrees(90, 20, 1.0, 4.0)
    model.reset(right=beat)
    model.advance(2.0)
    work = model.fin_work()[:, 0]
    # the swept angles are the same; the power scales with k S_p, k proportional to S_p^3
    assert work[1] / work[0] == pytest.approx((0.05 / PARAMS.fin_span) ** 4, rel=1e-12)
