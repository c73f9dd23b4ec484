"""Reference runs: the full blade-element model to periodic steady state on every grid pattern (Sec. 4.3).

Only the right fin beats (the left one rests at 90 deg), as in the paper. The
patterns are run in batches that share one averaging window (their fin
period), so each batch is one call into the compiled, multi-threaded model.
From each steady state come the turning radius ``R``, turning period ``T_b``
and drift angle ``alpha`` (eq. 29), and from those the body velocities the
averaged model must track. One more fin period, sampled, gives the in-beat
yaw-rate oscillation that the averaged model's oscillation-averaged yaw
damping needs (:mod:`pectoral_gym.model.averaging`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.steady import steady_state_batch

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
        yaw_oscillation: ``(n,)`` amplitude ``A`` [rad/s] of the sinusoid with the same mean
            absolute value as the steady in-beat yaw-rate oscillation ``omega - mean(omega)``.
        yaw_phase: ``(n,)`` phase ``phi`` [rad] of its fundamental, ``cos(2 pi t / T_p + phi)``
            with ``t`` from the start of the power stroke.
    """

    patterns: np.ndarray
    velocities: np.ndarray
    radius: np.ndarray
    turn_period: np.ndarray
    drift_angle: np.ndarray
    converged: np.ndarray
    sim_time: np.ndarray
    yaw_oscillation: np.ndarray
    yaw_phase: np.ndarray

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


OSCILLATION_SAMPLES = 64  # per fin period: mean |omega~| to ~1e-4 relative (the waveform has kinks)


def yaw_oscillation_statistics(omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude and phase of the yaw-rate oscillation from samples over one fin period.

    Args:
        omega: ``(n, samples)`` yaw rates at ``t_k = (k + 1) T_p / samples`` after the start
            of a power stroke.

    Returns:
        ``(A, phi)``: ``A = (pi / 2) mean|omega - mean(omega)|`` (the amplitude of the sinusoid
        with that mean absolute value) and the phase of the fundamental.
    """
    omega = np.asarray(omega, dtype=np.float64)
    samples = omega.shape[1]
    wiggle = omega - omega.mean(axis=1, keepdims=True)
    theta = 2.0 * np.pi * np.arange(1, samples + 1) / samples
    fundamental = wiggle @ np.exp(-1j * theta)
    return 0.5 * np.pi * np.abs(wiggle).mean(axis=1), np.angle(fundamental)


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
        rtol, atol: Steady-state tolerances (:func:`pectoral_gym.model.steady.steady_state_batch`).
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
    oscillation = np.zeros(n)
    phase = np.zeros(n)
    periods = np.unique(patterns[:, 2])
    bar = tqdm(total=n, desc="reference runs (full model)", unit="pattern", disable=not progress)
    for period in periods:
        index = np.flatnonzero(patterns[:, 2] == period)
        beats = np.empty((len(index), 2, 4))
        beats[:, 0] = patterns[index]
        beats[:, 1] = rest
        model = FullModel(len(index), params)
        states = steady_state_batch(model, beats, rtol=rtol, atol=atol, max_time=max_time, window=float(period))
        # the batch ends at a cycle boundary, in steady state: sample one more period
        omega = np.empty((len(index), OSCILLATION_SAMPLES))
        for k in range(OSCILLATION_SAMPLES):
            model.advance(float(period) / OSCILLATION_SAMPLES)
            omega[:, k] = model.state[:, 5]
        oscillation[index], phase[index] = yaw_oscillation_statistics(omega)
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
    return ReferenceRuns(patterns, velocities, radius, turn_period, drift, converged, sim_time, oscillation, phase)
