"""The identification pipeline of the paper's Sec. 4.3: grid -> reference runs -> NMPC -> regression -> file.

:func:`identify` runs the stages, timing each:

1. reference runs of the full model on every grid pattern (:mod:`scaling.reference`);
2. one NMPC per pattern (:mod:`scaling.nmpc`), spread over worker processes,
   each solution checked against the algebraic oracle; unidentifiable K values
   (forcing near zero, failed reference or solver) are flagged with a reason
   and left out of that K's fit;
3. the closed form of each K by cross-validated regression (:mod:`scaling.regression`);
4. a :class:`~pectoral_gym.kfunctions.ScalingFunctions` with full provenance
   in its metadata, ready to be saved where the averaged model reads it.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing as mp
import os
import platform
import time
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata

import numpy as np
from tqdm.auto import tqdm

from pectoral_gym.kfunctions import FEATURES, FORMAT, K_NAMES, ScalingFunctions
from pectoral_gym.params import FishParams
from scaling.grids import Grid
from scaling.nmpc import (
    NmpcResult,
    NmpcSettings,
    ScalingNmpc,
    algebraic_scaling,
    auto_substeps,
    unscaled_forcing,
)
from scaling.reference import ReferenceRuns, reference_runs
from scaling.regression import Fit, select_model, sensitivity_weights

__all__ = ["IdentificationResult", "identify", "solve_nmpc_batch"]

ORACLE_RTOL = 1e-3  # NMPC solutions must equal the algebraic steady-state solution to this relative tolerance
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
        fits: The chosen fit per K.
        candidates: All candidate fits per K.
        scaling: The identified scaling functions.
        timings: Seconds per stage.
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


_WORKER: ScalingNmpc | None = None


def _init_worker(params: FishParams, settings: NmpcSettings, velocities: np.ndarray) -> None:
    global _WORKER
    _WORKER = ScalingNmpc(params, settings, velocities)


def _solve_chunk(chunk: list[tuple[int, np.ndarray, np.ndarray]]) -> list[tuple[int, NmpcResult]]:
    out, guess = [], None
    for i, v_ref, forcing in chunk:
        result = _WORKER.solve(v_ref, forcing, guess)  # warm start from the neighbouring pattern
        guess = result.k if result.success and np.all(np.isfinite(result.k)) else None
        out.append((i, result))
    return out


def solve_nmpc_batch(
    velocities: np.ndarray,
    forcing: np.ndarray,
    params: FishParams,
    settings: NmpcSettings,
    jobs: int = 0,
    progress: bool = True,
) -> list[NmpcResult]:
    """One NMPC per pattern, over ``jobs`` processes (0: all cores; 1: in this process)."""
    n = len(velocities)
    jobs = jobs or os.cpu_count() or 1
    tasks = [(i, velocities[i], forcing[i]) for i in range(n) if np.all(np.isfinite(velocities[i]))]
    results: list[NmpcResult | None] = [None] * n
    bar = tqdm(total=n, desc="NMPC per pattern", unit="pattern", disable=not progress)
    size = max(1, min(32, math.ceil(len(tasks) / (4 * jobs))))
    chunks = [tasks[k : k + size] for k in range(0, len(tasks), size)]
    if jobs == 1:
        _init_worker(params, settings, velocities)
        for chunk in chunks:
            for i, r in _solve_chunk(chunk):
                results[i] = r
            bar.update(len(chunk))
    else:
        ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
        with ctx.Pool(jobs, initializer=_init_worker, initargs=(params, settings, velocities)) as pool:
            for done in pool.imap_unordered(_solve_chunk, chunks):
                for i, r in done:
                    results[i] = r
                bar.update(len(done))
    bar.update(n - bar.n)
    bar.close()
    failed = NmpcResult(np.full(3, np.nan), math.nan, False, "no reference (full model did not settle)", math.nan)
    return [r if r is not None else failed for r in results]


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
    # |fx|, |fy| <= base and |tau| <= C_p base, with base = |fx| / sin(bias) = |fy| / |cos(bias)|.
    base = np.hypot(forcing[:, 0], forcing[:, 1])
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


def identify(
    grid: Grid,
    params: FishParams | None = None,
    settings: NmpcSettings | None = None,
    max_degree: int = 7,
    folds: int = 5,
    seed: int = 0,
    jobs: int = 0,
    progress: bool = True,
    fit_target: float = 2e-3,
) -> IdentificationResult:
    """Run the whole pipeline on ``grid`` (module docstring).

    Args:
        grid: Right-fin patterns to identify on.
        params: Model parameters (Table 1 defaults if ``None``).
        settings: NMPC settings (the paper's defaults if ``None``).
        max_degree: Highest polynomial degree tried.
        folds: Cross-validation folds.
        seed: Seed of the CV fold shuffle.
        jobs: NMPC worker processes (0: all cores).
        progress: Show progress bars.
        fit_target: Accuracy a closed form must reach on held-out patterns
            (predicted relative speed / yaw-rate error), see :func:`scaling.regression.select_model`.
    """
    params = params or FishParams()
    settings = settings or NmpcSettings()
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    ref = reference_runs(grid.patterns, params, progress=progress)
    timings["reference_runs"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    forcing = unscaled_forcing(grid.patterns, params)
    k_oracle = algebraic_scaling(ref.velocities, forcing, params)
    results = solve_nmpc_batch(ref.velocities, forcing, params, settings, jobs, progress)
    k_nmpc = np.array([r.k for r in results])
    substeps = settings.substeps or auto_substeps(ref.velocities, params, settings.sampling)
    timings["nmpc"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    usable, flags = _flag(ref, forcing, k_nmpc, k_oracle, results, params)
    weights = sensitivity_weights(ref.velocities, forcing, params)
    fits, candidates = {}, {}
    for j, name in enumerate(K_NAMES):
        rows = usable[:, j]
        if rows.sum() < 2:
            raise RuntimeError(f"only {int(rows.sum())} usable values of {name}; cannot fit (see the flags)")
        fits[name], candidates[name] = select_model(
            grid.patterns[rows], k_nmpc[rows, j], weights[rows, j], max_degree, folds=folds, seed=seed,
            target=fit_target,
        )
    timings["regression"] = time.perf_counter() - t0

    n_terms = max(len(f.coefs) for f in fits.values())
    powers = np.zeros((3, n_terms, len(FEATURES)))
    coefs = np.zeros((3, n_terms))
    for j, name in enumerate(K_NAMES):
        powers[j, : len(fits[name].coefs)] = fits[name].powers
        coefs[j, : len(fits[name].coefs)] = fits[name].coefs
    deg = grid.patterns.copy()
    deg[:, :2] = np.degrees(deg[:, :2])
    meta = {
        "status": "identified",
        "format": FORMAT,
        "package_version": _package_version(),
        "python": platform.python_version(),
        "method": "full-model steady states, NMPC per pattern (paper Sec. 4.3), cross-validated polynomial regression",
        "grid": grid.to_dict(),
        "model_parameters": dataclasses.asdict(params),
        "nmpc": {**settings.as_dict(), "rk4_substeps": substeps, "oracle_rtol": ORACLE_RTOL},
        "regression": {
            "max_degree": max_degree,
            "folds": folds,
            "seed": seed,
            "selection": "fewest terms with CV error <= target, else within one standard error of the best",
            "target": fit_target,
            "weights": "relative speed / yaw-rate error per unit K error (scaling.regression.sensitivity_weights)",
            "fits": {name: fits[name].summary() for name in K_NAMES},
        },
        "flags": {"count": len(flags), "by_K": {n: int((~usable[:, j]).sum()) for j, n in enumerate(K_NAMES)}},
        "oracle_max_relative_gap": {
            name: float(np.nanmax(np.abs(k_nmpc[usable[:, j], j] - k_oracle[usable[:, j], j])
                                  / np.abs(k_oracle[usable[:, j], j]), initial=0.0))
            for j, name in enumerate(K_NAMES)
        },
        "timings_s": timings,
        "data": {
            "columns": ["bias_deg", "amplitude_deg", "period_s", "ratio", *K_NAMES, *(f"usable_{n}" for n in K_NAMES)],
            "rows": [[None if not math.isfinite(v) else v for v in row]
                     for row in np.column_stack([deg, k_nmpc, usable.astype(float)]).round(10).tolist()],
        },
    }
    scaling = ScalingFunctions(powers, coefs, meta)
    return IdentificationResult(grid, ref, forcing, k_nmpc, k_oracle, usable, flags, fits, candidates, scaling, timings)
