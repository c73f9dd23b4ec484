"""Prediction of the NMPC's moving target (task ``track``) over the horizon, from its observed path.

The observation gives the target's position and velocity now. :class:`ReferencePredictor` keeps the
positions seen so far in the episode and predicts the target's positions and velocities at the ends of
the horizon's intervals (``(2, horizon)`` each):

* ``"line"``: straight on with the current velocity (``ref + vref t``), the NMPC's prediction before;
* ``"arc"``: on a circular arc, the velocity turning at the rate observed over the last control period;
* ``"conic"``: along the conic section (an ellipse) fitted by least squares to the positions seen so far
  (the task moves its reference on an ellipse: docs/benchmark.md, ``track``), at the current speed;
  while too few or too unevenly spread points are known for a good fit (the start of an episode), or
  when the fit is no ellipse or misses the points, the ``"arc"`` prediction.

Everything here uses observed target positions and velocities only (nothing of the env's internals).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ReferencePredictor", "reference_path", "fit_ellipse", "PREDICTIONS"]

PREDICTIONS = ("line", "arc", "conic")


def reference_path(ref: np.ndarray, vref: np.ndarray, turn: float, dt: float, horizon: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The target's positions and velocities ``(2, horizon)`` at the interval ends, on a circular arc.

    It moves at its current speed with its velocity turning at the constant rate ``turn`` [rad/s]
    (``turn = 0``: a straight line, ``ref + vref t``, which a goal's ``vref = 0`` holds in place).
    """
    ref, vref = np.asarray(ref, dtype=np.float64).ravel(), np.asarray(vref, dtype=np.float64).ravel()
    t = dt * np.arange(1, int(horizon) + 1)
    normal = np.array([-vref[1], vref[0]])  # vref turned 90 deg to the left
    if abs(turn) > 1e-9:
        along, across = np.sin(turn * t) / turn, (1.0 - np.cos(turn * t)) / turn
    else:
        along, across = t, np.zeros_like(t)
    positions = ref[:, None] + vref[:, None] * along + normal[:, None] * across
    velocities = vref[:, None] * np.cos(turn * t) + normal[:, None] * np.sin(turn * t)
    return positions, velocities


def fit_ellipse(points: np.ndarray) -> np.ndarray | None:
    """Least-squares conic ``A x^2 + B x y + C y^2 + D x + E y + F = 0`` through ``points (n, 2)``.

    Returns the coefficients ``(A, B, C, D, E, F)`` (unit norm, the smallest singular vector of the
    design matrix of the points centred and scaled), or ``None`` when the conic is no ellipse
    (``B^2 - 4 A C >= 0``, up to rounding) or the points are too few (< 6).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[0] < 6:
        return None
    centre = pts.mean(axis=0)
    scale = float(np.max(np.abs(pts - centre))) or 1.0
    x, y = ((pts - centre) / scale).T
    design = np.column_stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    _, _, vt = np.linalg.svd(design, full_matrices=False)
    a, b, c, d, e, f = vt[-1]
    if not 4.0 * a * c - b * b > 1e-6 * (a * a + b * b + c * c):  # a parabola, hyperbola or pair of lines
        return None
    # back to tank coordinates: substitute x -> (x - cx) / s, y -> (y - cy) / s
    cx, cy, s = float(centre[0]), float(centre[1]), scale
    A, B, C = a / s**2, b / s**2, c / s**2
    D = d / s - 2 * a * cx / s**2 - b * cy / s**2
    E = e / s - 2 * c * cy / s**2 - b * cx / s**2
    F = f + a * cx**2 / s**2 + b * cx * cy / s**2 + c * cy**2 / s**2 - d * cx / s - e * cy / s
    coef = np.array([A, B, C, D, E, F])
    return coef / np.linalg.norm(coef)


def _distances(coef: np.ndarray, points: np.ndarray) -> np.ndarray:
    """First-order distances [m] of ``points (n, 2)`` from the conic (``|value| / |gradient|``)."""
    A, B, C, D, E, F = coef
    x, y = points[:, 0], points[:, 1]
    value = A * x * x + B * x * y + C * y * y + D * x + E * y + F
    gradient = np.hypot(2 * A * x + B * y + D, B * x + 2 * C * y + E)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(gradient > 0, np.abs(value) / gradient, np.inf)


def _along_conic(coef: np.ndarray, start: np.ndarray, velocity: np.ndarray, dt: float, horizon: int,
                 substeps: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities ``(2, horizon)``: from ``start`` along the conic at the speed of ``velocity``.

    The direction of travel is the tangent that agrees with ``velocity``; each substep moves along the
    tangent (midpoint rule), then back onto the conic along its gradient (one Newton step).
    """
    A, B, C, D, E, F = (float(v) for v in coef)
    speed = math.hypot(float(velocity[0]), float(velocity[1]))
    hx, hy = float(velocity[0]) / speed, float(velocity[1]) / speed
    x, y = float(start[0]), float(start[1])
    step = speed * dt / substeps

    def tangent(x: float, y: float, hx: float, hy: float) -> tuple[float, float]:
        gx, gy = 2 * A * x + B * y + D, B * x + 2 * C * y + E
        norm = math.hypot(gx, gy)
        tx, ty = -gy / norm, gx / norm
        return (tx, ty) if tx * hx + ty * hy >= 0 else (-tx, -ty)

    positions, velocities = np.empty((2, horizon)), np.empty((2, horizon))
    for k in range(horizon):
        for _ in range(substeps):
            tx, ty = tangent(x, y, hx, hy)
            mx, my = tangent(x + 0.5 * step * tx, y + 0.5 * step * ty, tx, ty)
            x, y = x + step * mx, y + step * my
            gx, gy = 2 * A * x + B * y + D, B * x + 2 * C * y + E
            value = A * x * x + B * x * y + C * y * y + D * x + E * y + F
            x, y = x - value * gx / (gx * gx + gy * gy), y - value * gy / (gx * gx + gy * gy)
            hx, hy = mx, my
        hx, hy = tangent(x, y, hx, hy)
        positions[:, k] = x, y
        velocities[:, k] = speed * hx, speed * hy
    return positions, velocities


