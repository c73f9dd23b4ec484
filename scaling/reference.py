"""Reference runs: the full blade-element model to periodic steady state on every grid pattern (Sec. 4.3).

Only the right fin beats (the left one rests at 90 deg), as in the paper. The
patterns are run in batches that share one averaging window (their fin
period), so each batch is one call into the compiled, multi-threaded model.
From each steady state come the turning radius ``R``, turning period ``T_b``
and drift angle ``alpha`` (eq. 29), and from those the body velocities the
averaged model must track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from pectoral_gym.models import FullModel
from pectoral_gym.params import FinBeat, FishParams
from pectoral_gym.steady import steady_state_batch

__all__ = ["ReferenceRuns", "reference_runs", "velocities_from_turning"]


@dataclass(frozen=True)
class ReferenceRuns:
    """Steady states of the full model, one row per pattern.

    Attributes:
        patterns: ``(n, 4)`` right-fin patterns (rad, rad, s, -).
        velocities: ``(n, 3)`` cycle-averaged ``(vx, vy, omega)`` targets from eq. (29).
        radius: ``(n,)`` turning radius [m] (NaN if the fish does not turn).
        turn_period: ``(n,)`` turning period ``T_b`` [s] (NaN if the fish does not turn).
        drift_angle: ``(n,)`` ``alpha`` [rad].
        converged: ``(n,)`` whether the steady state converged.
        sim_time: ``(n,)`` simulated time to convergence [s].
    """

    patterns: np.ndarray
    velocities: np.ndarray
    radius: np.ndarray
    turn_period: np.ndarray
    drift_angle: np.ndarray
    converged: np.ndarray
    sim_time: np.ndarray

    def __len__(self) -> int:
        return len(self.patterns)


def velocities_from_turning(
    radius: float, turn_period: float, drift_angle: float, turn_sign: float, backward: bool = False
) -> np.ndarray:
    """Body velocities ``(vx, vy, omega)`` from eq. (29): ``omega = 2 pi / T_b``, ``|V| = R omega``.

    Args:
        radius: Turning radius ``R`` [m].
        turn_period: Turning period ``T_b`` [s].
        drift_angle: ``alpha = arctan(vy / vx)`` [rad].
        turn_sign: +1 for a left (counter-clockwise) turn, -1 for a right turn.
        backward: ``vx < 0`` (``arctan`` loses the quadrant; eq. 29 assumes forward swimming).
    """
    omega = 2.0 * math.pi / turn_period
    speed = radius * omega * (-1.0 if backward else 1.0)
    return np.array([speed * math.cos(drift_angle), speed * math.sin(drift_angle), turn_sign * omega])


def reference_runs(
    patterns: np.ndarray,
    params: FishParams | None = None,
    rtol: float = 1e-7,
    atol: float = 1e-10,
    max_time: float = 900.0,
    progress: bool = True,
) -> ReferenceRuns:
    """Run the full model to periodic steady state for every right-fin pattern.

    Args:
        patterns: ``(n, 4)`` right-fin patterns.
        params: Model parameters (Table 1 defaults if ``None``).
        rtol, atol: Steady-state tolerances (:func:`pectoral_gym.steady.steady_state_batch`).
        max_time: Simulated-time limit per batch [s].
        progress: Show a progress bar over the batches.
    """
    params = params or FishParams()
    patterns = np.asarray(patterns, dtype=np.float64)
    n = len(patterns)
    rest = FinBeat.rest().as_array()
    velocities = np.full((n, 3), np.nan)
    radius = np.full(n, np.nan)
    turn_period = np.full(n, np.nan)
    drift = np.full(n, np.nan)
    converged = np.zeros(n, dtype=bool)
    sim_time = np.zeros(n)
    periods = np.unique(patterns[:, 2])
    bar = tqdm(total=n, desc="reference runs (full model)", unit="pattern", disable=not progress)
    for period in periods:
        index = np.flatnonzero(patterns[:, 2] == period)
        beats = np.empty((len(index), 2, 4))
        beats[:, 0] = patterns[index]
        beats[:, 1] = rest
        model = FullModel(len(index), params)
        states = steady_state_batch(model, beats, rtol=rtol, atol=atol, max_time=max_time, window=float(period))
        for i, s in zip(index, states, strict=True):
            converged[i] = s.converged
            sim_time[i] = s.time
            drift[i] = s.drift_angle
            if s.radius is not None:
                radius[i], turn_period[i] = s.radius, s.period
                velocities[i] = velocities_from_turning(
                    s.radius, s.period, s.drift_angle, math.copysign(1.0, s.omega), s.vx < 0
                )
            else:
                velocities[i] = (s.vx, s.vy, s.omega)
        bar.update(len(index))
    bar.close()
    return ReferenceRuns(patterns, velocities, radius, turn_period, drift, converged, sim_time)
