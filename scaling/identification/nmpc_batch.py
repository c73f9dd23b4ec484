"""One scaling NMPC per pattern, spread over worker processes.

The NMPC is :class:`pectoral_gym.scaling.identification.nmpc.ScalingNmpc`.

Each worker builds the NMPC problem once and solves its chunk of neighbouring
patterns in order, each warm-started from the previous solution.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os

import numpy as np
from tqdm.auto import tqdm

from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.identification.nmpc import IdentificationNmpcSettings, NmpcResult, ScalingNmpc

__all__ = ["solve_nmpc_batch"]

_WORKER: ScalingNmpc | None = None


def _init_worker(params: FishParams, settings: IdentificationNmpcSettings, velocities: np.ndarray,
                 oscillation: np.ndarray | None) -> None:
    global _WORKER
    _WORKER = ScalingNmpc(params, settings, velocities, oscillation)


def _solve_chunk(chunk: list[tuple[int, np.ndarray, np.ndarray, float]]) -> list[tuple[int, NmpcResult]]:
    out, guess = [], None
    for i, v_ref, forcing, oscillation in chunk:
        result = _WORKER.solve(v_ref, forcing, guess, oscillation)  # warm start from the neighbouring pattern
        guess = result.k if result.success and np.all(np.isfinite(result.k)) else None
        out.append((i, result))
    return out


def solve_nmpc_batch(
    velocities: np.ndarray,
    forcing: np.ndarray,
    params: FishParams,
    settings: IdentificationNmpcSettings,
    jobs: int = 0,
    progress: bool = True,
    oscillation: np.ndarray | None = None,
) -> list[NmpcResult]:
    """One NMPC per pattern, over ``jobs`` processes (0: all cores; 1: in this process).

    ``oscillation``: per-pattern yaw-oscillation amplitudes [rad/s] ``(n,)`` for the
    oscillation-averaged yaw damping; ``None`` for the paper's damping.
    """
    n = len(velocities)
    jobs = jobs or os.cpu_count() or 1
    amplitude = np.zeros(n) if oscillation is None else np.asarray(oscillation, dtype=np.float64)
    tasks = [(i, velocities[i], forcing[i], amplitude[i])
             for i in range(n) if np.all(np.isfinite(velocities[i]))]
    results: list[NmpcResult | None] = [None] * n
    bar = tqdm(total=n, desc="NMPC per pattern", unit="pattern", disable=not progress)
    size = max(1, min(32, math.ceil(len(tasks) / (4 * jobs))))
    chunks = [tasks[k : k + size] for k in range(0, len(tasks), size)]
    if jobs == 1:
        _init_worker(params, settings, velocities, oscillation)
        for chunk in chunks:
            for i, r in _solve_chunk(chunk):
                results[i] = r
            bar.update(len(chunk))
    else:
        ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
        with ctx.Pool(jobs, initializer=_init_worker, initargs=(params, settings, velocities, oscillation)) as pool:
            for done in pool.imap_unordered(_solve_chunk, chunks):
                for i, r in done:
                    results[i] = r
                bar.update(len(done))
    bar.update(n - bar.n)
    bar.close()
    failed = NmpcResult(np.full(3, np.nan), math.nan, False, "no reference (full model did not settle)", math.nan)
    return [r if r is not None else failed for r in results]
