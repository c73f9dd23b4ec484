"""The scaling-coefficients file: its format, and the parsing and checking of its spline sections.

Read by :class:`pectoral_gym.model.kfunctions.ScalingFunctions` (``load``, ``save``).

File format (JSON, ``format = "pectoral-gym-scaling/3"``)::

    {
      "format": "pectoral-gym-scaling/3",
      "sway": "base",
      "features": ["bias", "amplitude", "period", "ratio", "inv_period", "inv_ratio"],
      "units": {"bias": "rad", "amplitude": "rad", "period": "s", "ratio": "-", "inv_period": "1/s", "inv_ratio": "-"},
      "functions": {
        "K_fx": [{"coef": 1.0, "powers": [0, 0, 0, 0, 0, 0]}, ...],
        "K_fy": [...],
        "K_m":  [...]
      },
      "spline": {
        "degree": 3,
        "axes": ["bias", "amplitude", "inv_ratio"],
        "knots": [[...], [...], [...]],
        "coefficients": {"K_fx": [...], "K_fy": [...], "K_m": [...]},
        "extrapolation": "clamp"
      },
      "yaw_oscillation": {
        "degree": 3,
        "axes": ["bias", "amplitude", "inv_ratio"],
        "knots": [[...], [...], [...]],
        "cos": [...], "sin": [...],
        "extrapolation": "clamp"
      },
      "metadata": {...}
    }

Each K is the sum of two optional parts:

* a polynomial: monomials ``coef * prod(feature_i ** powers_i)``;
* a tensor-product cubic B-spline over ``(bias, amplitude, 1/ratio)`` with the
  given knot vectors (``n_i + 4`` knots for ``n_i`` coefficients per axis) and
  coefficients in C order, shape ``(n_bias, n_amplitude, n_inv_ratio)``; inputs
  outside the knot range are clamped to it (the spline is only identified
  there, and a cubic extrapolates badly).

``sway`` fixes what ``K_fy`` multiplies:

* ``"paper"``: the averaged sway force ``f_hy_avg = base cos(bias)`` (eq. 25 as
  printed);
* ``"base"``: ``base = f_hx_avg / sin(bias)``, the averaged force magnitude.
  ``K_fy`` then equals the paper's ``K_fy cos(bias)``: the effective sway
  force per unit fin force. It stays finite at 90 deg bias, where the paper's
  ``K_fy`` diverges (the blade-element model has a mean sway force there, the
  plain average has none), so it can be identified through 90 deg.

The optional ``yaw_oscillation`` section describes the yaw-rate oscillation a
fin drives within its beat, which the averaged model needs for its
oscillation-averaged yaw damping (``pectoral_gym.model.dynamics.body_accel``, beyond the
paper). ``cos, sin`` are the two components of the phasor
``A T_p (cos phi, sin phi)`` [rad] as cubic splines over the same three axes
(their own knots): ``A`` [rad/s] is the amplitude of the sinusoid with the
oscillation's mean absolute value, ``phi`` the phase of its fundamental,
``omega~(t) ~ A cos(2 pi t / T_p + phi)`` with ``t`` from the start of the power
stroke. ``A T_p`` is exactly period-free (the full model is invariant under
``t -> t / T_p``). Below the lowest amplitude node (if that is above zero) the
phasor shrinks linearly to zero at zero amplitude. Without the section the averaged model uses the
paper's damping ``c4 omega|omega|``.

A ``yaw_waveform`` section (the in-beat waveform's Fourier harmonics) belongs to an experiment that left
the package (``docs/model.md`` 3.6; its code is kept at the git tag :data:`WAVEFORM_TAG`): a file that has
one is refused, so that no file silently runs with another damping than it was identified for.

Format 1 and 2 files (format 1: polynomial only, ``sway`` implicitly
``"paper"``; five or six features) load unchanged. ``save`` always writes
format 3.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SPLINE_AXES", "SPLINE_DEGREE", "WAVEFORM_TAG", "check_knots", "checked_spline", "padded",
           "spline_dict", "spline_section"]

SPLINE_AXES = ("bias", "amplitude", "inv_ratio")
SPLINE_DEGREE = 3
#: The git tag that keeps the yaw-waveform experiment (its damping, coefficients file and reports).
WAVEFORM_TAG = "experiment/waveform"


def padded(knots: tuple[np.ndarray, ...], table: np.ndarray | None, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """Knot vectors as one ``(3, longest)`` array (padded with their last knot) and the contiguous table."""
    if table is None:
        return np.zeros((3, 1)), np.zeros((channels, 0, 0, 0))
    longest = max(len(k) for k in knots)
    return np.array([np.pad(k, (0, longest - len(k)), mode="edge") for k in knots]), np.ascontiguousarray(table)


def checked_spline(
    knots: tuple, table: np.ndarray | None, channels: int, what: str
) -> tuple[tuple[np.ndarray, ...], np.ndarray | None]:
    """Validated float copies of a spline's three knot vectors and ``(channels, n0, n1, n2)`` table."""
    if (table is None) != (len(knots) == 0):
        raise ValueError(f"a {what} needs both knots and a table")
    if table is None:
        return (), None
    table = np.asarray(table, dtype=np.float64)
    if table.ndim != 4 or table.shape[0] != channels or len(knots) != 3:
        raise ValueError(f"{what} table must be ({channels}, n_bias, n_amplitude, n_inv_ratio) with 3 knot vectors, "
                         f"got {table.shape} and {len(knots)} knot vectors")
    if not np.all(np.isfinite(table)):
        raise ValueError(f"{what} coefficients must be finite")
    knots = tuple(np.asarray(k, dtype=np.float64) for k in knots)
    for axis, (k, n) in enumerate(zip(knots, table.shape[1:], strict=True)):
        check_knots(k, n, f"{what} axis {SPLINE_AXES[axis]}")
    return knots, table


