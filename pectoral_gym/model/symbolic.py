"""CasADi expressions of the cycle-averaged model, for optimal control (NMPC).

The same equations as :class:`~pectoral_gym.model.models.AveragedModel` (exact
Bessel averages, eq. 25 with scaling functions K, body dynamics eqs. 19-20),
written with CasADi symbols so that the scaling identification (``scaling/``)
and the NMPC baseline (``agents/``) share one model. CasADi is an optional
dependency (``pip install pectoral-gym[nmpc]``); it is imported here only.

Every function accepts CasADi ``SX``/``MX`` (or plain numbers) and returns
expressions of the same kind.

The averaged model's corrections of a half-stroke (``docs/model.md`` 3.7-3.8) have their CasADi
form in :mod:`pectoral_gym.model.symbolic_corrections`.
"""

from __future__ import annotations

import math

try:
    import casadi as ca
except ImportError as err:  # pragma: no cover - exercised only without the nmpc extra
    raise ImportError(
        "pectoral_gym.model.symbolic needs CasADi: pip install 'pectoral-gym[nmpc]' (or pip install casadi)"
    ) from err


from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams, body_coefficients

__all__ = [
    "OSCILLATION_FLOOR", "STATE_SIZE", "STATE_POSITION", "STATE_PSI", "STATE_VELOCITY",
    "bessel_j1_sx", "bspline_basis_sx", "scaling_sx", "averaged_forcing_sx", "oscillating_square_mean_sx",
    "yaw_oscillation_sx", "combined_yaw_oscillation_sx", "body_accel_sx", "body_rhs_sx", "averaged_rhs_sx",
    "mean_fin_power_sx", "rk4_sx", "named_symbols",
]

# The state of the symbolic model, ``(X, Y, psi, vx, vy, omega)``: pose in the tank frame, then the
# body-frame velocities (eq. 19), the order of pectoral_gym.model.models' state rows.
STATE_SIZE = 6
STATE_POSITION = slice(0, 2)
STATE_PSI = 2
STATE_VELOCITY = slice(3, 6)

#: rad/s: the least yaw-oscillation amplitude the CasADi models use (keeps ``omega / A`` finite when two
#: mirrored fins cancel, or with no oscillation at all: ``A**2 / 2 = 5e-19`` off the paper's ``omega |omega|``).
OSCILLATION_FLOOR = 1e-9
_J1_TERMS = 18  # same truncation as averaging.bessel_j1 (machine precision for |x| <= pi)


def bessel_j1_sx(x):
    """``J1(x)`` by its power series (as :func:`pectoral_gym.model.averaging.bessel_j1`)."""
    half = 0.5 * x
    term = half
    total = half
    h2 = half * half
    for k in range(1, _J1_TERMS):
        term = term * (-h2 / (k * (k + 1)))
        total = total + term
    return total


def bspline_basis_sx(x, knots):
    """The ``len(knots) - 4`` cubic B-spline basis functions at ``x`` (clamped to the knot range).

    Cox-de Boor recursion written out symbolically, the same piecewise
    polynomials as the compiled :func:`pectoral_gym.model.averaging.scaling_values`.
    """
    knots = [float(k) for k in knots]
    n = len(knots) - 4
    x = ca.fmin(ca.fmax(x, knots[3]), knots[n])
    basis = []
    for j in range(len(knots) - 1):  # degree 0: the half-open knot interval, the last non-empty one closed
        if knots[j] == knots[j + 1]:
            basis.append(0.0)
        elif j == n - 1:
            basis.append(ca.if_else(x >= knots[j], 1.0, 0.0))
        else:
            basis.append(ca.if_else(ca.logic_and(x >= knots[j], x < knots[j + 1]), 1.0, 0.0))
    for degree in range(1, 4):
        nxt = []
        for j in range(len(knots) - 1 - degree):
            term = 0.0
            if knots[j + degree] != knots[j]:
                term = term + (x - knots[j]) / (knots[j + degree] - knots[j]) * basis[j]
            if knots[j + degree + 1] != knots[j + 1]:
                term = term + (knots[j + degree + 1] - x) / (knots[j + degree + 1] - knots[j + 1]) * basis[j + 1]
            nxt.append(term)
        basis = nxt
    return basis[:n]


