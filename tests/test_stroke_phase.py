"""strokes.StrokePhase: the full model's rotated stroke phase equals the direct evaluation of the forces."""

import math

import numpy as np

from pectoral_gym.model import strokes as st
from pectoral_gym.model.params import FinBeat, FishParams, coefficient_vector


def test_rotated_phase_forces_match_direct_evaluation_over_a_long_segment():
    params = FishParams(fin_force_scale_left=0.7, fin_angle_offset_right=0.04, fin_angle_scale_right=1.1)
    n = 1
    fins = np.zeros((n, 2, st.FIN_FIELDS))
    pending = np.zeros((n, 2, 4))
    beats = np.stack([FinBeat.from_degrees(100, 25, 1.0, 3).as_array(),
                      FinBeat.from_degrees(70, 15, 0.6, 1.5).as_array()])
    st.init_fins(fins, pending, beats[None], None)
    st.latch(fins, pending, 0, 0)
    st.latch(fins, pending, 0, 1)
    fins[0, 0, st.ELAPSED] = 0.013  # part-way into both strokes
    fins[0, 1, st.ELAPSED] = 0.002
    step = 1e-3
    p0, p1 = st.stroke_phase(fins, 0, 0, step, 0.0, 0.04, 1.1), st.stroke_phase(fins, 0, 1, step)
    k, c, off = params.fin_drag_constant, params.fin_inertia_constant, params.fin_offset
    coef = coefficient_vector(params)[None]
    worst = 0.0
    for j in range(200):  # far more rotations than one segment's 2 per substep
        got = np.array(st.phase_forcing(p0, p1, k, 0.7 * k, c, off))
        want = np.array(st.fin_forcing(fins, coef, 0, j * step))  # direct trig at each instant
        worst = max(worst, float(np.max(np.abs(got - want)) / np.max(np.abs(want))))
        p0, p1 = st.advance_phase(p0), st.advance_phase(p1)
    assert worst < 1e-12


def test_a_still_fin_has_no_phase_and_no_force():
    fins = np.zeros((1, 2, st.FIN_FIELDS))
    fins[0, :, st.ANGLE_FROM] = fins[0, :, st.ANGLE_TO] = math.pi / 2
    p = st.stroke_phase(fins, 0, 0, 0.01)
    assert not p.moving
    assert st.phase_forcing(p, st.advance_phase(p), 1.0, 1.0, 1.0, 0.1) == (0.0, 0.0, 0.0)
