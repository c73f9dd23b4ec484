"""The safety bounds on a fish whose fins differ: each fin's force factor and servo scale, by hand and by model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.hardware.safety.blind import CommandedGain, fin_force_bound, fin_pair_force_bound
from pectoral_gym.hardware.safety.geofence import SpeedBound
from pectoral_gym.model.dynamics import fin_force_right
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.servo import ServoLimits

LIMITS = ServoLimits()
SYMMETRIC = FishParams()
# A left fin twice as strong whose servo turns it 20 % further than commanded; the right fin weaker.
UNEQUAL = FishParams(fin_force_scale_left=2.0, fin_angle_scale_left=1.2, fin_force_scale_right=0.5)


def test_each_fins_bound_by_hand():
    d_min = 0.4 / 7.0  # the servos' shortest half-stroke (docs/guide/safety.md, "Fin force")
    w = 13.0 * 1.2  # the left fin's actual peak rate for a commanded 13 rad/s
    by_hand = 2.0 * UNEQUAL.fin_drag_constant * w * w + UNEQUAL.fin_inertia_constant * math.hypot(
        w * w, math.pi * w / d_min)
    assert fin_force_bound(UNEQUAL, LIMITS, 13.0, fin=1) == pytest.approx(by_hand, rel=1e-12)
    assert fin_force_bound(UNEQUAL, LIMITS, 13.0) == pytest.approx(by_hand, rel=1e-12)  # the larger fin
    right = 0.5 * UNEQUAL.fin_drag_constant * 169.0 + UNEQUAL.fin_inertia_constant * math.hypot(
        169.0, math.pi * 13.0 / d_min)
    assert fin_force_bound(UNEQUAL, LIMITS, 13.0, fin=0) == pytest.approx(right, rel=1e-12)
    assert fin_pair_force_bound(UNEQUAL, LIMITS) == pytest.approx(by_hand + right, rel=1e-12)


def test_the_symmetric_fish_keeps_its_bounds_exactly():
    one = fin_force_bound(SYMMETRIC, LIMITS, LIMITS.max_speed, fin=0)
    assert fin_pair_force_bound(SYMMETRIC, LIMITS) == 2.0 * one
    assert CommandedGain(SYMMETRIC, LIMITS).full == pytest.approx(SpeedBound(SYMMETRIC, LIMITS).accel, rel=1e-12)


def test_a_stronger_fin_raises_the_speed_bound():
    stronger = FishParams(fin_force_scale_left=1.5)
    assert SpeedBound(stronger, LIMITS).accel > SpeedBound(SYMMETRIC, LIMITS).accel
    assert CommandedGain(stronger, LIMITS).full > CommandedGain(SYMMETRIC, LIMITS).full


@pytest.mark.parametrize("side", [0, 1])
def test_the_models_fin_force_stays_within_the_fins_bound(side):
    # The blade-element fin force (eqs. 9-17) of a half-cosine stroke through the servo range at the commanded
    # peak rate, with the fin's servo map applied as the model applies it: never above that fin's bound.
    name = ("right", "left")[side]
    scale, factor = getattr(UNEQUAL, f"fin_angle_scale_{name}"), getattr(UNEQUAL, f"fin_force_scale_{name}")
    d = 0.4 / 7.0
    amplitude = LIMITS.max_speed * d / math.pi  # commanded half-stroke whose peak rate is max_speed
    t = np.linspace(0.0, d, 2001)
    g = scale * (1.57 + amplitude * np.cos(math.pi * t / d))
    gd = -scale * amplitude * (math.pi / d) * np.sin(math.pi * t / d)
    gdd = -scale * amplitude * (math.pi / d) ** 2 * np.cos(math.pi * t / d)
    peak = max(math.hypot(*fin_force_right(a, b, c, factor * UNEQUAL.fin_drag_constant, UNEQUAL.fin_inertia_constant))
               for a, b, c in zip(g, gd, gdd, strict=True))
    assert peak <= fin_force_bound(UNEQUAL, LIMITS, LIMITS.max_speed, d, fin=side) * (1 + 1e-12)
    assert peak >= 0.5 * fin_force_bound(UNEQUAL, LIMITS, LIMITS.max_speed, d, fin=side)  # the bound is not vacuous
