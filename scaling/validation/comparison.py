"""Averaged against full model on the same fin patterns: steady states, relative errors, paths.

The building blocks of :mod:`pectoral_gym.scaling.validation.validate`: both models' cycle-averaged
periodic steady states (eq. 29) for batches of two-fin patterns, the relative
errors between them, and trajectories from rest.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import FishModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import AVERAGED, FULL_FAST, FULL_REFERENCE, ModelSpec, make_model
from pectoral_gym.model.steady import common_period, steady_state_batch

__all__ = [
    "REST", "candidate_spec", "fin_pattern", "label", "relative_error", "simulate_xy", "steady_pair", "summarize",
]


def relative_error(approx, exact) -> np.ndarray:
    """``|approx - exact| / |exact|`` elementwise; NaN where either is NaN or ``exact`` is 0."""
    approx = np.asarray(approx, dtype=np.float64)
    exact = np.asarray(exact, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.abs(approx - exact) / np.abs(exact)
    return np.where(exact == 0, np.nan, err)


def summarize(errors, labels) -> dict[str, Any]:
    """Median, 90th percentile and worst of ``errors`` (NaNs skipped), naming the worst label."""
    errors = np.asarray(errors, dtype=np.float64)
    ok = np.isfinite(errors)
    if not np.any(ok):
        return {"n": 0, "median": None, "p90": None, "worst": None, "worst_pattern": None}
    idx = np.flatnonzero(ok)
    worst = idx[int(np.argmax(errors[idx]))]
    return {
        "n": int(idx.size),
        "median": float(np.median(errors[idx])),
        "p90": float(np.percentile(errors[idx], 90)),
        "worst": float(errors[worst]),
        "worst_pattern": labels[worst],
    }


def label(beats: np.ndarray) -> str:
    """``"R(90, 22, 1, 4) L(rest)"``: both fins of one fish in the paper's units."""
    parts = []
    for side, beat in zip("RL", beats, strict=True):
        if beat[1] == 0:
            parts.append(f"{side}(rest)")
        else:
            parts.append(f"{side}({math.degrees(beat[0]):.4g}, {math.degrees(beat[1]):.4g}, "
                         f"{beat[2]:.4g}, {beat[3]:.4g})")
    return " ".join(parts)


def fin_pattern(g0_deg: float, ga_deg: float, period: float, ratio: float) -> np.ndarray:
    """One fin's ``(bias, amplitude, period, ratio)`` from the paper's units (deg, deg, s, -)."""
    return np.array([math.radians(g0_deg), math.radians(ga_deg), period, ratio])


REST = fin_pattern(90.0, 0.0, 1.0, 1.0)


#: Models compared against the full model's reference integration: the averaged model
#: (:data:`pectoral_gym.model.spec.AVERAGED`), or the full model's fast integration preset
#: (:data:`pectoral_gym.model.spec.FULL_FAST`).
CANDIDATES = ("averaged", "full-fast")


def candidate_spec(kind: str, transitions: bool = True, ripple_offsets: bool = True) -> ModelSpec:
    """The spec of ``"full"`` (the reference) or a candidate of :data:`CANDIDATES`.

    ``transitions``, ``ripple_offsets``: the averaged model's options. Build it with
    ``pectoral_gym.model.spec.make_model(spec, n, params, scaling)``: the K under test, in memory.
    """
    if kind == "full":
        return FULL_REFERENCE
    if kind == "full-fast":
        return FULL_FAST
    if kind != "averaged":
        raise ValueError(f"model must be 'full' or one of {CANDIDATES}, got {kind!r}")
    return AVERAGED.replace(transitions=transitions, ripple_offsets=ripple_offsets)


def _steady(kind: str, beats: np.ndarray, params: FishParams, scaling: ScalingFunctions) -> np.ndarray:
    """``(n, 5)`` vx, vy, omega, radius, period (NaN when not turning), one batch per common window."""
    windows = np.array([common_period([b[2] for b in fins if b[1] > 0] or [1.0]) for fins in beats])
    out = np.full((len(beats), 5), np.nan)
    for window in np.unique(np.round(windows, 9)):
        idx = np.flatnonzero(np.abs(windows - window) < 1e-9)
        for i, s in zip(idx, steady_state_batch(make_model(candidate_spec(kind), idx.size, params, scaling),
                                                     beats[idx]), strict=True):
            out[i] = (s.vx, s.vy, s.omega, np.nan if s.radius is None else s.radius,
                      np.nan if s.period is None else s.period)
    return out


def steady_pair(beats: np.ndarray, scaling: ScalingFunctions, params: FishParams | None = None,
                candidate: str = "averaged") -> dict[str, Any]:
    """Steady states of both models and their relative errors for fish patterns ``(n, 2, 4)``.

    ``candidate`` (:data:`CANDIDATES`) is the model compared with the full one; its results
    are under ``"averaged"`` whichever it is.
    """
    params = params or FishParams()
    full = _steady("full", beats, params, scaling)
    avg = _steady(candidate, beats, params, scaling)
    speed_full, speed_avg = np.hypot(full[:, 0], full[:, 1]), np.hypot(avg[:, 0], avg[:, 1])
    return {
        "full": {"vx": full[:, 0], "vy": full[:, 1], "omega": full[:, 2], "speed": speed_full,
                 "radius": full[:, 3], "period": full[:, 4]},
        "averaged": {"vx": avg[:, 0], "vy": avg[:, 1], "omega": avg[:, 2], "speed": speed_avg,
                     "radius": avg[:, 3], "period": avg[:, 4]},
        # The turning radius has no sign: a fish circling the other way would score well on it alone.
        "direction_flip": (np.sign(avg[:, 2]) != np.sign(full[:, 2])) & (np.abs(full[:, 2]) > 1e-9),
        "radius_error": relative_error(avg[:, 3], full[:, 3]),
        "period_error": relative_error(avg[:, 4], full[:, 4]),
        "speed_error": relative_error(speed_avg, speed_full),
    }


def simulate_xy(model: FishModel, beats: np.ndarray, duration: float, step: float = 0.5) -> np.ndarray:
    """Positions ``(n, k + 1, 2)`` every ``step`` seconds from rest at the origin, all fish in one batch."""
    model.reset(right=beats[:, 0], left=beats[:, 1])
    steps = max(1, round(duration / step))
    path = [model.state[:, :2].copy()]
    for _ in range(steps):
        path.append(model.advance(duration / steps)[:, :2].copy())
    return np.stack(path, axis=1)
