"""Closed forms of the scaling functions: lowest-complexity polynomial chosen by k-fold cross-validation.

Candidates are complete polynomials of total degree ``0 .. max_degree`` in a
subset of the features of :data:`pectoral_gym.model.kfunctions.FEATURES` (the paper
fits polynomials in the four fin-beat parameters; ``inv_ratio`` and
``inv_period`` let ``1 / zeta`` and ``1 / T_p`` bases compete). Each candidate is fitted by weighted least squares
and scored by its k-fold cross-validated weighted RMS residual. The chosen
form is the one with the fewest terms whose CV error meets an accuracy target
or, if none does, is within one standard error of the best candidate's (the
one-standard-error rule): a simpler form wins unless a richer one is clearly
better on held-out patterns.

Weights: :func:`pectoral_gym.scaling.identification.response.sensitivity_weights` turns an error in ``K_i`` into the
relative error it causes in the steady-state velocity it drives (a
linearisation of eq. 20), so the fit minimises the predicted velocity error
rather than treating every K value alike.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline

from pectoral_gym.model.kfunctions import FEATURES, ScalingFunctions

__all__ = [
    "Fit",
    "SplineFit",
    "fit_oscillation",
    "fit_spline",
    "spline_nodes",
    "FEATURE_SETS",
    "design_matrix",
    "feature_matrix",
    "fit_polynomial",
    "monomial_powers",
    "select_model",
]

# Candidate feature subsets (indices into FEATURES: bias, amplitude, period, ratio, inv_period, inv_ratio).
FEATURE_SETS: dict[str, tuple[int, ...]] = {
    "bias, amplitude, ratio": (0, 1, 3),
    "bias, amplitude, 1/ratio": (0, 1, 5),
    "bias, amplitude, 1/ratio, period": (0, 1, 5, 2),
    "bias, amplitude, 1/ratio, 1/period": (0, 1, 5, 4),
}


@dataclass(frozen=True)
class Fit:
    """A fitted closed form of one scaling function.

    Attributes:
        features: Name of the feature subset.
        degree: Total polynomial degree.
        powers: ``(n_terms, len(FEATURES))`` exponents over all :data:`FEATURES`.
        coefs: ``(n_terms,)`` coefficients.
        r2: Weighted coefficient of determination on all data.
        cv_rmse: k-fold cross-validated weighted RMS residual.
        cv_se: Standard error of ``cv_rmse`` over the folds.
        cv_max: Largest weighted held-out residual.
        n_points: Number of data points fitted.
    """

    features: str
    degree: int
    powers: np.ndarray
    coefs: np.ndarray
    r2: float
    cv_rmse: float
    cv_se: float
    cv_max: float
    n_points: int

    def predict(self, patterns: np.ndarray) -> np.ndarray:
        """Evaluate at ``(n, 4)`` patterns."""
        return design_matrix(feature_matrix(patterns), self.powers) @ self.coefs

    def summary(self) -> dict:
        """JSON-ready fit statistics."""
        return {
            "features": self.features,
            "degree": self.degree,
            "terms": len(self.coefs),
            "r2": self.r2,
            "cv_rmse": self.cv_rmse,
            "cv_se": self.cv_se,
            "cv_max": self.cv_max,
            "points": self.n_points,
        }


def feature_matrix(patterns: np.ndarray) -> np.ndarray:
    """``(n, 6)`` values of :data:`FEATURES` for ``(n, 4)`` patterns."""
    patterns = np.asarray(patterns, dtype=np.float64)
    return np.column_stack([patterns, 1.0 / patterns[:, 2], 1.0 / patterns[:, 3]])


def monomial_powers(feature_set: tuple[int, ...], degree: int) -> np.ndarray:
    """Exponents ``(n_terms, 5)`` of every monomial of total degree <= ``degree`` in ``feature_set``."""
    rows = []
    for total in range(degree + 1):
        for combo in itertools.combinations_with_replacement(feature_set, total):
            row = np.zeros(len(FEATURES))
            for k in combo:
                row[k] += 1
            rows.append(row)
    return np.array(rows)


def design_matrix(features: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """``(n, n_terms)`` monomials ``prod_k features[:, k] ** powers[j, k]``."""
    return np.prod(features[:, None, :] ** powers[None, :, :], axis=2)


def _weighted_lstsq(a: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    aw = a * w[:, None]
    scale = np.linalg.norm(aw, axis=0)
    scale[scale == 0] = 1.0  # column scaling keeps high-degree monomials well conditioned
    coefs, *_ = np.linalg.lstsq(aw / scale, y * w, rcond=None)
    return coefs / scale


def fit_polynomial(
    patterns: np.ndarray,
    values: np.ndarray,
    weights: np.ndarray | None = None,
    feature_set: str = "bias, amplitude, ratio",
    degree: int = 2,
    folds: int = 5,
    seed: int = 0,
) -> Fit:
    """Weighted least-squares polynomial fit with k-fold cross-validation statistics.

    Args:
        patterns: ``(n, 4)`` fin patterns.
        values: ``(n,)`` K values.
        weights: ``(n,)`` positive weights (ones if ``None``).
        feature_set: A key of :data:`FEATURE_SETS`.
        degree: Total degree.
        folds: Number of CV folds (``min(folds, n)``).
        seed: Seed of the fold shuffle.
    """
    values = np.asarray(values, dtype=np.float64)
    n = len(values)
    weights = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
    if feature_set not in FEATURE_SETS:
        raise ValueError(f"unknown feature set {feature_set!r}; choose from {list(FEATURE_SETS)}")
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(weights)) and np.all(weights > 0)):
        raise ValueError("values and weights must be finite, weights > 0")
    powers = monomial_powers(FEATURE_SETS[feature_set], degree)
    a = design_matrix(feature_matrix(patterns), powers)
    coefs = _weighted_lstsq(a, values, weights)
    resid = (a @ coefs - values) * weights
    centred = (values - np.average(values, weights=weights**2)) * weights
    r2 = 1.0 - float(resid @ resid) / max(float(centred @ centred), 1e-300)
    order = np.random.default_rng(seed).permutation(n)
    fold_rmse, held_out = [], []
    for test in np.array_split(order, min(folds, n)):
        train = np.setdiff1d(order, test)
        c = _weighted_lstsq(a[train], values[train], weights[train])
        e = (a[test] @ c - values[test]) * weights[test]
        fold_rmse.append(float(np.sqrt(np.mean(e**2))))
        held_out.append(np.abs(e))
    held = np.concatenate(held_out)
    return Fit(
        features=feature_set,
        degree=degree,
        powers=powers,
        coefs=coefs,
        r2=r2,
        cv_rmse=float(np.sqrt(np.mean(held**2))),
        cv_se=float(np.std(fold_rmse, ddof=1) / np.sqrt(len(fold_rmse))) if len(fold_rmse) > 1 else 0.0,
        cv_max=float(held.max()),
        n_points=n,
    )


def select_model(
    patterns: np.ndarray,
    values: np.ndarray,
    weights: np.ndarray | None = None,
    max_degree: int = 7,
    feature_sets: tuple[str, ...] | None = None,
    folds: int = 5,
    seed: int = 0,
    target: float = 2e-3,
) -> tuple[Fit, list[Fit]]:
    """The lowest-complexity candidate that fits, and all candidates.

    "Fits": CV error <= ``target`` (weighted units; with the sensitivity
    weights, a predicted relative velocity error). The candidate with the
    fewest terms that fits is chosen; if none does, the one with the fewest
    terms within one standard error of the best CV error. Candidates with more
    terms than a fifth of the data points are skipped (their CV error is
    unreliable).
    """
    feature_sets = feature_sets or tuple(FEATURE_SETS)
    n = len(values)
    candidates = []
    for name in feature_sets:
        for degree in range(max_degree + 1):
            if len(monomial_powers(FEATURE_SETS[name], degree)) > max(1, n // 5):
                break
            candidates.append(fit_polynomial(patterns, values, weights, name, degree, folds, seed))
    best = min(candidates, key=lambda f: f.cv_rmse)
    threshold = max(best.cv_rmse + best.cv_se, target)
    chosen = min((f for f in candidates if f.cv_rmse <= threshold), key=lambda f: (len(f.coefs), f.cv_rmse))
    return chosen, candidates


# --------------------------------------------------------------------------- tensor-product cubic splines


def spline_nodes(patterns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted distinct ``(bias, amplitude, 1/ratio)`` node values of a grid of ``(n, 4)`` patterns."""
    patterns = np.asarray(patterns, dtype=np.float64)
    coords = np.column_stack([patterns[:, 0], patterns[:, 1], 1.0 / patterns[:, 3]])
    return tuple(np.unique(np.round(coords[:, k], 12)) for k in range(3))


