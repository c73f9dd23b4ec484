"""Episode trajectories and the metrics computed from them (pure functions), with bootstrap confidence intervals.

Definitions (per episode; ``dt`` is the control period, ``T`` the number of steps):

* ``success``: 1 if the episode ended by reaching the goal (``goal`` task), else 0.
* ``time_to_goal`` [s]: ``T * dt`` of a successful episode (undefined, NaN, otherwise).
* ``path_length`` [m]: sum of the straight segments between the centre-of-mass positions after each step.
* ``tracking_error`` [m]: mean distance to the reference point over the steps (``track`` task).
* ``final_distance`` [m]: distance to the target at the end of the episode.
* ``fin_work`` [J]: fin work, ``sum over steps of sum over fins of mean_fin_power * dt``
  (the environment's ``reward_energy`` term divided by ``-energy_weight``).
* ``mean_fin_power`` [W]: ``fin_work / (T * dt)``.
* ``swept_work`` [J]: the fins' hydrodynamic work over the strokes they actually swept
  (:meth:`pectoral_gym.model.models.FishModel.fin_work`): transitional strokes included, which
  ``fin_work`` (the price of the commanded patterns' regular beats) leaves out; NaN if not recorded.
* ``return``: sum of the rewards.
* ``wall``: 1 if the episode ended at a wall (with ``stop_band``, as the v1 envs: in the stopping band), else 0.

Aggregates are means over episodes (NaN values left out), each with a seeded
percentile-bootstrap confidence interval (``scipy.stats.bootstrap``).
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.stats

__all__ = [
    "METRICS",
    "MetricSummary",
    "Trajectory",
    "bootstrap_ci",
    "episode_metrics",
    "path_length",
    "summarize",
    "time_to_goal",
    "tracking_error",
]

# scipy >= 1.15 takes the generator as ``rng``, older versions as ``random_state``
_RNG_ARG = "rng" if "rng" in inspect.signature(scipy.stats.bootstrap).parameters else "random_state"

METRICS = {
    "goal": ("success", "time_to_goal", "path_length", "final_distance", "fin_work", "mean_fin_power", "swept_work",
             "return", "wall", "length"),
    "track": ("tracking_error", "path_length", "final_distance", "fin_work", "mean_fin_power", "swept_work", "return",
              "wall", "length"),
}


@dataclass
class Trajectory:
    """One episode, sampled after the reset and after every step.

    Attributes:
        xy: ``(T+1, 2)`` centre-of-mass positions in the tank frame [m].
        psi: ``(T+1,)`` headings [rad].
        target: ``(T+1, 2)`` target (or reference point) positions [m].
        distance: ``(T+1,)`` distances to the target [m].
        reward: ``(T,)`` rewards.
        fin_work: ``(T,)`` fin work of each step [J].
        control_period: Time per step [s].
        success: The goal was reached.
        wall: The episode ended at a wall.
        truncated: The episode hit the step limit.
        seed: The reset seed of the episode.
        swept_work: ``(T,)`` the fins' work over the strokes swept in each step [J], or ``None``.
    """

    xy: np.ndarray
    psi: np.ndarray
    target: np.ndarray
    distance: np.ndarray
    reward: np.ndarray
    fin_work: np.ndarray
    control_period: float
    success: bool = False
    wall: bool = False
    truncated: bool = False
    seed: int | None = None
    extra: dict = field(default_factory=dict)
    swept_work: np.ndarray | None = None

    @property
    def steps(self) -> int:
        """Number of steps ``T``."""
        return int(len(self.reward))

    @property
    def duration(self) -> float:
        """Episode duration ``T * dt`` [s]."""
        return self.steps * self.control_period


def path_length(xy: np.ndarray) -> float:
    """Length of the polyline through the positions ``(T+1, 2)`` [m]."""
    xy = np.asarray(xy, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"positions must have shape (T+1, 2), got {xy.shape}")
    if len(xy) < 2:
        return 0.0
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


def time_to_goal(trajectory: Trajectory) -> float:
    """Duration of a successful episode [s]; NaN if the goal was not reached."""
    return trajectory.duration if trajectory.success else math.nan


def tracking_error(distance: np.ndarray) -> float:
    """Mean distance to the reference over the steps (the samples after each step, not the reset) [m]."""
    distance = np.asarray(distance, dtype=float)
    return float(np.mean(distance[1:])) if len(distance) > 1 else math.nan


def episode_metrics(trajectory: Trajectory, task: str) -> dict[str, float]:
    """All metrics of one episode for ``task`` (``"goal"`` or ``"track"``), as in the module docstring."""
    if task not in METRICS:
        raise ValueError(f"task must be one of {tuple(METRICS)}, got {task!r}")
    work = float(np.sum(trajectory.fin_work))
    values = {
        "path_length": path_length(trajectory.xy),
        "final_distance": float(trajectory.distance[-1]),
        "fin_work": work,
        "mean_fin_power": work / trajectory.duration if trajectory.steps else math.nan,
        "swept_work": math.nan if trajectory.swept_work is None else float(np.sum(trajectory.swept_work)),
        "return": float(np.sum(trajectory.reward)),
        "wall": float(trajectory.wall),
        "length": float(trajectory.steps),
    }
    if task == "goal":
        values["success"] = float(trajectory.success)
        values["time_to_goal"] = time_to_goal(trajectory)
    else:
        values["tracking_error"] = tracking_error(trajectory.distance)
    return {name: values[name] for name in METRICS[task]}


def bootstrap_ci(values: np.ndarray, confidence: float = 0.95, n_resamples: int = 2000,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of the mean (NaN values left out), ``scipy.stats.bootstrap``.

    The resamples are ``n_resamples`` draws of ``len(values)`` indices from ``np.random.default_rng(seed)``;
    the interval is the ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` quantiles of their means.

    Args:
        values: Sample.
        confidence: Confidence level in (0, 1).
        n_resamples: Bootstrap resamples.
        seed: Seed of the resampling generator (same seed, same interval).

    Returns:
        ``(low, high)``; ``(nan, nan)`` for an empty sample, ``(v, v)`` for a single value.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if n_resamples < 1:
        raise ValueError(f"n_resamples must be >= 1, got {n_resamples}")
    x = np.asarray(values, dtype=float).ravel()
    x = x[~np.isnan(x)]
    if x.size == 0:
        return math.nan, math.nan
    if x.size == 1:
        return float(x[0]), float(x[0])
    generator = {_RNG_ARG: np.random.default_rng(seed)}
    result = scipy.stats.bootstrap((x,), np.mean, n_resamples=n_resamples, confidence_level=confidence,
                                   method="percentile", vectorized=True, **generator)
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


@dataclass(frozen=True)
class MetricSummary:
    """Mean of a metric over episodes with its bootstrap confidence interval.

    Attributes:
        mean: Mean over the episodes where the metric is defined.
        low: Lower end of the confidence interval.
        high: Upper end.
        n: Number of episodes where the metric is defined.
    """

    mean: float
    low: float
    high: float
    n: int

    def as_dict(self) -> dict[str, float | int | None]:
        """JSON-ready dict (NaN becomes ``None``)."""
        def clean(v: float) -> float | None:
            return None if math.isnan(v) else float(v)

        return {"mean": clean(self.mean), "ci_low": clean(self.low), "ci_high": clean(self.high), "n": self.n}


def summarize(values: np.ndarray, confidence: float = 0.95, seed: int = 0) -> MetricSummary:
    """Mean and bootstrap interval of ``values`` (NaN values left out)."""
    x = np.asarray(values, dtype=float).ravel()
    x = x[~np.isnan(x)]
    mean = float(x.mean()) if x.size else math.nan
    low, high = bootstrap_ci(x, confidence=confidence, seed=seed)
    return MetricSummary(mean, low, high, int(x.size))