def scaling_sx(beat, scaling: ScalingFunctions | None):
    """``[K_fx, K_fy, K_m]`` at ``beat = (bias, amplitude, period, ratio)``; all 1 if ``scaling`` is None.

    ``K_fy`` is in the sense of ``scaling.sway`` (:mod:`pectoral_gym.model.kfunctions`).
    """
    if scaling is None:
        return ca.vertcat(1.0, 1.0, 1.0)
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    features = (bias, amplitude, period, ratio, 1.0 / period, 1.0 / ratio)
    values = []
    for which in range(3):
        total = 0.0
        for powers, coef in zip(scaling.powers[which], scaling.coefs[which], strict=True):
            if coef == 0.0:
                continue
            term = float(coef)
            for feature, p in zip(features, powers, strict=True):
                if p != 0.0:
                    term = term * feature ** (int(p) if float(p).is_integer() else float(p))
            total = total + term
        values.append(total)
    if scaling.has_spline:
        for which, value in enumerate(_tensor_spline_sx((bias, amplitude, 1.0 / ratio), scaling.knots, scaling.table)):
            values[which] = values[which] + value
    return ca.vertcat(*values)


def _tensor_spline_sx(x, knots, table):
    """Each channel of a tensor-product cubic spline ``table (channels, n0, n1, n2)`` at ``x``."""
    bases = [ca.vertcat(*bspline_basis_sx(xi, k)) for xi, k in zip(x, knots, strict=True)]
    n0, n1, n2 = table.shape[1:]
    values = []
    for channel in table:
        # contract one axis at a time: (n0, n1 n2) -> (n1, n2) -> (n2,) -> scalar
        first = ca.mtimes(bases[0].T, ca.DM(channel.reshape(n0, n1 * n2)))
        second = ca.mtimes(bases[1].T, ca.reshape(first, n2, n1).T)
        values.append(ca.mtimes(second, bases[2]))
    return values


def yaw_oscillation_sx(beat, scaling: ScalingFunctions | None):
    """Phasor ``A (cos phi, sin phi)`` [rad/s] of the right fin's yaw-rate oscillation (zero without data).

    As :func:`pectoral_gym.model.averaging.yaw_oscillation_phasor`, including the
    linear shrink below the lowest amplitude node.
    """
    if scaling is None or not scaling.has_oscillation:
        return ca.vertcat(0.0, 0.0)
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    pc, ps = _tensor_spline_sx((bias, amplitude, 1.0 / ratio), scaling.oscillation_knots, scaling.oscillation_table)
    lowest = float(scaling.oscillation_knots[1][3])
    shrink = ca.fmin(ca.fmax(amplitude, 0.0), lowest) / lowest if lowest > 0.0 else 1.0
    return ca.vertcat(pc, ps) * shrink / period


def combined_yaw_oscillation_sx(right, left, scaling: ScalingFunctions | None):
    """Amplitude [rad/s] of the yaw oscillation of two fins beating in phase; ``None`` without yaw-oscillation data.

    The left fin's oscillation is the mirror image, so the phasors subtract
    (as in :func:`pectoral_gym.model.forcing_cache.yaw_oscillation` with equal beat phases); a tiny
    floor keeps ``omega / A`` finite when two equal fins cancel.
    """
    if scaling is None or not scaling.has_oscillation:
        return None
    phasor = yaw_oscillation_sx(right, scaling) - yaw_oscillation_sx(left, scaling)
    return ca.sqrt(ca.sumsqr(phasor) + OSCILLATION_FLOOR**2)


def oscillating_square_mean_sx(mean, amplitude):
    """Cycle mean of ``x|x|`` for ``x = mean + amplitude sin(theta)``.

    As :func:`pectoral_gym.model.averaging.oscillating_square_mean`; ``amplitude`` must be positive.
    The branch not taken is evaluated on clamped arguments, so its derivatives stay finite.
    """
    u = mean / amplitude
    a2 = amplitude * amplitude
    inside = ca.fmin(ca.fmax(u, -1.0 + 1e-12), 1.0 - 1e-12)
    crossing = a2 * (2.0 * ca.asin(inside) / math.pi * (u * u + 0.5)
                     + 3.0 / math.pi * u * ca.sqrt(ca.fmax(1.0 - u * u, 1e-300)))
    return ca.if_else(ca.fabs(u) >= 1.0, ca.sign(u) * a2 * (u * u + 0.5), crossing)