@dataclass(frozen=True)
class SplineFit:
    """An interpolating tensor-product cubic spline of one scaling function over (bias, amplitude, 1/ratio).

    Attributes:
        knots: Three not-a-knot knot vectors.
        table: ``(n_bias, n_amplitude, n_inv_ratio)`` B-spline coefficients.
        nodes: The grid's node values per axis.
        filled: Nodes without a usable value, filled by ``fill`` before interpolating.
        period_spread: Largest difference between values of the same node at different periods
            (K does not depend on the period; this checks it on every run).
    """

    knots: tuple[np.ndarray, np.ndarray, np.ndarray]
    table: np.ndarray
    nodes: tuple[np.ndarray, np.ndarray, np.ndarray]
    filled: int
    period_spread: float

    def predict(self, patterns: np.ndarray) -> np.ndarray:
        """Evaluate at ``(n, 4)`` patterns (clamped to the node range, like the averaged model)."""
        table = np.zeros((3, *self.table.shape))
        table[0] = self.table
        single = ScalingFunctions(np.zeros((3, 1, len(FEATURES))), np.zeros((3, 1)), {}, self.knots, table)
        return np.array([single.evaluate(*p)[0] for p in np.asarray(patterns, dtype=np.float64)])

    def summary(self) -> dict:
        """JSON-ready description."""
        return {
            "kind": "tensor-product cubic spline (not-a-knot), interpolating",
            "axes": ["bias", "amplitude", "inv_ratio"],
            "nodes": [len(n) for n in self.nodes],
            "coefficients": int(self.table.size),
            "filled_nodes": self.filled,
            "period_spread": self.period_spread,
        }