class ReferencePredictor:
    """The moving target's positions and velocities over the horizon (module docstring).

    Args:
        dt: Control period [s].
        horizon: Number of control intervals predicted.
        mode: ``"line"``, ``"arc"`` or ``"conic"``.
        min_turn: ``"conic"``: the points seen must span at least this turn of the target's velocity
            [rad] before the fit is used.
        tolerance: ``"conic"``: largest distance [m] of a seen point from the fitted conic.
        history: Positions kept (the latest ones).
    """

    def __init__(self, dt: float, horizon: int, mode: str = "conic", min_turn: float = 1.0,
                 tolerance: float = 0.002, history: int = 240):
        if mode not in PREDICTIONS:
            raise ValueError(f"mode must be one of {PREDICTIONS}, got {mode!r}")
        self.dt, self.horizon, self.mode = float(dt), int(horizon), mode
        self.min_turn, self.tolerance, self.history = float(min_turn), float(tolerance), int(history)
        self.reset()

    def reset(self) -> None:
        """Forget the target's path (a new episode)."""
        self.points: list[np.ndarray] = []
        self.turned = 0.0  # total turn of the target's velocity over the points kept [rad]
        self.turn = 0.0  # the turning rate over the last control period [rad/s]
        self.coef: np.ndarray | None = None  # the conic used by the last prediction, if any
        self._velocity: np.ndarray | None = None

    def observe(self, ref: np.ndarray, vref: np.ndarray) -> None:
        """Record the target's position and velocity of this control step."""
        ref, vref = np.asarray(ref, dtype=np.float64).ravel(), np.asarray(vref, dtype=np.float64).ravel()
        self.turn = 0.0
        before = self._velocity
        if before is not None and min(float(np.hypot(*before)), float(np.hypot(*vref))) > 1e-6:
            angle = math.atan2(before[0] * vref[1] - before[1] * vref[0], float(before @ vref))
            self.turn = float(np.clip(angle, -1.0, 1.0)) / self.dt
            self.turned += abs(angle)
        self._velocity = vref
        if np.all(np.isfinite(ref)):
            self.points.append(ref)
            del self.points[: -self.history]

    def predict(self, ref: np.ndarray, vref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities ``(2, horizon)`` of the target at the interval ends (from ``ref``, ``vref`` now)."""
        ref, vref = np.asarray(ref, dtype=np.float64).ravel(), np.asarray(vref, dtype=np.float64).ravel()
        self.coef = None
        if self.mode == "line" or float(np.hypot(*vref)) < 1e-6:
            return reference_path(ref, vref, 0.0, self.dt, self.horizon)
        if self.mode == "conic" and self.turned >= self.min_turn:
            points = np.array(self.points)
            coef = fit_ellipse(points)
            if coef is not None and float(_distances(coef, points).max()) <= self.tolerance:
                self.coef = coef
                return _along_conic(coef, ref, vref, self.dt, self.horizon)
        return reference_path(ref, vref, self.turn, self.dt, self.horizon)
