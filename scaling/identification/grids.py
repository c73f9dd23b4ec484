"""Grids of right-fin beat patterns on which the scaling functions are identified (paper, Sec. 4.3).

A grid is the Cartesian product of values of the four fin-beat parameters
``(bias, amplitude, period, ratio)`` (radians and seconds inside; degrees in
files and on the command line), or an explicit list of patterns.

Presets:

* ``paper``: the paper's 560 patterns (amplitudes 10-30 deg, biases 50-90 deg,
  periods 0.5, 0.66, 1, 2 s, ratios 2-5).
* ``quick``: 12 patterns (biases 60, 75, 90 deg; amplitudes 15, 25 deg; period
  1 s; ratios 2, 4) for smoke runs (``python -m pectoral_gym.scaling identify --quick``);
  the K it gives is not meant for use.
* ``env``: covers the environments' whole default action ranges (bias 45-135
  deg, amplitude 0-30 deg, period 0.5-2 s, ratio 1-5), so the averaged
  environment never extrapolates, and the periods of the paper's forward
  swimming sweep (Fig. 4). K does not depend on the period (the model is
  invariant under a change of time scale, see docs/scaling.md), so three
  periods suffice; amplitudes are denser where K changes fastest. The
  biases and amplitudes avoid those of the paper's Table 4 (60, 80, 90 deg;
  20, 22 deg), which the validation uses as held-out patterns. Patterns
  with no forcing (ratio 1, amplitude 0) are not identifiable and are left
  out; their forcing is zero whatever K is.

Grid file (JSON), either axes whose product is taken::

    {"bias_deg": [50, 70, 90], "amplitude_deg": [10, 20], "period_s": [1.0], "ratio": [2, 4]}

or explicit patterns ``[bias_deg, amplitude_deg, period_s, ratio]``::

    {"patterns": [[90, 22, 1.0, 4], [60, 20, 1.0, 3]]}
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["GRIDS", "Grid", "GridError", "draw_off_grid", "load_grid"]

_AXES = ("bias_deg", "amplitude_deg", "period_s", "ratio")


class GridError(ValueError):
    """A grid file or grid specification is invalid."""


@dataclass(frozen=True)
class Grid:
    """A set of right-fin beat patterns.

    Attributes:
        name: Preset name or file path.
        patterns: ``(n, 4)`` array of ``(bias [rad], amplitude [rad], period [s], ratio [-])``.
    """

    name: str
    patterns: np.ndarray

    @classmethod
    def product(cls, name: str, bias_deg, amplitude_deg, period_s, ratio) -> Grid:
        """Cartesian product of axis values given in degrees and seconds."""
        rows = [
            (math.radians(b), math.radians(a), float(t), float(z))
            for b, a, t, z in itertools.product(bias_deg, amplitude_deg, period_s, ratio)
        ]
        return cls.from_patterns(name, np.array(rows, dtype=np.float64).reshape(-1, 4))

    @classmethod
    def from_patterns(cls, name: str, patterns: np.ndarray) -> Grid:
        """A grid from an ``(n, 4)`` array in radians and seconds, validated."""
        patterns = np.asarray(patterns, dtype=np.float64)
        if patterns.ndim != 2 or patterns.shape[1] != 4 or len(patterns) == 0:
            raise GridError(f"grid {name!r}: patterns must be a non-empty (n, 4) array, got shape {patterns.shape}")
        if not np.all(np.isfinite(patterns)):
            raise GridError(f"grid {name!r}: patterns must be finite")
        bias, amp, period, ratio = patterns.T
        bad = (amp < 0) | (period <= 0) | (ratio <= 0) | (bias - amp < 0) | (bias + amp > math.pi)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise GridError(
                f"grid {name!r}: pattern {i} (bias {math.degrees(bias[i]):.4g} deg, amplitude "
                f"{math.degrees(amp[i]):.4g} deg, period {period[i]:.4g} s, ratio {ratio[i]:.4g}) is invalid: "
                "needs amplitude >= 0, period > 0, ratio > 0 and 0 <= bias -+ amplitude <= 180 deg"
            )
        patterns = patterns.copy()
        patterns.setflags(write=False)
        return cls(name, patterns)

    def __len__(self) -> int:
        return len(self.patterns)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-parameter ``(low, high)`` over the grid, each ``(4,)``."""
        return self.patterns.min(axis=0), self.patterns.max(axis=0)

    def contains(self, pattern, tol: float = 1e-9) -> bool:
        """Whether ``pattern`` (4,) equals a grid pattern within ``tol`` in every parameter."""
        diff = np.abs(self.patterns - np.asarray(pattern, dtype=np.float64)[None, :])
        return bool(np.any(np.all(diff <= tol, axis=1)))

    def to_dict(self) -> dict:
        """JSON-ready description (degrees), for the coefficients file's metadata."""
        deg = self.patterns.copy()
        deg[:, :2] = np.degrees(deg[:, :2])
        axes = {}
        for key, column in zip(_AXES, deg.T, strict=True):
            axes[key] = sorted({round(float(v), 9) for v in column})
        product = math.prod(len(v) for v in axes.values()) == len(self)
        return {"name": self.name, "size": len(self), **(axes if product else {"patterns": deg.round(9).tolist()})}


