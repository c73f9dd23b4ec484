"""pectoral_gym.agents.training.metrics.bootstrap_ci through scipy.stats.bootstrap.

The documented resampling, written out here, and the normal approximation of a large sample.
"""

import numpy as np
import pytest

from pectoral_gym.agents.training.metrics import bootstrap_ci, summarize


def reference_percentile_bootstrap(x, confidence, n_resamples, seed):
    """The definition in bootstrap_ci's docstring, independently of scipy."""
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, len(x), size=(n_resamples, len(x)))].mean(axis=1)
    alpha = (1.0 - confidence) / 2.0
    return tuple(np.quantile(means, [alpha, 1.0 - alpha]))


@pytest.mark.parametrize(("n", "confidence", "n_resamples", "seed"),
                         [(2, 0.95, 2000, 0), (17, 0.9, 500, 3), (100, 0.95, 2000, 11), (250, 0.99, 1000, 5)])
def test_scipy_interval_is_the_documented_percentile_bootstrap(n, confidence, n_resamples, seed):
    sample_rng = np.random.default_rng(100 + n)
    for x in (sample_rng.normal(2.0, 3.0, n), (sample_rng.random(n) < 0.3).astype(float)):
        low, high = bootstrap_ci(x, confidence=confidence, n_resamples=n_resamples, seed=seed)
        ref_low, ref_high = reference_percentile_bootstrap(x, confidence, n_resamples, seed)
        assert low == pytest.approx(ref_low, abs=1e-12) and high == pytest.approx(ref_high, abs=1e-12)


def test_large_sample_matches_the_normal_approximation():
    # mean of n normal values: the interval is close to mean -+ z s / sqrt(n) (z = 1.95996 for 95 %)
    x = np.random.default_rng(1).normal(0.5, 2.0, 4000)
    low, high = bootstrap_ci(x, confidence=0.95, n_resamples=4000, seed=2)
    half = 1.959964 * x.std() / np.sqrt(x.size)
    assert low == pytest.approx(x.mean() - half, abs=0.1 * half)
    assert high == pytest.approx(x.mean() + half, abs=0.1 * half)


def test_summary_fields_and_nan_handling():
    x = np.array([1.0, np.nan, 3.0, 2.0, np.nan, 6.0])
    summary = summarize(x, seed=4)
    assert summary.n == 4 and summary.mean == pytest.approx(3.0)
    assert (summary.low, summary.high) == bootstrap_ci(x[~np.isnan(x)], seed=4)
    assert 1.0 <= summary.low < 3.0 < summary.high <= 6.0
    assert set(summary.as_dict()) == {"mean", "ci_low", "ci_high", "n"}
    assert bootstrap_ci(np.full(5, 0.25)) == (0.25, 0.25)  # every resample has the same mean
