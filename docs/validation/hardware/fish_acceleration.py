"""How fast the full model's fish gains speed: the figure the blind rule's physical bound is compared with.

Runs the full model (reference integration) from rest and from 0.2 m/s straight ahead, for 3 s, under a grid
of fin patterns within the servo limits (peak rate <= 13 rad/s, strokes inside [10, 170] deg), one fin or
both, and prints the largest speed gain over 5 ms (the instantaneous rate) and over 0.1, 0.2 and 0.3 s.

Example (the figures in docs/hardware.md, "Degraded radio and camera")::

    python docs/validation/hardware/fish_acceleration.py
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.spec import FULL_REFERENCE

DT = 0.005  # s, sampling of the speed
WINDOWS = (0.1, 0.2, 0.3)  # s


def main() -> int:
    """Print the largest speed gains found."""
    model = FULL_REFERENCE.build(1)
    best = {DT: (0.0, None), **{w: (0.0, None) for w in WINDOWS}}
    rest = FinBeat(math.radians(90), 0.0, 1.0, 1.0)
    grid = itertools.product([math.radians(d) for d in (60, 90, 120)], [0.6, 1.0, 1.3], [0.4, 0.6, 1.0],
                             [0.5, 1, 2, 4], [True, False], [0.0, 0.2])
    for bias, amplitude, period, ratio, both, v0 in grid:
        half = period * min(ratio / (ratio + 1), 1 / (ratio + 1))
        inside = math.radians(10) <= bias - amplitude and bias + amplitude <= math.radians(170)
        if math.pi * amplitude / half > 13 or not inside:
            continue  # beyond the servo limits the firmware enforces
        beat = FinBeat(bias, amplitude, period, ratio)
        model.reset(np.array([1.0, 0.5, 0.0, v0, 0.0, 0.0]), right=beat, left=beat if both else rest)
        speed = np.array([math.hypot(*model.advance(DT)[0][3:5]) for _ in range(int(3.0 / DT))])
        for window in best:
            n = max(1, round(window / DT))
            gain = float(np.max(speed[n:] - speed[:-n]))
            if gain > best[window][0]:
                best[window] = (gain, (beat, "both fins" if both else "right fin", v0))
    for window, (gain, where) in best.items():
        print(f"largest speed gain over {window:.3f} s: {gain:.3f} m/s ({gain / window:.2f} m/s^2 on average); "
              f"{where[0]}, {where[1]}, from {where[2]} m/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
