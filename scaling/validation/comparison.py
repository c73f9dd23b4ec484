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
from pectoral_gym.model.kloading import held_yaw_damping
from pectoral_gym.model.models import FishModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import AVERAGED, FULL_REFERENCE, AveragedSpec, ModelSpec, make_model, spec_from_dict
from pectoral_gym.model.steady import common_period, steady_state_batch

__all__ = [
    "REST", "as_run", "fin_pattern", "label", "relative_error", "simulate_xy", "steady_pair", "summarize",
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


def as_run(model: str | ModelSpec, scaling: ScalingFunctions | None) -> ModelSpec:
    """The spec of ``model`` as :func:`~pectoral_gym.model.spec.make_model` builds it with the K ``scaling`` in memory.

    ``model``: a spec, a preset name (:data:`~pectoral_gym.model.spec.PRESETS`), ``"full"``
    (:data:`~pectoral_gym.model.spec.FULL_REFERENCE`) or ``"averaged"`` (:data:`~pectoral_gym.model.spec.AVERAGED`).
    An averaged model runs with the richest yaw damping the K under test holds (the spec names it); the
    full model does not use K. What a report records as the model it ran.
    """
    spec = model if isinstance(model, ModelSpec) else FULL_REFERENCE if model == "full" else \
        AVERAGED if model == "averaged" else spec_from_dict(model)
    return spec.replace(yaw_damping=held_yaw_damping(scaling)) if isinstance(spec, AveragedSpec) else spec


def _steady(model: str | ModelSpec, beats: np.ndarray, params: FishParams, scaling: ScalingFunctions) -> np.ndarray:
    """``(n, 5)`` vx, vy, omega, radius, period (NaN when not turning), one batch per common window."""
    windows = np.array([common_period([b[2] for b in fins if b[1] > 0] or [1.0]) for fins in beats])
    out = np.full((len(beats), 5), np.nan)
    for window in np.unique(np.round(windows, 9)):
        idx = np.flatnonzero(np.abs(windows - window) < 1e-9)
        for i, s in zip(idx, steady_state_batch(make_model(model, idx.size, params, scaling),
                                                     beats[idx]), strict=True):
            out[i] = (s.vx, s.vy, s.omega, np.nan if s.radius is None else s.radius,
                      np.nan if s.period is None else s.period)
    return out


def steady_pair(beats: np.ndarray, scaling: ScalingFunctions, params: FishParams | None = None,
                candidate: str | ModelSpec = "averaged") -> dict[str, Any]:
    """Steady states of the full model and of ``candidate``, and their relative errors, for patterns ``(n, 2, 4)``.

    ``candidate``: the model compared with the full one, as :func:`as_run` names it, built with the K
    ``scaling``; its results are under ``"averaged"`` whichever it is.
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
