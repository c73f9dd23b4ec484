"""The identification pipeline of the paper's Sec. 4.3: grid -> reference runs -> NMPC -> regression -> file.

:func:`identify` runs the stages, timing each:

1. reference runs of the full model on every grid pattern (:mod:`pectoral_gym.scaling.identification.reference`);
2. one NMPC per pattern (:mod:`pectoral_gym.scaling.identification.nmpc`), spread over worker processes
   (:mod:`pectoral_gym.scaling.identification.nmpc_batch`),
   each solution checked against the algebraic oracle; unidentifiable K values
   (forcing near zero, failed reference or solver) are flagged with a reason
   and left out of that K's fit;
3. two closed forms of each K (:mod:`pectoral_gym.scaling.identification.regression`): the lowest-degree
   polynomial chosen by k-fold cross-validation, and the interpolating
   tensor-product cubic spline over (bias, amplitude, 1/ratio); they compete
   on seeded off-grid held-out patterns, where each form's predicted steady
   turning radius and period are compared with the full model's, and the
   smaller form that meets the turning target wins (else the more accurate);
4. a :class:`~pectoral_gym.model.kfunctions.ScalingFunctions` with full provenance
   in its metadata, ready to be saved where the averaged model reads it.
"""

from __future__ import annotations

import dataclasses
import math
import platform
import time
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from typing import Any

import numpy as np

from pectoral_gym.model.kfunctions import FEATURES, FORMAT, K_NAMES, ScalingFunctions
from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.identification.grids import Grid, draw_off_grid
from pectoral_gym.scaling.identification.nmpc import (
    IdentificationNmpcSettings,
    NmpcResult,
    algebraic_scaling,
    auto_substeps,
    unscaled_forcing,
)
from pectoral_gym.scaling.identification.nmpc_batch import solve_nmpc_batch
from pectoral_gym.scaling.identification.reference import ReferenceRuns, reference_runs
from pectoral_gym.scaling.identification.regression import (
    Fit,
    SplineFit,
    fit_oscillation,
    fit_spline,
    select_model,
)
from pectoral_gym.scaling.identification.response import predicted_turning, sensitivity_weights

__all__ = ["IdentificationResult", "holdout_patterns", "identify"]

YAW_DAMPING = ("oscillation", "paper")
SWAY = "base"  # K_fy multiplies the fin's force magnitude, not f_hy_avg = base cos(bias) (model.kfunctions)
ORACLE_RTOL = 1e-3  # NMPC solutions must equal the algebraic steady-state solution to this relative tolerance
MIN_TURN_RATE = 0.02  # rad/s: held-out patterns turning slower get no radius / period error (huge, meaningless radii)
FORCING_RTOL = 0.1  # a forcing term below this fraction of its pattern's largest possible value is "near zero"


@dataclass
class IdentificationResult:
    """Everything the pipeline produced.

    Attributes:
        grid: The grid.
        reference: Full-model steady states.
        forcing: ``(n, 3)`` unscaled averaged forcing per pattern.
        k_nmpc: ``(n, 3)`` NMPC solutions (NaN on failure).
        k_oracle: ``(n, 3)`` algebraic solutions.
        usable: ``(n, 3)`` whether each K value entered its fit.
        flags: ``[{"pattern": i, "K": name, "reason": text}]``.
        fits: The cross-validated polynomial per K.
        candidates: All candidate polynomials per K.
        scaling: The identified scaling functions (the chosen form).
        timings: Seconds per stage.
        splines: The interpolating spline per K (empty if the grid is not a tensor grid).
        chosen: ``"polynomial"`` or ``"spline"``.
        comparison: Size and held-out turning errors of each form.
    """

    grid: Grid
    reference: ReferenceRuns
    forcing: np.ndarray
    k_nmpc: np.ndarray
    k_oracle: np.ndarray
    usable: np.ndarray
    flags: list[dict]
    fits: dict[str, Fit]
    candidates: dict[str, list[Fit]]
    scaling: ScalingFunctions
    timings: dict[str, float] = field(default_factory=dict)
    splines: dict[str, SplineFit] = field(default_factory=dict)
    chosen: str = "polynomial"
    comparison: dict[str, dict] = field(default_factory=dict)


