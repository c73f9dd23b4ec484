"""Periodic steady state and the turning quantities of eq. (29).

:func:`steady_state` runs a batch of fish from rest until their fin-beat-
averaged body velocities stop changing:

* the averaging window ``W`` is a common period of both fins (the fin forcing
  is ``W``-periodic, so at periodic steady state the window averages are
  constant);
* convergence: the change of the window averages ``(vx, vy, omega)`` between
  two consecutive windows is below ``rtol * |average| + atol`` for every
  component, two windows in a row.

The cycle-averaged ``vx, vy, omega`` then give (eq. 29) speed, turning radius
``R = |V| / |omega|``, turning period ``T_b = 2 pi / |omega|`` and drift angle
``alpha = arctan(vy / vx)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from fractions import Fraction

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import FishModel, validate_beats
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.spec import ModelSpec, make_model

__all__ = ["SteadyState", "common_period", "steady_state", "steady_state_batch", "turning_quantities"]

TURN_THRESHOLD = 1e-6  # rad/s: below this |omega| the fish is taken as swimming straight


@dataclass(frozen=True)
class SteadyState:
    """Cycle-averaged periodic steady state of one fish (body frame).

    Attributes:
        vx, vy: Mean surge and sway velocity [m/s].
        omega: Mean yaw rate [rad/s]; > 0 is a left turn.
        speed: ``sqrt(vx^2 + vy^2)`` [m/s].
        radius: Turning radius [m] (eq. 29), ``None`` if the fish does not turn.
        period: Turning period [s] (eq. 29), ``None`` if the fish does not turn.
        drift_angle: ``arctan(vy / vx)`` [rad] (eq. 29).
        converged: Whether the convergence criterion was met.
        time: Simulated time used [s].
    """

    vx: float
    vy: float
    omega: float
    speed: float
    radius: float | None
    period: float | None
    drift_angle: float
    converged: bool
    time: float

    def as_dict(self) -> dict:
        """Plain dict (JSON-ready)."""
        return asdict(self)


def turning_quantities(vx: float, vy: float, omega: float) -> tuple[float, float | None, float | None, float]:
    """``(speed, radius, period, drift_angle)`` from averaged body velocities (eq. 29)."""
    speed = math.hypot(vx, vy)
    drift = math.atan(vy / vx) if vx != 0 else math.copysign(math.pi / 2, vy) if vy != 0 else 0.0
    if abs(omega) < TURN_THRESHOLD:
        return speed, None, None, drift
    return speed, speed / abs(omega), 2.0 * math.pi / abs(omega), drift


def common_period(periods: Sequence[float], max_window: float = 120.0) -> float:
    """Shortest window that is a whole number of every period (within 1e-9), up to ``max_window``.

    Falls back to the longest period times the largest whole number that fits
    ``max_window`` when the periods are not commensurate enough.
    """
    periods = [float(p) for p in periods]
    base = periods[0]
    window = base
    for p in periods[1:]:
        frac = Fraction(window / p).limit_denominator(1000)
        candidate = window * frac.denominator
        if abs(candidate / p - round(candidate / p)) < 1e-9 and candidate <= max_window:
            window = candidate
        else:
            longest = max(periods)
            return longest * max(1, math.floor(max_window / longest))
    return window


def _window(beats: np.ndarray) -> float:
    moving = [b[2] for b in beats if b[1] > 0]
    if not moving:
        return 1.0
    return common_period(moving)


def steady_state_batch(
    model: FishModel,
    beats: np.ndarray,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    max_time: float = 600.0,
    window: float | None = None,
) -> list[SteadyState]:
    """Periodic steady states of ``model.n`` fish driven by ``beats`` ``(n, 2, 4)`` (right fin first).

    Args:
        model: A :class:`FullModel` or :class:`AveragedModel` with ``n`` fish (it is reset).
        beats: Fin patterns per fish, radians and seconds.
        rtol, atol: Convergence tolerances on the window averages (module docstring).
        max_time: Give up (``converged=False``) after this much simulated time [s].
        window: Averaging window [s]; default: a common period of each fish's fins,
            the longest over the batch rounded up to whole windows per fish.
    """
    beats = np.asarray(beats, dtype=np.float64)
    validate_beats(beats)
    n = model.n
    if beats.shape != (n, 2, 4):
        raise ValueError(f"beats must have shape ({n}, 2, 4), got {beats.shape}")
    if window is None:
        # One window for the batch: each fish's own common period times a whole number.
        own = np.array([_window(b) for b in beats])
        window = float(own.max())
        reps = np.maximum(1, np.round(window / own))
        window_per_fish = own * reps
        if not np.allclose(window_per_fish, window_per_fish[0], rtol=1e-9):
            # Different fish need different windows: advance in chunks of each one's own window.
            return [
                steady_state_batch(_single_like(model, i), beats[i : i + 1], rtol, atol, max_time)[0]
                for i in range(n)
            ]
        window = float(window_per_fish[0])
    model.reset(right=beats[:, 0], left=beats[:, 1])
    prev = None
    calm = np.zeros(n, dtype=int)
    done_at = np.full(n, np.nan)
    result = np.zeros((n, 3))
    t = 0.0
    while t < max_time and not np.all(calm >= 2):
        before = model.integral.copy()
        model.advance(window)
        t += window
        avg = (model.integral - before) / window
        if prev is not None:
            ok = np.all(np.abs(avg - prev) <= rtol * np.abs(avg) + atol, axis=1)
            calm = np.where(ok, calm + 1, 0)
            newly = (calm >= 2) & np.isnan(done_at)
            result[newly] = avg[newly]
            done_at[newly] = t
        prev = avg
    pending = np.isnan(done_at)
    result[pending] = prev[pending]
    out = []
    for i in range(n):
        vx, vy, om = (float(v) for v in result[i])
        speed, radius, period, drift = turning_quantities(vx, vy, om)
        out.append(SteadyState(vx, vy, om, speed, radius, period, drift, bool(not pending[i]),
                               float(t if pending[i] else done_at[i])))
    return out


def _single_like(model: FishModel, i: int) -> FishModel:
    """A one-fish copy of ``model``'s configuration with fish ``i``'s parameters."""
    clone = model.__class__.__new__(model.__class__)
    clone.__dict__.update(model.__dict__)
    clone.n = 1
    clone.state = np.zeros((1, 6))
    clone.fins = np.zeros((1,) + model.fins.shape[1:])
    clone.forcing_cache = np.zeros((1,) + model.forcing_cache.shape[1:])
    clone.pending = np.zeros((1, 2, 4))
    clone.integral = np.zeros((1, 3))
    clone.coef = model.coef[i : i + 1].copy()
    return clone


def steady_state(
    model: str | ModelSpec = "full",
    right: FinBeat | None = None,
    left: FinBeat | None = None,
    params: FishParams | None = None,
    scaling: ScalingFunctions | str | None = "spec",
    forcing: str | None = None,
    **kwargs,
) -> SteadyState:
    """Periodic steady state of one fish; an omitted fin is at rest.

    Args:
        model: A model spec (:mod:`pectoral_gym.model.spec`), a preset name, ``"full"`` or ``"averaged"``.
        right, left: Fin patterns (``None``: at rest).
        params: Model parameters.
        scaling, forcing: Replace the averaged spec's K and forcing
            (:func:`pectoral_gym.model.spec.make_model`; the defaults keep the spec's).
        **kwargs: Passed to :func:`steady_state_batch` (tolerances, ``max_time``).

    Example:
        >>> s = steady_state("full", right=FinBeat.from_degrees(90, 20, 1.0, 4))
        >>> s.omega > 0  # the right fin turns the fish left
        True
    """
    fish = make_model(model, 1, params, scaling, forcing)
    rest = FinBeat.rest().as_array()
    beats = np.array([[(right.as_array() if right else rest), (left.as_array() if left else rest)]])
    return steady_state_batch(fish, beats, **kwargs)[0]