def averaged_forcing_sx(beat, side: float, params: FishParams, scaling: ScalingFunctions | None):
    """Scaled cycle-averaged ``[f_hx, f_hy, tau]`` of one fin on the body (eq. 25, exact averages).

    Args:
        beat: ``(bias, amplitude, period, ratio)`` (rad, rad, s, -), symbols or numbers.
        side: +1 for the right fin, -1 for the left.
        params: Model parameters.
        scaling: Scaling functions, or ``None`` for K = 1.
    """
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    c = params.fin_drag_constant * math.pi**2 * (ratio * ratio - 1.0) / (ratio * period * period)
    base = c * amplitude * bessel_j1_sx(amplitude)  # exact averages (paper-notes), Taylor form in eqs. (26)-(27)
    fx = base * ca.sin(bias)
    fy = base * ca.cos(bias)
    tau = params.fin_offset * fx  # eq. (28): moment arm C_p
    k = scaling_sx(beat, scaling)
    sway = k[1] * base if scaling is not None and scaling.sway == "base" else k[1] * fy
    return ca.vertcat(k[0] * fx, side * sway, side * k[2] * tau)


def body_accel_sx(v, forcing, params: FishParams, smoothing: float = 0.0, yaw_oscillation=None):
    """Body-frame accelerations ``d(vx, vy, omega)/dt`` of eqs. (19)-(20).

    Args:
        v: ``(vx, vy, omega)``.
        forcing: Total ``(f_x, f_y, tau)`` of the fins on the body.
        params: Model parameters.
        smoothing: 0 (default) evaluates ``alpha = arctan(vy / vx)`` and the speed
            exactly as :func:`pectoral_gym.model.dynamics.body_accel`; a positive speed
            scale [m/s] (e.g. 1e-4) replaces them by smooth versions whose
            derivatives exist at rest, which gradient-based solvers need when a
            trajectory starts from rest.
        yaw_oscillation: ``None`` (default) for the paper's yaw damping
            ``c4 omega|omega|``; else the amplitude [rad/s] of the in-beat yaw
            oscillation (> 0), and the damping is its cycle mean
            (:func:`oscillating_square_mean_sx`).
    """
    vx, vy, omega = v[0], v[1], v[2]
    m1, m2, j3, c1, c2, c4 = body_coefficients(params)
    if smoothing > 0.0:
        eps2 = smoothing * smoothing
        speed = ca.sqrt(vx * vx + vy * vy + eps2)
        alpha = ca.atan(vx * vy / (vx * vx + eps2))  # -> arctan(vy / vx) for |vx| >> smoothing
        yaw_damping = c4 * omega * ca.sqrt(omega * omega + eps2)
    else:
        speed = ca.sqrt(vx * vx + vy * vy)
        alpha = ca.if_else(vx >= 0, ca.atan2(vy, vx), -ca.atan2(vy, -vx))  # arctan(vy / vx), also for vx < 0
        yaw_damping = c4 * omega * ca.fabs(omega)
    if yaw_oscillation is not None:
        yaw_damping = c4 * oscillating_square_mean_sx(omega, yaw_oscillation)
    dvx = (m2 * vy * omega - c1 * vx * speed + c2 * vy * speed * alpha + forcing[0]) / m1  # eqs. (19)-(20), f1
    dvy = (-m1 * vx * omega - c1 * vy * speed - c2 * vx * speed * alpha + forcing[1]) / m2  # f2
    dom = (m1 - m2) / j3 * vx * vy - yaw_damping + forcing[2] / j3  # f3
    return ca.vertcat(dvx, dvy, dom)


