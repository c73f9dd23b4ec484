"""High-gain observer: body-frame velocities from timestamped camera poses (paper Sec. 4.1).

For each measured coordinate ``y`` in (X, Y, psi) a second-order high-gain observer

    x1' = x2 + (a1 / eps) (y - x1)
    x2' = (a2 / eps^2) (y - x1)

estimates the coordinate (x1) and its rate (x2). Seen from ``y`` to ``x2`` it is a differentiator followed by a
second-order low-pass filter with natural frequency ``sqrt(a2) / eps`` and damping ``a1 / (2 sqrt(a2))``: smaller
``eps`` tracks faster and amplifies more camera noise. Measurements arrive at irregular times; between two of them
the measurement is interpolated linearly (first-order hold) and the linear system is integrated exactly with a
matrix exponential (closed form for the 2x2
system), so a ramp is followed without error at any spacing. Heading is unwrapped against the
observer's own prediction, so a measurement jumping from +pi to -pi is a small turn, not a full one. The world rates
are finally rotated into the body frame: vx, vy (eq. 19's kinematics, inverted) and omega = psi'.

The arithmetic is :mod:`pectoral_gym.sensing.observer`'s batched kernels, on one row: the simulated envs'
camera (``EnvConfig.sensing``, :mod:`pectoral_gym.envs.sensed`) runs the very same observer.

:meth:`HighGainObserver.predict` extrapolates without a measurement (constant rates) and leaves the observer's state
alone, so a lost frame is never replaced by a made-up pose.
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.sensing import observer as kernels

__all__ = ["HighGainObserver"]


class HighGainObserver:
    """Second-order high-gain observer of (X, Y, psi) giving the simulated state layout.

    Args:
        epsilon: High-gain parameter [s]; the filter's natural frequency is ``sqrt(a2) / epsilon`` [rad/s].
        a1: First gain (``a1 = 2, a2 = 1``: critically damped, both poles at ``-1 / epsilon``).
        a2: Second gain.
        max_gap: Longest accepted time between two measurements [s]; after a longer gap the observer restarts
            from the new pose with zero rates instead of interpolating across it.
    """

    def __init__(self, epsilon: float = 0.1, a1: float = kernels.A1, a2: float = kernels.A2,
                 max_gap: float = 1.0) -> None:
        for name, value in (("epsilon", epsilon), ("a1", a1), ("a2", a2), ("max_gap", max_gap)):
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f"HighGainObserver: {name} must be a finite number > 0, got {value!r}")
        self.epsilon, self.a1, self.a2, self.max_gap = float(epsilon), float(a1), float(a2), float(max_gap)
        # The batched kernels' arrays, one row (pectoral_gym.sensing.observer).
        self._z = np.zeros((1, 2, 3))  # rows x1, x2; columns X, Y, psi (unwrapped)
        self._last = np.full((1, 4), np.nan)  # time and pose (psi unwrapped) of the last measurement
        self._estimate = np.full((1, 6), np.nan)
        self.restarts = 0

    @property
    def initialised(self) -> bool:
        """True once a first pose was given (by :meth:`reset` or :meth:`update`)."""
        return not math.isnan(self._last[0, 0])

    @property
    def time(self) -> float | None:
        """Timestamp of the last measurement [s]."""
        return float(self._last[0, 0]) if self.initialised else None

    @property
    def estimate(self) -> np.ndarray:
        """Latest output (6,) = X, Y, psi (unwrapped), vx, vy, omega; NaN before the first pose."""
        return self._estimate[0].copy()

    def transition(self, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact discretisation over ``step`` with the measurement interpolated linearly from ``u0`` to ``u1``.

        Returns ``(Phi, g1, gs)`` such that ``z(step) = Phi z(0) + g1 u1 - gs (u1 - u0) / step``:
        ``Phi = exp(A h)``, ``g1 = A^-1 (Phi - I) b``, ``gs = A^-1 (h Phi - A^-1 (Phi - I)) b``
        (:func:`pectoral_gym.sensing.observer.transition`).
        """
        return kernels.transition_matrices(self.epsilon, self.a1, self.a2, step)

    @staticmethod
    def _check(t: float, x: float, y: float, psi: float) -> None:
        if not all(math.isfinite(value) for value in (t, x, y, psi)):
            raise ValueError(f"observer input must be finite, got t={t!r}, x={x!r}, y={y!r}, psi={psi!r}")

    def reset(self, x: float, y: float, psi: float, t: float) -> np.ndarray:
        """Start from a measured pose at rest; returns the estimate (6,)."""
        self._check(t, x, y, psi)
        kernels.observer_reset(0, self._z, self._last, self._estimate, float(t), float(x), float(y), float(psi))
        return self.estimate

    def update(self, t: float, x: float, y: float, psi: float) -> np.ndarray:
        """Correct with a measured pose taken at time ``t``; returns the estimate (6,).

        The first call (or one after a gap longer than ``max_gap``) starts the observer at that pose.

        Raises:
            ValueError: Non-finite input, or ``t`` not after the previous measurement.
        """
        self._check(t, x, y, psi)
        if self.initialised and t - self._last[0, 0] <= 0:
            raise ValueError(f"measurement time {t!r} is not after the previous one {self.time!r}")
        self.restarts += kernels.observer_update(0, self._z, self._last, self._estimate, float(t), float(x),
                                                 float(y), float(psi), self.epsilon, self.a1, self.a2, self.max_gap)
        return self.estimate

    def predict(self, t: float) -> np.ndarray:
        """Estimate at time ``t`` with no new measurement (rates held); the observer state is unchanged.

        Raises:
            RuntimeError: No pose was ever given.
            ValueError: ``t`` is before the last measurement.
        """
        if not self.initialised:
            raise RuntimeError("HighGainObserver.predict: no pose yet; call reset() or update() first")
        if not math.isfinite(t) or t < self._last[0, 0]:
            raise ValueError(f"predict time {t!r} must be finite and not before the last measurement {self.time!r}")
        kernels.observer_predict(0, self._z, self._last, self._estimate, float(t))
        return self.estimate

    def frequency_response(self, omega: float) -> complex:
        """Transfer function from the true rate to the estimated rate at angular frequency ``omega`` [rad/s].

        ``G(j omega) = w_n^2 / (w_n^2 - omega^2 + j 2 zeta w_n omega)`` with ``w_n^2 = a2 / eps^2`` and
        ``2 zeta w_n = a1 / eps`` (continuous observer; the first-order hold makes it exact for ramps).
        """
        return kernels.frequency_response(omega, self.epsilon, self.a1, self.a2)
