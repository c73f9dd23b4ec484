"""The averaged model's latch: K and the yaw-oscillation phasor evaluated together (ktables.pattern_values)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.interpolate import NdBSpline

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.ktables import interleave, pattern_values, scaling_values, yaw_oscillation_phasor


def _random_scaling(shared: bool) -> ScalingFunctions:
    """Random K and phasor splines over the shipped knots; the phasor's bias knots moved unless ``shared``."""
    base = ScalingFunctions.load()
    rng = np.random.default_rng(11)
    table = 1.0 + rng.normal(0.0, 0.2, size=base.table.shape)
    osc = rng.normal(0.0, 0.3, size=(2,) + base.table.shape[1:])
    osc_knots = tuple(np.array(k) for k in base.knots)
    if not shared:
        osc_knots = (osc_knots[0] * 1.01,) + osc_knots[1:]
    return dataclasses.replace(base, table=table, oscillation_knots=osc_knots, oscillation_table=osc)


PATTERNS = [  # bias, amplitude, period, ratio: inside the grid, below the lowest amplitude node, clamped, at rest
    (math.radians(77), math.radians(21), 1.5, 2.6),
    (math.radians(101), math.radians(1.2), 0.7, 4.1),
    (math.radians(150), math.radians(29), 2.0, 0.9),
    (math.radians(90), 0.0, 1.0, 1.0),
]


@pytest.mark.parametrize("pattern", PATTERNS)
def test_pattern_values_are_the_splines_of_scipy(pattern):
    s = _random_scaling(shared=True)
    tables = s.kernel_arrays()
    assert tables.shared.shape == s.table.shape[1:] + (5,)
    bias, amplitude, period, ratio = pattern
    kx, ky, km, pc, ps = pattern_values(bias, amplitude, period, ratio, tables)
    # an independent evaluation: scipy's tensor-product B-spline, clamped to the knot range as the file says
    x = tuple(min(max(v, k[3]), k[-4]) for v, k in zip((bias, amplitude, 1.0 / ratio), s.knots, strict=True))
    expected_k = [float(NdBSpline(s.knots, s.table[c], 3)(x)) for c in range(3)]
    assert (kx, ky, km) == pytest.approx(expected_k, rel=1e-12, abs=1e-14)
    lowest = s.oscillation_knots[1][3]
    taper = 0.0 if amplitude <= 0 else min(1.0, amplitude / lowest)
    expected_p = [taper * float(NdBSpline(s.oscillation_knots, s.oscillation_table[c], 3)(x)) / period
                  for c in range(2)]
    assert (pc, ps) == pytest.approx(expected_p, rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("shared", [True, False])
@pytest.mark.parametrize("pattern", PATTERNS)
def test_pattern_values_equal_the_separate_evaluations_bit_for_bit(pattern, shared):
    """The one-pass path changes no number the model computed before it existed."""
    tables = _random_scaling(shared).kernel_arrays()
    assert (tables.shared.shape[0] > 0) == shared
    together = pattern_values(*pattern, tables)
    apart = scaling_values(*pattern, tables) + yaw_oscillation_phasor(*pattern, tables)
    assert together == apart


def test_interleave_needs_the_same_knots_and_three_k_channels():
    s = ScalingFunctions.load()
    t = s.kernel_arrays()
    assert interleave(t.knots, t.table, t.osc_knots, t.osc_table).shape[0] > 0
    assert interleave(t.knots, t.table, t.osc_knots + 0.1, t.osc_table).shape == (0, 0, 0, 5)
    assert interleave(t.knots, t.table, t.osc_knots, np.zeros((2, 0, 0, 0))).shape == (0, 0, 0, 5)
    unit = ScalingFunctions.unit().kernel_arrays()
    assert unit.shared.shape == (0, 0, 0, 5)
    assert pattern_values(1.2, 0.3, 1.0, 3.0, unit) == scaling_values(1.2, 0.3, 1.0, 3.0, unit) + (0.0, 0.0)
