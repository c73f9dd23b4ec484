"""The held-out check: the calibrated full model run open loop over logged episodes it was not fitted on.

Each held-out episode is simulated from its starting state under its logged commands, with the fins
replayed by the firmware's rules, for ``horizon`` s (40 s in the held-out
target of docs/calibration.md); the error is the distance between
the simulated and the observed end positions, as a percentage of the observed path length. The path is
measured on the poses averaged over 0.5 s bins, so camera noise does not lengthen it.

The starting state is fitted, with the parameters under test, to the episode's first ``start_fit`` s of
poses (2 s: the shooting fit's own machinery with no free parameter); a quadratic through the first
frames alone leaves a heading error of a few tenths of a degree, which the destabilising Munk moment of
eq. (19) grows into centimetres over 40 s of straight swimming.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import FULL_FAST, FullSpec
from pectoral_gym.runlog import RunLog
from pectoral_gym.scaling.calibration.replay import simulate
from pectoral_gym.scaling.calibration.windows import split_windows

__all__ = ["HeldOutRun", "held_out", "path_length"]


@dataclass
class HeldOutRun:
    """One held-out episode.

    Attributes:
        log: The log's path. episode: The episode's number.
        duration: The simulated span [s] (the episode's, at most the horizon).
        path: Observed path length [m].
        end_error: Distance between simulated and observed end positions [m].
        t: ``(s,)`` pose times [s]. observed: ``(s, 3)`` the camera's poses. simulated: ``(s, 3)`` the model's.
    """

    log: str
    episode: int
    duration: float
    path: float
    end_error: float
    t: np.ndarray
    observed: np.ndarray
    simulated: np.ndarray

    @property
    def error_percent(self) -> float:
        """End-position error as a percentage of the path [%]."""
        return 100.0 * self.end_error / max(self.path, 1e-9)


def path_length(t: np.ndarray, xy: np.ndarray, bin_width: float = 0.5) -> float:
    """Length [m] of the path through the means of the positions ``xy`` ``(s, 2)`` in ``bin_width`` s bins."""
    label = np.floor((t - t[0]) / bin_width).astype(int)
    means = np.array([xy[label == k].mean(axis=0) for k in np.unique(label)])
    return float(np.sum(np.hypot(*np.diff(means, axis=0).T))) if len(means) > 1 else 0.0


def _fitted_starts(params: FishParams, log: RunLog, track, start_fit: float, spec: FullSpec) -> np.ndarray:
    """``(w, 6)`` each episode's starting state fitted to its first ``start_fit`` s of poses with ``params``."""
    from scipy.optimize import least_squares

    from pectoral_gym.scaling.calibration.fit import CalibrationSettings, _Problem

    head = split_windows(log, math.inf, track, horizon=start_fit)
    problem = _Problem([head], params, (), CalibrationSettings(fields=(), spec=spec))
    result = least_squares(problem.fun, problem.x0(), jac=problem.jac, bounds=problem.bounds(), method="trf",
                           loss="soft_l1", f_scale=3.0, x_scale="jac", tr_solver="lsmr", max_nfev=30)
    return result.x.reshape(-1, 6)


def held_out(params: FishParams, logs: Sequence[RunLog], horizon: float = 40.0, min_duration: float | None = None,
             spec: FullSpec = FULL_FAST, start_fit: float = 2.0) -> list[HeldOutRun]:
    """Run ``params`` open loop over each episode of ``logs`` for ``horizon`` s (module docstring).

    Args:
        params: The parameters to check.
        logs: The held-out logs.
        horizon: Open-loop span [s].
        min_duration: Leave out episodes shorter than this [s] (default: ``0.9 * horizon``).
        spec: The full model's integration.
        start_fit: Span of the first poses the starting state is fitted to [s] (0: a quadratic through them).
    """
    min_duration = 0.9 * horizon if min_duration is None else min_duration
    runs = []
    for log in logs:
        lw = split_windows(log, math.inf, horizon=horizon)
        if start_fit > 0:
            lw.starts = _fitted_starts(params, log, lw.track, start_fit, spec)
        sim = simulate(lw.track, [params], lw.window_t, lw.starts[None], lw.sample_t, spec)[0]
        episodes = [ep for ep in log.episodes if len(ep.pose_t) >= 8]
        for w, ep in enumerate(episodes):
            rows = np.flatnonzero(lw.sample_window == w)
            t = lw.sample_t[rows]
            if t[-1] - t[0] < min_duration:
                continue
            end = slice(-3, None)  # three frames at the end: a tenth of a second, against the camera's noise
            error = float(np.hypot(*(sim[rows][end, :2] - lw.observed[rows][end, :2]).mean(axis=0)))
            runs.append(HeldOutRun(log.path, ep.index, float(t[-1] - t[0]), path_length(t, lw.observed[rows, :2]),
                                   error, t, lw.observed[rows], sim[rows]))
    return runs
