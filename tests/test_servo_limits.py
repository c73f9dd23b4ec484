"""What the default servo limits let through (pectoral_gym.model.servo.ServoLimits, clip_beats), by hand."""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model.servo import ServoLimits, clip_beats, peak_rates


def test_fastest_default_stroke_is_slowed_to_the_servo_speed():
    # (90, 30 deg, 0.5 s, 5): power stroke 2 x 30 deg in 0.5 / 6 s, peak pi * 30 deg * 6 / 0.5 s = 19.7 rad/s
    fast = np.array([[math.pi / 2, math.radians(30.0), 0.5, 5.0]] * 2)
    np.testing.assert_allclose(peak_rates(fast)[:, 0], math.pi * math.radians(30.0) * 6.0 / 0.5)
    clipped, changed = clip_beats(fast, ServoLimits())
    assert changed
    np.testing.assert_allclose(clipped[:, 2], math.pi * math.radians(30.0) * 6.0 / 13.0)  # 0.759 s: 13 rad/s
    np.testing.assert_allclose(peak_rates(clipped)[:, 0], 13.0)
    np.testing.assert_array_equal(clipped[:, [0, 1, 3]], fast[:, [0, 1, 3]])


def test_slow_default_strokes_pass_unchanged():
    # peak pi * 30 deg * 2 / 1 s = 3.3 rad/s, far below 13 rad/s
    slow = np.array([[math.radians(45.0), math.radians(30.0), 1.0, 1.0], [math.radians(135.0), 0.0, 2.0, 5.0]])
    clipped, changed = clip_beats(slow, ServoLimits())
    assert not changed
    np.testing.assert_array_equal(clipped, slow)
