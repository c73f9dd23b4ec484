"""Compiled evaluation of the scaling functions K and the yaw-oscillation phasor from their tables.

The one implementation of the K polynomial and splines on the numba side: the
model kernels call it at every latch of a new pattern, and
:meth:`pectoral_gym.model.kfunctions.ScalingFunctions.evaluate` calls it from Python
(the CasADi side has its own, :func:`pectoral_gym.model.symbolic.scaling_sx`).
What the tables mean, and the file they come from, is described in
:mod:`pectoral_gym.model.kfunctions`; :meth:`~pectoral_gym.model.kfunctions.ScalingFunctions.kernel_arrays`
packs them into a :class:`KTables`.

Everything here is free of allocations (it runs inside the parallel model kernels).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["KTables", "as_tables", "bspline_basis", "interleave",
           "oscillation_phasor", "pattern_values", "scaling_values", "spline_values", "yaw_oscillation_phasor"]


class KTables(NamedTuple):
    """The scaling-function tables as the compiled kernels read them (numba compiles it as a tuple).

    =============  ===================  ===================================================================
    field          shape                meaning
    =============  ===================  ===================================================================
    ``powers``     ``(3, n_terms, 6)``  integer exponents [-] of the features (``kfunctions.FEATURES``:
                                        rad, rad, s, -, 1/s, -), per K (``K_fx, K_fy, K_m``)
    ``coefs``      ``(3, n_terms)``     polynomial coefficients [-] (zeros pad unused terms)
    ``knots``      ``(3, longest)``     spline knots: ``bias`` [rad], ``amplitude`` [rad], ``1/ratio`` [-],
                                        padded with their last knot (never read)
    ``table``      ``(3, nb, na, nr)``  spline coefficients [-] of the three K; ``(3, 0, 0, 0)``: none
    ``base_sway``  bool                 True: ``K_fy`` multiplies ``base``; False: ``f_hy_avg`` (paper)
    ``osc_knots``  ``(3, longest)``     knots of the yaw-oscillation splines (same axes)
    ``osc_table``  ``(2, nb, na, nr)``  phasor ``A T_p (cos phi, sin phi)`` [rad]; ``(2, 0, 0, 0)``: none
    ``shared``     ``(nb, na, nr, 5)``  when ``osc_table`` has ``table``'s knots and shape (the shipped
                                        file): both tables interleaved, ``K_fx, K_fy, K_m, cos, sin`` last,
                                        for :func:`pattern_values`; ``(0, 0, 0, 5)``: not shared
    =============  ===================  ===================================================================

    ``nb, na, nr``: spline coefficients along bias, amplitude and 1/ratio.
    """

    powers: np.ndarray
    coefs: np.ndarray
    knots: np.ndarray
    table: np.ndarray
    base_sway: bool
    osc_knots: np.ndarray
    osc_table: np.ndarray
    shared: np.ndarray


@njit(inline="always")
def as_tables(packed) -> KTables:
    """The :class:`KTables` of ``tuple(tables)``, inside compiled code.

    numba types a NamedTuple argument in Python at every call (about 1.4 us
    more than a plain tuple), so the per-step entry points take
    ``tuple(tables)`` and name the fields again here.
    """
    return KTables(packed[0], packed[1], packed[2], packed[3], packed[4], packed[5], packed[6], packed[7])


@njit
def bspline_basis(knots, n: int, x: float):
    """Span and the four nonzero cubic B-spline basis values at ``x`` (clamped to the knot range).

    The Cox-de Boor recursion of Piegl & Tiller, *The NURBS Book*, algorithm
    A2.2, unrolled for degree 3 and free of allocations (it runs inside the
    parallel model kernels). Coefficient ``span - 3 + a`` multiplies the
    ``a``-th value. Returns ``(span, b0, b1, b2, b3)``.
    """
    x = min(max(x, knots[3]), knots[n])
    span = 3
    while span < n - 1 and knots[span + 1] <= x:
        span += 1
    left1, left2, left3 = x - knots[span], x - knots[span - 1], x - knots[span - 2]
    right1, right2, right3 = knots[span + 1] - x, knots[span + 2] - x, knots[span + 3] - x
    # degree 1
    temp = 1.0 / (right1 + left1)
    n0, n1 = right1 * temp, left1 * temp
    # degree 2
    temp = n0 / (right1 + left2)
    n0, saved = right1 * temp, left2 * temp
    temp = n1 / (right2 + left1)
    n1, n2 = saved + right2 * temp, left1 * temp
    # degree 3
    temp = n0 / (right1 + left3)
    n0, saved = right1 * temp, left3 * temp
    temp = n1 / (right2 + left2)
    n1, saved = saved + right2 * temp, left2 * temp
    temp = n2 / (right3 + left1)
    n2, n3 = saved + right3 * temp, left1 * temp
    return span, n0, n1, n2, n3


@njit
def _tensor_spline(bias: float, amplitude: float, inv_ratio: float, knots, table):
    """Up to three channels of a tensor-product cubic spline ``table (channels, n0, n1, n2)``; absent ones are 0."""
    channels, n0, n1, n2 = table.shape[0], table.shape[1], table.shape[2], table.shape[3]
    s0, a0, a1, a2, a3 = bspline_basis(knots[0], n0, bias)
    s1, c0, c1, c2, c3 = bspline_basis(knots[1], n1, amplitude)
    s2, d0, d1, d2, d3 = bspline_basis(knots[2], n2, inv_ratio)
    b0, b1, b2 = (a0, a1, a2, a3), (c0, c1, c2, c3), (d0, d1, d2, d3)
    v0 = v1 = v2 = 0.0
    for a in range(4):
        for b in range(4):
            w = b0[a] * b1[b]
            for c in range(4):
                wc = w * b2[c]
                i, j, k = s0 - 3 + a, s1 - 3 + b, s2 - 3 + c
                v0 += wc * table[0, i, j, k]
                if channels > 1:
                    v1 += wc * table[1, i, j, k]
                if channels > 2:
                    v2 += wc * table[2, i, j, k]
    return v0, v1, v2


@njit
def spline_values(bias: float, amplitude: float, inv_ratio: float, knots, table):
    """Spline parts of ``(K_fx, K_fy, K_m)``; ``knots``, ``table`` as in :class:`KTables`.

    Zero when ``table`` is empty (no spline part).
    """
    if table.shape[1] == 0:
        return 0.0, 0.0, 0.0
    return _tensor_spline(bias, amplitude, inv_ratio, knots, table)


@njit(inline="always")
def _taper(amplitude: float, knots) -> float:
    """Below the lowest amplitude node (``knots[1, 3]``) the phasor splines shrink linearly to zero."""
    lowest = knots[1, 3]
    return amplitude / lowest if amplitude < lowest and lowest > 0.0 else 1.0


@njit
def oscillation_phasor(bias: float, amplitude: float, inv_ratio: float, knots, table):
    """Yaw-oscillation phasor ``A T_p (cos phi, sin phi)`` [rad] of one fin (module docstring).

    ``knots``, ``table`` are :attr:`KTables.osc_knots`, :attr:`KTables.osc_table`;
    ``(0, 0)`` when ``table`` is empty or the fin does not beat. Below the
    lowest amplitude node the phasor shrinks linearly to zero.
    """
    if table.shape[1] == 0 or amplitude <= 0.0:
        return 0.0, 0.0
    pc, ps, _ = _tensor_spline(bias, amplitude, inv_ratio, knots, table)
    taper = _taper(amplitude, knots)
    if taper != 1.0:
        pc *= taper
        ps *= taper
    return pc, ps


@njit
def _ipow(x: float, exponent: float) -> float:
    """``x ** exponent`` for a small non-negative integer ``exponent``, by repeated multiplication."""
    result = 1.0
    for _ in range(int(exponent)):
        result *= x
    return result


@njit
def _k_value(which: int, bias: float, amplitude: float, period: float, ratio: float, k_powers, k_coefs) -> float:
    """Evaluate the polynomial part of scaling function ``which`` (0 K_fx, 1 K_fy, 2 K_m) as a sum of monomials.

    Features, in order: bias [rad], amplitude [rad], period [s], ratio [-], 1/period [1/s], 1/ratio [-].
    """
    total = 0.0
    for j in range(k_coefs.shape[1]):
        c = k_coefs[which, j]
        if c == 0.0:
            continue
        p = k_powers[which, j]
        # integer exponents (the file format allows no others): multiplications instead of pow()
        total += (
            c * _ipow(bias, p[0]) * _ipow(amplitude, p[1]) * _ipow(period, p[2]) * _ipow(ratio, p[3])
            * _ipow(1.0 / period, p[4]) * _ipow(1.0 / ratio, p[5])
        )
    return total


@njit
def scaling_values(bias: float, amplitude: float, period: float, ratio: float, tables: KTables):
    """``(K_fx, K_fy, K_m)`` at one pattern (rad, rad, s, -): polynomial part plus spline part."""
    sx, sy, sm = spline_values(bias, amplitude, 1.0 / ratio, tables.knots, tables.table)
    kx, ky, km = _polynomial_parts(bias, amplitude, period, ratio, tables)
    return kx + sx, ky + sy, km + sm


@njit(inline="always")
def _polynomial_parts(bias: float, amplitude: float, period: float, ratio: float, tables: KTables):
    """The polynomial parts of ``(K_fx, K_fy, K_m)`` (:func:`_k_value` of each)."""
    # A loop, not three calls with the constants 0, 1, 2: numba would compile _k_value once per constant.
    kx = ky = km = 0.0
    for which in range(3):
        value = _k_value(which, bias, amplitude, period, ratio, tables.powers, tables.coefs)
        if which == 0:
            kx = value
        elif which == 1:
            ky = value
        else:
            km = value
    return kx, ky, km


def interleave(knots: np.ndarray, table: np.ndarray, osc_knots: np.ndarray, osc_table: np.ndarray) -> np.ndarray:
    """:attr:`KTables.shared`: the K and phasor tables interleaved when they share knots and shape."""
    if (table.shape[0] == 3 and table.shape[1] > 0 and osc_table.shape[1:] == table.shape[1:]
            and np.array_equal(osc_knots, knots)):
        return np.ascontiguousarray(np.concatenate([table, osc_table], axis=0).transpose(1, 2, 3, 0))
    return np.zeros((0, 0, 0, 5))


@njit
def _shared_splines(bias: float, amplitude: float, inv_ratio: float, knots, shared):
    """The three K spline channels and the two phasor channels of :attr:`KTables.shared`, in one pass.

    The basis is evaluated once and the five channels are read side by side; each is summed in
    the order of :func:`_tensor_spline`, so the values are bit for bit those of
    :func:`spline_values` and :func:`oscillation_phasor` (before its low-amplitude taper).
    """
    s0, a0, a1, a2, a3 = bspline_basis(knots[0], shared.shape[0], bias)
    s1, c0, c1, c2, c3 = bspline_basis(knots[1], shared.shape[1], amplitude)
    s2, d0, d1, d2, d3 = bspline_basis(knots[2], shared.shape[2], inv_ratio)
    b0, b1, b2 = (a0, a1, a2, a3), (c0, c1, c2, c3), (d0, d1, d2, d3)
    v0 = v1 = v2 = p0 = p1 = 0.0
    for a in range(4):
        for b in range(4):
            w = b0[a] * b1[b]
            row = shared[s0 - 3 + a, s1 - 3 + b]
            for c in range(4):
                wc = w * b2[c]
                k = s2 - 3 + c
                v0 += wc * row[k, 0]
                v1 += wc * row[k, 1]
                v2 += wc * row[k, 2]
                p0 += wc * row[k, 3]
                p1 += wc * row[k, 4]
    return v0, v1, v2, p0, p1


@njit
def pattern_values(bias: float, amplitude: float, period: float, ratio: float, tables: KTables):
    """``(K_fx, K_fy, K_m)`` and the yaw-oscillation phasor [rad/s] of one right fin, at one latch.

    The values of :func:`scaling_values` and :func:`yaw_oscillation_phasor`, bit for bit; when
    the two splines share their knots (:attr:`KTables.shared`, the shipped file) one pass over
    the basis serves both, which more than halves the cost of a latch.
    """
    if tables.shared.shape[0] == 0 or amplitude <= 0.0:
        kx, ky, km = scaling_values(bias, amplitude, period, ratio, tables)
        pc, ps = yaw_oscillation_phasor(bias, amplitude, period, ratio, tables)
        return kx, ky, km, pc, ps
    sx, sy, sm, pc, ps = _shared_splines(bias, amplitude, 1.0 / ratio, tables.knots, tables.shared)
    taper = _taper(amplitude, tables.osc_knots)
    if taper != 1.0:  # as oscillation_phasor
        pc *= taper
        ps *= taper
    kx, ky, km = _polynomial_parts(bias, amplitude, period, ratio, tables)
    return kx + sx, ky + sy, km + sm, pc / period, ps / period


@njit
def yaw_oscillation_phasor(bias: float, amplitude: float, period: float, ratio: float, tables: KTables):
    """Phasor ``A (cos phi, sin phi)`` [rad/s] of the yaw-rate oscillation one right fin drives.

    ``A T_p`` and ``phi`` come from the scaling file (:func:`oscillation_phasor`);
    ``(0, 0)`` without yaw-oscillation data.
    """
    pc, ps = oscillation_phasor(bias, amplitude, 1.0 / ratio, tables.osc_knots, tables.osc_table)
    return pc / period, ps / period