def spline_dict(knots: tuple[np.ndarray, ...], data: dict[str, Any]) -> dict[str, Any]:
    """A spline section of the file: degree, axes, knots, then ``data``, then the extrapolation rule."""
    return {"degree": SPLINE_DEGREE, "axes": list(SPLINE_AXES), "knots": [k.tolist() for k in knots], **data,
            "extrapolation": "clamp"}


def spline_section(
    section: Any, source: str, key: str, channels
) -> tuple[tuple[np.ndarray, ...], np.ndarray | None]:
    """Knots and table of the spline section ``key`` of a coefficients file; ``channels(section)`` lists its data."""
    if section is None:
        return (), None
    if not isinstance(section, dict):
        raise ValueError(f"{source}: '{key}' must be an object")
    if section.get("degree") != SPLINE_DEGREE or tuple(section.get("axes", ())) != SPLINE_AXES:
        raise ValueError(f"{source}: {key} must have degree {SPLINE_DEGREE} and axes {list(SPLINE_AXES)}")
    if section.get("extrapolation", "clamp") != "clamp":
        raise ValueError(f"{source}: {key} extrapolation must be 'clamp'")
    try:
        knots = tuple(np.asarray(k, dtype=np.float64) for k in section["knots"])
        if len(knots) != 3:
            raise ValueError("3 knot vectors required")
        shape = tuple(len(k) - 4 for k in knots)
        table = np.array([np.asarray(values, dtype=np.float64).reshape(shape) for values in channels(section)])
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{source}: malformed {key}: {err}") from None
    return knots, table


def check_knots(knots: np.ndarray, n: int, where: str) -> None:
    """Raise ``ValueError`` unless ``knots`` are the ``n + 4`` finite, sorted knots of an ``n``-coefficient cubic."""
    if n < 4:
        raise ValueError(f"{where}: a cubic spline needs at least 4 coefficients per axis, got {n}")
    if knots.shape != (n + 4,) or not np.all(np.isfinite(knots)):
        raise ValueError(f"{where}: {n + 4} finite knots required for {n} coefficients, got {knots.shape[0]}")
    if np.any(np.diff(knots) < 0) or not knots[3] < knots[n]:
        raise ValueError(f"{where}: knots must be non-decreasing and span a non-empty interval")
