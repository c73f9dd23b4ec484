"""The averaged model's beat-mean ripple offset (docs/model.md section 3.8, AveragedModel(ripple_offsets=True))."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model.averaging import odd_moment, ripple_offset
from pectoral_gym.model.dynamics import fin_angle_eq21, fin_force_right
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.steady import steady_state_batch

PATTERNS = [(90, 22, 1.0, 4.0), (60, 30, 0.5, 5.0), (120, 10, 2.0, 1.0), (100, 80, 1.3, 0.7), (45, 2, 0.8, 2.5)]


def _offset_by_quadrature(beat: FinBeat, params: FishParams) -> np.ndarray:
    """``M = (1/T) int_0^T E dt``, ``E`` the impulse of (16)-(17) beyond the cycle mean, along eq. (21).

    By parts, ``M = fbar T / 2 - (1/T) int_0^T t f(t) dt``; adaptive quadrature of each half-stroke
    (the inertial terms jump at the turning points), inertial terms included.
    """
    k, inertia = params.fin_drag_constant, params.fin_inertia_constant
    period = beat.period
    turn = period / (beat.ratio + 1.0)

    def force(t: float, axis: int) -> float:
        g, gd, gdd = (float(np.ravel(x)[0]) for x in fin_angle_eq21(np.array([t]), beat.bias, beat.amplitude,
                                                                     beat.period, beat.ratio))
        return fin_force_right(g, gd, gdd, k, inertia)[axis]

    out = []
    for axis in (0, 1):
        impulse = moment = 0.0
        for a, b in ((0.0, turn), (turn, period)):
            impulse += quad(force, a, b, args=(axis,), epsabs=1e-15, epsrel=1e-12, limit=200)[0]
            moment += quad(lambda t, ax=axis: t * force(t, ax), a, b, epsabs=1e-15, epsrel=1e-12, limit=200)[0]
        out.append(impulse / 2.0 - moment / period)
    return np.array(out)


def test_odd_moment_series_equals_quadrature():
    for h in (-1.5, -0.4, 1e-3, 0.3, 1.0, math.pi / 2):
        expected = quad(lambda p, h=h: (p - math.pi / 2) * math.sin(p) ** 2 * math.sin(h * math.cos(p)), 0, math.pi,
                        epsabs=1e-14)[0]
        assert odd_moment(h) == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert odd_moment(1e-6) == pytest.approx(-4e-6 / 9, rel=1e-9)  # q_0 = -4/9


@pytest.mark.parametrize("pattern", PATTERNS)
def test_ripple_offset_closed_form_equals_the_sampled_blade_element_impulse(pattern):
    params = FishParams()
    beat = FinBeat.from_degrees(*pattern)
    expected = _offset_by_quadrature(beat, params)
    got = ripple_offset(beat.bias, beat.amplitude, beat.period, beat.ratio, params.fin_drag_constant)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.max(np.abs(expected)))
    assert ripple_offset(beat.bias, 0.0, beat.period, beat.ratio, params.fin_drag_constant) == (0.0, 0.0)


def test_the_left_fin_mirrors_sway_and_moment_in_the_cache():
    params = FishParams()
    beat = FinBeat.from_degrees(80, 20, 1.0, 3.0)
    model = AveragedModel(1, params)
    model.reset(right=beat, left=beat)
    model.advance(0.01)  # both fins latch
    right, left = model.forcing_cache[0, 0], model.forcing_cache[0, 1]
    mx, my = ripple_offset(beat.bias, beat.amplitude, beat.period, beat.ratio, params.fin_drag_constant)
    assert (right[fc.OFF_FX], right[fc.OFF_FY], right[fc.OFF_TAU]) == pytest.approx((mx, my, params.fin_offset * mx))
    assert (left[fc.OFF_FX], left[fc.OFF_FY], left[fc.OFF_TAU]) == pytest.approx((mx, -my, -params.fin_offset * mx))


def test_averaged_surge_is_the_full_models_beat_mean_without_damping():
    """No body drag, lift or yaw damping, both fins the same pattern (no sway, no yaw): the surge
    velocity is impulse / m1. From rest, the averaged model (K = 1) with both corrections then equals
    the full model's velocity averaged over each regular beat, at the beat's middle; without the ripple
    offset it is short by M / m1."""
    params = FishParams().replace(drag_coef=1e-9, lift_coef=1e-9, moment_coef=1e-9)
    beats = np.array([FinBeat.from_degrees(*p).as_array() for p in PATTERNS[:4]])
    command = np.ascontiguousarray(np.stack([beats, beats], axis=1))
    period = beats[:, 2]
    # advance fish by fish to whole beats: the first (transitional) beat, then one regular beat
    for i in range(beats.shape[0]):
        t = period[i]
        models = {name: AveragedModel(1, params, scaling="none", ripple_offsets=(name == "on")) if name != "full"
                  else FullModel(1, params) for name in ("full", "on", "off")}
        for model in models.values():
            model.reset()
            model.command_array(command[i:i + 1].copy())
            model.advance(t)  # the first beat ends with a recovery stroke: the impulses agree again
        start = models["full"].integral[0, 0]
        models["full"].advance(t)
        beat_mean = (models["full"].integral[0, 0] - start) / t
        for name in ("on", "off"):
            models[name].advance(0.5 * t)
        mx = ripple_offset(*beats[i], params.fin_drag_constant)[0]
        expected_gap = 2.0 * mx / params.m1  # two fins
        assert models["on"].state[0, 3] == pytest.approx(beat_mean, rel=1e-4, abs=1e-4 * abs(expected_gap))
        assert models["off"].state[0, 3] == pytest.approx(beat_mean - expected_gap, rel=1e-4,
                                                          abs=1e-4 * abs(expected_gap))


def test_ripple_offsets_leave_the_steady_states_unchanged():
    right, left = FinBeat.from_degrees(100, 25, 1.0, 3.0), FinBeat.from_degrees(85, 20, 1.2, 3.5)
    beats = np.array([[right.as_array(), left.as_array()]])
    on = steady_state_batch(AveragedModel(1), beats)[0]
    off = steady_state_batch(AveragedModel(1, ripple_offsets=False), beats)[0]
    assert on.converged and off.converged
    assert on.omega == pytest.approx(off.omega, rel=1e-6) and on.vx == pytest.approx(off.vx, rel=1e-6)


def test_parking_gives_the_offset_back():
    """A fin that parks delivers -M: after a pattern and its parking stroke the delivered offset is zero."""
    model = AveragedModel(1)
    model.reset()
    model.command(right=FinBeat.from_degrees(90, 20, 1.0, 3.0))
    model.advance(3.0)
    assert model.forcing_cache[0, 0, fc.OFF_FX] > 0.0
    model.command()  # both fins to rest
    model.advance(2.0)
    assert model.forcing_cache[0, 0, fc.OFF_FX] == 0.0 and model.forcing_cache[0, 0, fc.OFF_TAU] == 0.0


@pytest.mark.parametrize("pattern", PATTERNS)
def test_symbolic_ripple_offset_equals_the_compiled_one(pattern):
    import casadi as ca

    from pectoral_gym.model.symbolic_corrections import ripple_offset_sx

    params = FishParams()
    beat = FinBeat.from_degrees(*pattern)
    mx, my = ripple_offset(beat.bias, beat.amplitude, beat.period, beat.ratio, params.fin_drag_constant)
    for side in (1.0, -1.0):
        got = np.array(ca.DM(ripple_offset_sx(beat.as_array(), side, params))).ravel()
        np.testing.assert_allclose(got, [mx, side * my, side * params.fin_offset * mx], rtol=1e-13, atol=1e-18)