def fit_spline(patterns: np.ndarray, values: np.ndarray, usable: np.ndarray | None = None, fill=None) -> SplineFit:
    """Interpolate ``values`` on a tensor grid of patterns with a cubic spline per axis.

    The patterns must form a full tensor grid over (bias, amplitude, ratio),
    repeated at any number of periods (values of one node at several periods
    are averaged: K does not depend on the period). The coefficients are
    found one axis at a time (tensor-product interpolation is separable),
    each by :func:`scipy.interpolate.make_interp_spline` with not-a-knot ends.

    Args:
        patterns: ``(n, 4)`` grid patterns.
        values: ``(n,)`` K values.
        usable: ``(n,)`` mask of values to use (default: the finite ones).
        fill: Callable ``patterns -> values`` for nodes without a usable value
            (e.g. a polynomial fit); without it such nodes raise.

    Raises:
        ValueError: If the patterns are not a tensor grid, an axis has fewer
            than 4 nodes, or nodes are missing and there is no ``fill``.
    """
    patterns = np.asarray(patterns, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    usable = np.isfinite(values) if usable is None else (np.asarray(usable, dtype=bool) & np.isfinite(values))
    nodes = spline_nodes(patterns)
    shape = tuple(len(n) for n in nodes)
    if min(shape) < 4:
        raise ValueError(f"a cubic spline needs >= 4 distinct values of bias, amplitude and ratio; grid has {shape}")
    coords = np.column_stack([patterns[:, 0], patterns[:, 1], 1.0 / patterns[:, 3]])
    index = tuple(np.searchsorted(nodes[k], np.round(coords[:, k], 12)) for k in range(3))
    seen = np.zeros(shape, dtype=bool)
    seen[index] = True
    if not np.all(seen):
        raise ValueError(f"the grid is not a full tensor product: {int((~seen).sum())} of {seen.size} "
                         "(bias, amplitude, ratio) nodes have no pattern")
    total, count = np.zeros(shape), np.zeros(shape)
    low, high = np.full(shape, np.inf), np.full(shape, -np.inf)
    sel = tuple(i[usable] for i in index)
    np.add.at(total, sel, values[usable])
    np.add.at(count, sel, 1.0)
    np.minimum.at(low, sel, values[usable])
    np.maximum.at(high, sel, values[usable])
    table = np.divide(total, count, out=np.full(shape, np.nan), where=count > 0)
    spread = float(np.max(np.where(count > 1, high - low, 0.0), initial=0.0))
    missing = count == 0
    if np.any(missing):
        if fill is None:
            raise ValueError(f"{int(missing.sum())} grid nodes have no usable value and no fill was given")
        idx = np.argwhere(missing)
        fill_patterns = np.column_stack([nodes[0][idx[:, 0]], nodes[1][idx[:, 1]], np.ones(len(idx)),
                                         1.0 / nodes[2][idx[:, 2]]])
        table[missing] = fill(fill_patterns)
    knots = []
    for axis in range(3):
        spline = make_interp_spline(nodes[axis], table, k=3, axis=axis)
        table, knots_axis = np.moveaxis(spline.c, 0, axis), spline.t
        knots.append(knots_axis)
    return SplineFit(tuple(knots), np.ascontiguousarray(table), nodes, int(missing.sum()), spread)


def fit_oscillation(
    patterns: np.ndarray, amplitude: np.ndarray, phase: np.ndarray, usable: np.ndarray | None = None
) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """Splines of the yaw-oscillation phasor ``A T_p (cos phi, sin phi)`` over (bias, amplitude, 1/ratio).

    ``A T_p`` and ``phi`` do not depend on the period (the full model is
    invariant under ``t -> t / T_p``), so nodes at several periods are
    averaged, as for K. Nodes without a usable value are filled by a cubic
    least-squares polynomial of the usable ones.

    Args:
        patterns: ``(n, 4)`` grid patterns (a tensor grid, see :func:`fit_spline`).
        amplitude: ``(n,)`` oscillation amplitudes ``A`` [rad/s] (``pectoral_gym.scaling.identification.reference``).
        phase: ``(n,)`` phases ``phi`` [rad].
        usable: ``(n,)`` mask (default: finite values).

    Returns:
        ``(knots, table)`` for :class:`pectoral_gym.model.kfunctions.ScalingFunctions`
        (``oscillation_knots``, ``oscillation_table`` of shape ``(2, n0, n1, n2)``).

    Raises:
        ValueError: If the patterns are not a tensor grid (:func:`fit_spline`).
    """
    patterns = np.asarray(patterns, dtype=np.float64)
    scaled = np.asarray(amplitude, dtype=np.float64) * patterns[:, 2]
    return _period_free_splines(patterns, [scaled * np.cos(phase), scaled * np.sin(phase)], usable)


def _period_free_splines(patterns: np.ndarray, parts: list[np.ndarray], usable: np.ndarray | None):
    """Knots and stacked tables of one interpolating spline per value list (nodes missing: cubic polynomial fill)."""
    ok = np.all([np.isfinite(v) for v in parts], axis=0) & (True if usable is None else np.asarray(usable, dtype=bool))
    powers = monomial_powers((0, 1, 5), 3)
    fits = []
    for values in parts:
        coefs = np.linalg.lstsq(design_matrix(feature_matrix(patterns[ok]), powers), values[ok], rcond=None)[0]
        fits.append(fit_spline(patterns, values, ok,
                               fill=lambda p, c=coefs: design_matrix(feature_matrix(p), powers) @ c))
    return fits[0].knots, np.array([f.table for f in fits])