def _flag(
    ref: ReferenceRuns, forcing: np.ndarray, k_nmpc: np.ndarray, k_oracle: np.ndarray,
    results: list[NmpcResult], params: FishParams,
) -> tuple[np.ndarray, list[dict]]:
    n = len(ref)
    usable = np.ones((n, 3), dtype=bool)
    flags: list[dict] = []

    def flag(i: int, which: int, reason: str) -> None:
        if usable[i, which]:
            usable[i, which] = False
            flags.append({"pattern": int(i), "K": K_NAMES[which], "reason": reason})

    # Largest possible magnitude of each forcing term at the pattern's amplitude, period and ratio:
    # |fx| <= base and |tau| <= C_p base; the sway term is base itself ("base" sway convention).
    base = np.abs(forcing[:, 1])
    scale = np.column_stack([base, base, params.fin_offset * base])
    for i in range(n):
        if not ref.converged[i]:
            for j in range(3):
                flag(i, j, "full model did not reach a periodic steady state")
        if base[i] == 0.0:
            for j in range(3):
                flag(i, j, "no forcing (amplitude 0 or ratio 1): every K is unidentifiable")
        for j in range(3):
            if abs(forcing[i, j]) < FORCING_RTOL * scale[i, j]:
                share = abs(forcing[i, j]) / max(scale[i, j], 1e-300)
                flag(i, j, f"{('surge', 'sway', 'yaw')[j]} forcing is {share:.2g} of its largest value "
                     f"(< {FORCING_RTOL}): {K_NAMES[j]} has no effect here")
        r = results[i]
        if not r.success:
            for j in range(3):
                flag(i, j, f"NMPC failed: {r.status}")
            continue
        for j in range(3):
            if usable[i, j]:
                gap = abs(k_nmpc[i, j] - k_oracle[i, j]) / max(abs(k_oracle[i, j]), 1e-12)
                if not gap <= ORACLE_RTOL:
                    flag(i, j, f"NMPC solution differs from the algebraic solution by {gap:.2g} (relative)")
    return usable, flags


def _package_version() -> str:
    try:
        return importlib_metadata.version("pectoral-gym")
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


def holdout_patterns(grid: Grid, n: int, seed: int) -> np.ndarray:
    """``n`` seeded random right-fin patterns inside the grid's box and off its nodes.

    Bias, amplitude and ratio are uniform in the grid's ranges (amplitude and
    ratio above a forcing floor); the period is one of the grid's periods (K
    does not depend on it). Drawn from the stream ``(seed, 1)``, so they differ
    from the validator's patterns for the same seed.
    """
    low, high = grid.bounds()
    low = low.copy()
    low[1] = max(low[1], min(high[1], math.radians(5.0)))
    low[3] = max(low[3], min(high[3], 1.25))
    return draw_off_grid(np.random.default_rng([seed, 1]), n, low, high, grid, np.unique(grid.patterns[:, 2]))


_BASIS_MULTIPLICATIONS = 18  # kfunctions.bspline_basis: 6 divisions and 12 products per axis


def _evaluation_multiplications(form: str, per_k: dict) -> int:
    """Multiplications (and divisions) of one evaluation of all three K in the averaged model's kernel.

    Spline: the basis values on three axes, 16 + 64 weight products, then 64
    coefficient products per K. Polynomial: per monomial its total degree plus
    the coefficient.
    """
    if form == "spline":
        return 3 * _BASIS_MULTIPLICATIONS + 16 + 64 + 3 * 64
    return int(sum(np.sum(f.powers) + len(f.coefs) for f in per_k.values()))


def _turning_errors(pred: np.ndarray, ref: ReferenceRuns) -> dict[str, float]:
    """Median and worst relative radius and period errors over the turning held-out patterns."""
    turning = np.abs(ref.velocities[:, 2]) >= MIN_TURN_RATE
    errors = np.abs(pred / np.column_stack([ref.radius, ref.turn_period]) - 1.0)[turning]
    solved = np.all(np.isfinite(errors), axis=1)
    errors = np.where(solved[:, None], errors, np.inf)  # no equilibrium on the full model's branch: a miss
    return {
        "patterns": int(turning.sum()),
        "unsolved": int((~solved).sum()),
        "radius_median": float(np.median(errors[:, 0])) if errors.size else math.nan,
        "radius_worst": float(np.max(errors[:, 0], initial=0.0)),
        "period_median": float(np.median(errors[:, 1])) if errors.size else math.nan,
        "period_worst": float(np.max(errors[:, 1], initial=0.0)),
    }