def body_rhs_sx(state, forcing, params: FishParams, smoothing: float = 0.0, yaw_oscillation=None):
    """Time derivative of ``state = (X, Y, psi, vx, vy, omega)`` under the fin forcing ``(f_x, f_y, tau)``.

    The tank-frame kinematics of eq. (19) and the body accelerations of
    :func:`body_accel_sx` (whose ``smoothing`` and ``yaw_oscillation`` these are).
    """
    psi = state[STATE_PSI]
    vx, vy, omega = (state[i] for i in range(STATE_VELOCITY.start, STATE_VELOCITY.stop))
    accel = body_accel_sx([vx, vy, omega], forcing, params, smoothing, yaw_oscillation)
    x_dot = vx * ca.cos(psi) - vy * ca.sin(psi)  # eq. (19), kinematics
    y_dot = vx * ca.sin(psi) + vy * ca.cos(psi)
    return ca.vertcat(x_dot, y_dot, omega, accel)


def averaged_rhs_sx(state, beats, params: FishParams, scaling: ScalingFunctions | None, smoothing: float = 0.0):
    """Time derivative of ``state = (X, Y, psi, vx, vy, omega)`` under the averaged model (eqs. 19, 25).

    With yaw-oscillation data in ``scaling`` the yaw damping is
    oscillation-averaged, with the two fins' oscillations added as phasors of
    fins beating in phase (as fins with equal periods started together do;
    :func:`pectoral_gym.model.forcing_cache.yaw_oscillation` tracks the actual phases).

    Args:
        state: Pose in the tank frame and body-frame velocities.
        beats: ``(8,)``: right fin ``(bias, amplitude, period, ratio)``, then the left fin.
        params: Model parameters.
        scaling: Scaling functions, or ``None`` for K = 1.
        smoothing: See :func:`body_accel_sx`.
    """
    right = averaged_forcing_sx([beats[i] for i in range(4)], 1.0, params, scaling)
    left = averaged_forcing_sx([beats[i] for i in range(4, 8)], -1.0, params, scaling)
    fins = [beats[i] for i in range(4)], [beats[i] for i in range(4, 8)]
    oscillation = combined_yaw_oscillation_sx(*fins, scaling)
    return body_rhs_sx(state, right + left, params, smoothing, oscillation)


def mean_fin_power_sx(amplitude, period, ratio, params: FishParams):
    """Mean hydrodynamic power one fin delivers to the water [W], as :func:`~.averaging.mean_fin_power`.

    ``k S_p gA^3 (w1^2 + w2^2) / T_p`` from eq. (14) with the stroke rates
    ``w1 = pi (zeta + 1) / T_p`` and ``w2 = w1 / zeta`` (docs/model.md, Sec. 3.5):
    cubic in the amplitude, so ``mean_fin_power_sx(1.0, ...)`` is the factor of ``gA^3``.
    """
    w1 = math.pi * (ratio + 1.0) / period
    w2 = w1 / ratio
    return params.fin_drag_constant * params.fin_span * amplitude**3 * (w1 * w1 + w2 * w2) / period


def named_symbols(sizes):
    """One ``SX`` column symbol per field of the NamedTuple ``sizes`` (field -> length), as the same NamedTuple.

    For a packed NLP vector with named parts: ``ca.vertcat(*symbols)`` is the
    packed symbol, and the numbers go in the same order (``np.concatenate``
    of the same NamedTuple filled with values).
    """
    return type(sizes)(*(ca.SX.sym(name, int(size)) for name, size in zip(sizes._fields, sizes, strict=True)))


def rk4_sx(rhs, x, u, h, steps: int = 1):
    """``steps`` classical Runge-Kutta steps of size ``h`` of ``dx/dt = rhs(x, u)``, ``u`` held constant.

    Args:
        rhs: Callable ``(x, u) -> dx/dt`` (a ``ca.Function`` or a Python function of expressions).
        x: Initial state (expression or numbers).
        u: Whatever ``rhs`` takes as its second argument, passed through unchanged.
        h: Step size [s].
        steps: Number of steps (>= 1).
    """
    if int(steps) < 1:
        raise ValueError(f"steps must be >= 1, got {steps!r}")
    for _ in range(int(steps)):
        k1 = rhs(x, u)
        k2 = rhs(x + 0.5 * h * k1, u)
        k3 = rhs(x + 0.5 * h * k2, u)
        k4 = rhs(x + h * k3, u)
        x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x
