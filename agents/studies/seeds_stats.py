"""Statistics across training seeds, as rliable computes them: the interquartile mean and its bootstrap interval.

:func:`iqm` is ``scipy.stats.trim_mean(x, 0.25)``, the mean of the middle half of the seeds; :func:`aggregate`
adds a percentile-bootstrap interval over the seeds (``scipy.stats.bootstrap``) and the mean, min, median and
max. With a handful of seeds the interval is coarse: it can only take values that subsets of these seeds give.
:func:`pectoral_gym.agents.studies.seeds.summarize_seeds` applies them to a seeds run.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.stats

__all__ = ["aggregate", "iqm"]

# bootstrap's generator argument: rng in newer scipy, random_state in older ones.
_RNG_ARG = "rng" if "rng" in inspect.signature(scipy.stats.bootstrap).parameters else "random_state"


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: ``scipy.stats.trim_mean(values, 0.25)`` (NaN values left out; NaN if none)."""
    x = np.asarray(values, dtype=float).ravel()
    x = x[~np.isnan(x)]
    return float(scipy.stats.trim_mean(x, 0.25)) if x.size else float("nan")


def aggregate(values: Sequence[float], confidence: float = 0.95, n_resamples: int = 2000,
              seed: int = 0) -> dict[str, Any]:
    """Across-seed summary of one figure: IQM with its percentile-bootstrap interval, mean, min, median, max.

    Args:
        values: One value per seed (NaN values left out).
        confidence: Level of the interval in (0, 1).
        n_resamples: Bootstrap resamples of the seeds.
        seed: Seed of the resampling generator.

    Returns:
        ``{"n", "iqm", "ci_low", "ci_high", "mean", "min", "median", "max"}`` (``None`` where there is no value).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    x = np.asarray(values, dtype=float).ravel()
    x = x[~np.isnan(x)]
    if x.size == 0:
        return {"n": 0, "iqm": None, "ci_low": None, "ci_high": None, "mean": None, "min": None, "median": None,
                "max": None}
    centre = iqm(x)
    if x.size == 1 or np.ptp(x) == 0.0:
        low = high = centre
    else:
        result = scipy.stats.bootstrap((x,), lambda s, axis=-1: scipy.stats.trim_mean(s, 0.25, axis=axis),
                                       n_resamples=n_resamples, confidence_level=confidence, method="percentile",
                                       vectorized=True, **{_RNG_ARG: np.random.default_rng(seed)})
        low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
    return {"n": int(x.size), "iqm": centre, "ci_low": low, "ci_high": high, "mean": float(x.mean()),
            "min": float(x.min()), "median": float(np.median(x)), "max": float(x.max())}