def identify(
    grid: Grid,
    params: FishParams | None = None,
    settings: IdentificationNmpcSettings | None = None,
    max_degree: int = 7,
    folds: int = 5,
    seed: int = 0,
    jobs: int = 0,
    progress: bool = True,
    fit_target: float = 2e-3,
    holdout: int = 60,
    turn_target: float = 0.02,
    yaw_damping: str = "oscillation",
) -> IdentificationResult:
    """Run the whole pipeline on ``grid`` (module docstring).

    Args:
        grid: Right-fin patterns to identify on.
        params: Model parameters (Table 1 defaults if ``None``).
        settings: NMPC settings (the paper's defaults if ``None``).
        max_degree: Highest polynomial degree tried.
        folds: Cross-validation folds.
        seed: Seed of the CV fold shuffle and of the held-out patterns.
        jobs: NMPC worker processes (0: all cores).
        progress: Show progress bars.
        fit_target: Accuracy a polynomial must reach in cross-validation
            (predicted relative speed / yaw-rate error), see
            :func:`pectoral_gym.scaling.identification.regression.select_model`.
        holdout: Random off-grid patterns on which the closed forms compete (0: polynomials only).
        turn_target: Worst held-out turning radius / period error a form must reach to count as fitting.
        yaw_damping: ``"oscillation"`` (default): identify K for the averaged model with the
            oscillation-averaged yaw damping, whose yaw-oscillation splines are fitted from the
            reference runs and shipped in the file (needs a tensor grid); ``"paper"``: the paper's
            damping ``c4 omega|omega|``.

    Raises:
        ValueError: For an unknown ``yaw_damping``, or ``"oscillation"`` on a grid that is not a tensor grid.
    """
    if yaw_damping not in YAW_DAMPING:
        raise ValueError(f"yaw_damping must be one of {YAW_DAMPING}, got {yaw_damping!r}")
    params = params or FishParams()
    settings = settings or IdentificationNmpcSettings()
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    ref = reference_runs(grid.patterns, params, progress=progress)
    held = reference_runs(holdout_patterns(grid, holdout, seed), params, progress=False) if holdout else None
    timings["reference_runs"] = time.perf_counter() - t0

    osc_knots, osc_table, oscillation, held_oscillation = (), None, None, None
    if yaw_damping == "oscillation":
        try:
            osc_knots, osc_table = fit_oscillation(grid.patterns, ref.yaw_oscillation, ref.yaw_phase, ref.converged)
        except ValueError as err:
            raise ValueError(f"the oscillation-averaged yaw damping needs a tensor grid ({err}); "
                             "use yaw_damping='paper' (--yaw-damping paper)") from None
        # The averaged model will use the spline's amplitude, so K is identified with it too.
        oscillator = ScalingFunctions.unit()
        oscillator = dataclasses.replace(oscillator, oscillation_knots=osc_knots, oscillation_table=osc_table)
        oscillation = np.array([oscillator.yaw_oscillation(*p)[0] for p in grid.patterns])
        if held is not None:
            held_oscillation = np.array([oscillator.yaw_oscillation(*p)[0] for p in held.patterns])

    t0 = time.perf_counter()
    forcing = unscaled_forcing(grid.patterns, params, sway=SWAY)
    k_oracle = algebraic_scaling(ref.velocities, forcing, params, oscillation)
    results = solve_nmpc_batch(ref.velocities, forcing, params, settings, jobs, progress, oscillation)
    k_nmpc = np.array([r.k for r in results])
    substeps = settings.substeps or auto_substeps(ref.velocities, params, settings.sampling, oscillation)
    timings["nmpc"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    usable, flags = _flag(ref, forcing, k_nmpc, k_oracle, results, params)
    weights = sensitivity_weights(ref.velocities, forcing, params, oscillation=oscillation)
    fits, candidates, splines = {}, {}, {}
    for j, name in enumerate(K_NAMES):
        rows = usable[:, j]
        if rows.sum() < 2:
            raise RuntimeError(f"only {int(rows.sum())} usable values of {name}; cannot fit (see the flags)")
        fits[name], candidates[name] = select_model(
            grid.patterns[rows], k_nmpc[rows, j], weights[rows, j], max_degree, folds=folds, seed=seed,
            target=fit_target,
        )
        try:
            splines[name] = fit_spline(grid.patterns, k_nmpc[:, j], usable[:, j], fill=fits[name].predict)
        except ValueError as err:  # not a tensor grid, or too few nodes: polynomials only
            splines[name] = None
            spline_reason = str(err)
    forms = {"polynomial": {name: fits[name] for name in K_NAMES}}
    if all(splines.values()):
        forms["spline"] = splines
    comparison: dict[str, dict] = {}
    for form, per_k in forms.items():
        size = sum(f.table.size if form == "spline" else len(f.coefs) for f in per_k.values())
        entry: dict[str, Any] = {"coefficients": int(size), "multiplications": _evaluation_multiplications(form, per_k)}
        if held is not None:
            k_pred = np.column_stack([per_k[name].predict(held.patterns) for name in K_NAMES])
            held_forcing = unscaled_forcing(held.patterns, params, sway=SWAY)
            entry.update(_turning_errors(
                predicted_turning(held.velocities, held_forcing, k_pred, params, held_oscillation), held))
        comparison[form] = entry

    def fits_target(entry: dict) -> bool:
        return max(entry.get("radius_worst", math.inf), entry.get("period_worst", math.inf)) <= turn_target

    meeting = [f for f in forms if fits_target(comparison[f])]
    if held is None:
        chosen = "polynomial"
    elif meeting:
        # the averaged model evaluates K at every fin latch, inside its batched kernels: cheapest first
        chosen = min(meeting, key=lambda f: (comparison[f]["multiplications"], comparison[f]["coefficients"]))
    else:
        chosen = min(forms, key=lambda f: max(comparison[f]["radius_worst"], comparison[f]["period_worst"]))
    timings["regression"] = time.perf_counter() - t0

    if chosen == "spline":
        powers, coefs = np.zeros((3, 1, len(FEATURES))), np.zeros((3, 1))
        knots = splines[K_NAMES[0]].knots
        table = np.array([splines[name].table for name in K_NAMES])
    else:
        n_terms = max(len(f.coefs) for f in fits.values())
        powers = np.zeros((3, n_terms, len(FEATURES)))
        coefs = np.zeros((3, n_terms))
        for j, name in enumerate(K_NAMES):
            powers[j, : len(fits[name].coefs)] = fits[name].powers
            coefs[j, : len(fits[name].coefs)] = fits[name].coefs
        knots, table = (), None
    deg = grid.patterns.copy()
    deg[:, :2] = np.degrees(deg[:, :2])
    meta = {
        "status": "identified",
        "format": FORMAT,
        "package_version": _package_version(),
        "python": platform.python_version(),
        "method": "full-model steady states, NMPC per pattern (paper Sec. 4.3), closed form chosen on held-out "
                  "patterns between cross-validated polynomials and tensor-product cubic splines",
        "sway": f"{SWAY}: K_fy multiplies the fin's averaged force magnitude (the paper's K_fy cos(bias))",
        "yaw_damping": {
            "oscillation": "oscillation: the mean of c4 omega|omega| over the in-beat yaw oscillation (beyond the "
                           "paper); its phasor A T_p (cos phi, sin phi) interpolated from the reference runs",
            "paper": "paper: c4 omega|omega| (eq. 20)"}[yaw_damping],
        "grid": grid.to_dict(),
        "model_parameters": dataclasses.asdict(params),
        "nmpc": {**settings.as_dict(), "rk4_substeps": substeps, "oracle_rtol": ORACLE_RTOL},
        "regression": {
            "chosen": chosen,
            "selection": f"of the forms whose worst held-out turning radius and period errors are <= {turn_target}, "
                         "the one with the fewest multiplications per evaluation (then coefficients); else the one "
                         "with the smallest worst error",
            "turn_target": turn_target,
            "holdout": {"patterns": holdout, "seed": [seed, 1],
                        "comparison": {form: {k: (v if math.isfinite(v) else None) for k, v in c.items()}
                                       for form, c in comparison.items()}},
            "polynomial": {
                "max_degree": max_degree,
                "folds": folds,
                "seed": seed,
                "selection": "fewest terms with CV error <= target, else within one standard error of the best",
                "target": fit_target,
                "weights": ("relative speed / yaw-rate error per unit K error "
                            "(pectoral_gym.scaling.identification.response.sensitivity_weights)"),
                "fits": {name: fits[name].summary() for name in K_NAMES},
            },
            "spline": ({name: splines[name].summary() for name in K_NAMES} if "spline" in forms
                       else {"unavailable": spline_reason}),
        },
        "flags": {"count": len(flags), "by_K": {n: int((~usable[:, j]).sum()) for j, n in enumerate(K_NAMES)}},
        "oracle_max_relative_gap": {
            name: float(np.nanmax(np.abs(k_nmpc[usable[:, j], j] - k_oracle[usable[:, j], j])
                                  / np.abs(k_oracle[usable[:, j], j]), initial=0.0))
            for j, name in enumerate(K_NAMES)
        },
        "timings_s": timings,
        "data": {
            "columns": ["bias_deg", "amplitude_deg", "period_s", "ratio", *K_NAMES, *(f"usable_{n}" for n in K_NAMES),
                        "yaw_oscillation_rad_s", "yaw_phase_rad"],
            "rows": [[None if not math.isfinite(v) else v for v in row]
                     for row in np.column_stack([deg, k_nmpc, usable.astype(float), ref.yaw_oscillation,
                                                 ref.yaw_phase]).round(10).tolist()],
        },
    }
    scaling = ScalingFunctions(powers, coefs, meta, knots, table, SWAY, osc_knots, osc_table)
    return IdentificationResult(grid, ref, forcing, k_nmpc, k_oracle, usable, flags, fits, candidates, scaling,
                                timings, splines if "spline" in forms else {}, chosen, comparison)