def _from_dict(name: str, data) -> Grid:
    if not isinstance(data, dict):
        raise GridError(f"grid {name!r}: expected a JSON object, got {type(data).__name__}")
    if "patterns" in data:
        try:
            deg = np.array(data["patterns"], dtype=np.float64)
        except (TypeError, ValueError):
            msg = f"grid {name!r}: 'patterns' must be a list of [bias_deg, amplitude_deg, period_s, ratio]"
            raise GridError(msg) from None
        if deg.ndim != 2 or deg.shape[1] != 4:
            raise GridError(f"grid {name!r}: 'patterns' must be a list of 4-number lists, got shape {deg.shape}")
        rad = deg.copy()
        rad[:, :2] = np.radians(deg[:, :2])
        return Grid.from_patterns(name, rad)
    missing = [k for k in _AXES if k not in data]
    if missing:
        raise GridError(f"grid {name!r}: missing keys {missing}; give all of {list(_AXES)} or 'patterns'")
    axes = []
    for key in _AXES:
        values = data[key]
        if not isinstance(values, list) or not values or not all(isinstance(v, (int, float)) for v in values):
            raise GridError(f"grid {name!r}: {key!r} must be a non-empty list of numbers, got {values!r}")
        axes.append(values)
    return Grid.product(name, *axes)


def load_grid(spec: str | Path) -> Grid:
    """A preset by name (:data:`GRIDS`) or a grid JSON file (module docstring).

    Raises:
        GridError: Unknown preset, unreadable file, or invalid content.
    """
    if isinstance(spec, str) and spec in GRIDS:
        return GRIDS[spec]
    path = Path(spec)
    if not path.is_file():
        raise GridError(f"unknown grid {str(spec)!r}: not a preset ({', '.join(GRIDS)}) and not a file")
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise GridError(f"cannot read grid file {str(path)!r}: {err}") from None
    return _from_dict(str(path), data)


GRIDS: dict[str, Grid] = {
    "paper": Grid.product(
        "paper",
        bias_deg=(50, 60, 70, 80, 90),
        amplitude_deg=(10, 15, 20, 22, 25, 28, 30),
        period_s=(0.5, 0.66, 1.0, 2.0),
        ratio=(2, 3, 4, 5),
    ),
    "env": Grid.product(
        "env",
        bias_deg=(45, 55, 65, 75, 85, 95, 105, 115, 125, 135),
        amplitude_deg=(2.5, 5, 7.5, 10, 12.5, 15, 17.5, 21, 24, 27, 30),
        period_s=(0.36, 1.0, 4.0),
        ratio=(1.25, 1.5, 2, 3, 4, 5),
    ),
    "quick": Grid.product("quick", bias_deg=(60, 75, 90), amplitude_deg=(15, 25), period_s=(1.0,), ratio=(2, 4)),
}


def draw_off_grid(rng: np.random.Generator, n: int, low: np.ndarray, high: np.ndarray, grid: Grid | None,
                  periods=None) -> np.ndarray:
    """``n`` patterns uniform in the box ``[low, high]``, off ``grid``'s nodes, stroke inside [0, pi].

    With ``periods``, the period is drawn from those of them inside the box instead.
    """
    out = []
    allowed = [p for p in periods if low[2] <= p <= high[2]] if periods is not None else []
    while len(out) < n:
        beat = rng.uniform(low, high)
        if allowed:
            beat[2] = allowed[int(rng.integers(len(allowed)))]
        on_grid = grid is not None and grid.contains(beat, tol=1e-6)
        if not on_grid and beat[0] - beat[1] >= 0 and beat[0] + beat[1] <= math.pi:
            out.append(beat)
    return np.array(out).reshape(n, 4)
