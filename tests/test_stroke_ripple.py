"""Yaw-oscillation gain of transitional half-strokes (docs/model.md section 3.9, pectoral_gym.model.ripple)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model.dynamics import fin_force_right, stroke_kinematics
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.ripple import half_stroke_ripple_square, transitional_oscillation_gain
from pectoral_gym.scaling.validation.fidelity import draw_patterns, open_loop

PARAMS = FishParams()
SCALING = ScalingFunctions.load()
K, INERTIA = PARAMS.fin_drag_constant, PARAMS.fin_inertia_constant
# (angle_from, angle_to, duration) in deg, deg, s: a regular-sized stroke, a full sweep, a short fast one
STROKES = [(60.0, 110.0, 1.5), (0.0, 180.0, 0.4), (150.0, 140.0, 0.25), (95.0, 20.0, 2.0)]


def _ripple_square_by_quadrature(a: float, b: float, d: float, mean: float) -> float:
    def deviation(t: float) -> float:
        return (fin_force_right(*stroke_kinematics(t, d, a, b), K, INERTIA)[0] - mean) ** 2

    return quad(deviation, 0.0, d, epsabs=1e-16, epsrel=1e-12, limit=200)[0] / d


@pytest.mark.parametrize("stroke", STROKES)
@pytest.mark.parametrize("mean", [0.0, 3e-3, -1e-2])
def test_ripple_square_equals_adaptive_quadrature_of_the_blade_element_force(stroke, mean):
    a, b, d = math.radians(stroke[0]), math.radians(stroke[1]), stroke[2]
    expected = _ripple_square_by_quadrature(a, b, d, mean)
    assert half_stroke_ripple_square(a, b, d, K, INERTIA, mean) == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("power", [True, False])
def test_gain_is_one_on_the_patterns_own_half_strokes_and_without_amplitude(power):
    beat = FinBeat.from_degrees(80, 25, 1.2, 3.0)
    low, high = beat.bias - beat.amplitude, beat.bias + beat.amplitude
    a, b = (low, high) if power else (high, low)
    d = beat.period / (beat.ratio + 1.0) if power else beat.ratio * beat.period / (beat.ratio + 1.0)
    assert transitional_oscillation_gain(a, b, d, power, *beat.as_array(), K, INERTIA) == 1.0
    # a still pattern has no phasor to scale: the sweep to its angle gets gain 1
    assert transitional_oscillation_gain(0.3, beat.bias, d, power, beat.bias, 0.0, beat.period, beat.ratio,
                                         K, INERTIA) == 1.0


def test_gain_is_the_fourth_root_of_the_ripple_squares_ratio():
    """The quasi-static yaw limit (docs/model.md 3.9): G = (S_swept / S_regular)^(1/4), both by quadrature."""
    beat = FinBeat.from_degrees(100, 15, 0.8, 2.0)
    low, high = beat.bias - beat.amplitude, beat.bias + beat.amplitude
    t_power = beat.period / (beat.ratio + 1.0)
    t_recovery = beat.period - t_power
    impulse = sum(quad(lambda t, a=a, b=b, d=d: fin_force_right(*stroke_kinematics(t, d, a, b), K, INERTIA)[0],
                       0.0, d, epsabs=1e-16, epsrel=1e-12)[0]
                  for a, b, d in ((low, high, t_power), (high, low, t_recovery)))
    mean = impulse / beat.period  # the pattern's exact cycle-mean f_hx
    swept = (math.radians(20.0), high, t_power)  # a power stroke from far below the pattern's turning point
    expected = (_ripple_square_by_quadrature(*swept, mean)
                / _ripple_square_by_quadrature(low, high, t_power, mean)) ** 0.25
    gain = transitional_oscillation_gain(*swept, True, *beat.as_array(), K, INERTIA)
    assert gain == pytest.approx(expected, rel=2e-6)
    assert gain > 1.5  # a sweep of 95 deg in place of 30 deg ripples far more


def test_the_gain_lasts_one_half_stroke_and_mirrors_between_fins():
    model = AveragedModel(1)
    model.reset()
    beat = FinBeat.from_degrees(90, 20, 1.0, 3.0)
    model.command(right=beat, left=beat)
    model.advance(0.05)  # inside the first (transitional) power stroke, swept from 90 deg to 110 deg
    excess = model.forcing_cache[0, :, fc.OSC_EXCESS]
    assert excess[0] != 0.0 and excess[0] == excess[1]  # the left fin's stroke is the mirror image
    model.advance(2.0 * beat.period)  # on the pattern: regular half-strokes only
    assert np.all(model.forcing_cache[0, :, fc.OSC_EXCESS] == 0.0)


def test_without_transitions_there_is_no_gain():
    model = AveragedModel(1, transitions=False)
    model.reset()
    model.command(right=FinBeat.from_degrees(90, 20, 1.0, 3.0))
    model.advance(0.05)
    assert model.forcing_cache[0, 0, fc.OSC_EXCESS] == 0.0


def test_one_fin_changed_every_half_second_turns_as_the_full_model_does():
    """The other model as reference: 32 one-fin schedules, a new pattern every 0.5 s for 20 s.

    Least-squares slope of the averaged model's total turns on the full model's: 1.07 with the
    gain, 1.13 without it (the averaged fish turned too much, its yaw damping too weak).
    """
    rng = np.random.default_rng(5)
    schedule = draw_patterns(rng, 32, 40)
    schedule[:, :, 1] = FinBeat.rest().as_array()
    full, averaged = (open_loop(kind, schedule, 0.5, 20.0, PARAMS, SCALING)
                      for kind in ("full", "averaged"))
    turn_full, turn_averaged = full[:, -1, 2] - full[:, 0, 2], averaged[:, -1, 2] - averaged[:, 0, 2]
    slope = np.sum(turn_averaged * turn_full) / np.sum(turn_full**2)
    assert abs(slope - 1.0) < 0.10
