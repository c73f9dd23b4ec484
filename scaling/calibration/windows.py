"""The logged poses cut into shooting windows, with each window's starting state estimated from the poses.

A 40 s open-loop run diverges long before a wrong parameter shows cleanly (a small heading error turns
into metres), so the fit compares the model with the camera over short windows, each re-initialised
from the observed poses (windowed shooting): the start of each window, ``X, Y, psi, vx, vy, omega``, is
a nuisance parameter of the fit, started from a local quadratic fit to the window's first poses. Frames
lost by the camera simply leave no residual; nothing is interpolated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pectoral_gym.runlog import Episode, RunLog
from pectoral_gym.scaling.calibration.replay import FinTrack, replay_fins

__all__ = ["LogWindows", "initial_state", "noise_levels", "split_windows"]

_MIN_SAMPLES = 8  # a window with fewer poses is dropped (it says little and still costs six nuisances)
_START_FIT = 0.5  # s of poses of the local fit that estimates a window's starting state


@dataclass
class LogWindows:
    """One log, cut into windows.

    Attributes:
        log: The run log.
        track: Its replayed fins (:func:`~pectoral_gym.scaling.calibration.replay.replay_fins`).
        window_t: ``(w,)`` window start times [s] (the first pose of each window).
        starts: ``(w, 6)`` first estimates of each window's starting state (m, m, rad, m/s, m/s, rad/s).
        sample_t: ``(s,)`` pose times [s].
        sample_window: ``(s,)`` the window of each pose.
        observed: ``(s, 3)`` observed ``X, Y, psi`` (psi unwrapped along each episode).
        weight: ``(s,)`` the poses' confidence.
        sigma: ``(3,)`` the camera noise of ``X, Y, psi`` estimated from the poses (m, m, rad).
    """

    log: RunLog
    track: FinTrack
    window_t: np.ndarray
    starts: np.ndarray
    sample_t: np.ndarray
    sample_window: np.ndarray
    observed: np.ndarray
    weight: np.ndarray
    sigma: np.ndarray


def noise_levels(episodes: list[Episode], fps_gap: float = 0.05) -> np.ndarray:
    """Camera noise ``(sigma_X, sigma_Y, sigma_psi)`` from second differences of consecutive poses (m, m, rad).

    For white noise of variance ``s^2`` a second difference of three equally spaced poses has variance
    ``6 s^2``; the motion itself adds ``a dt^2`` (a tenth of a millimetre at 30 fps). The median absolute
    deviation keeps outliers out. Only triples with both gaps under ``fps_gap`` s and equal within 10 % count.
    """
    diffs = []
    for ep in episodes:
        t, p = ep.pose_t, np.column_stack([ep.poses[:, :2], np.unwrap(ep.poses[:, 2])])
        if len(t) < 3:
            continue
        g1, g2 = np.diff(t)[:-1], np.diff(t)[1:]
        ok = (g1 < fps_gap) & (g2 < fps_gap) & (np.abs(g1 - g2) < 0.1 * g1)
        diffs.append((p[2:] - 2.0 * p[1:-1] + p[:-2])[ok])
    d = np.concatenate(diffs) if diffs else np.zeros((0, 3))
    if len(d) < 10:
        return np.array([0.002, 0.002, math.radians(1.0)])  # too few frames to tell: a typical camera
    mad = 1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return np.maximum(mad / math.sqrt(6.0), [1e-4, 1e-4, math.radians(0.05)])


def initial_state(t: np.ndarray, poses: np.ndarray, t0: float) -> np.ndarray:
    """``X, Y, psi, vx, vy, omega`` at ``t0`` from a quadratic fit to ``poses`` ``(k, 3)`` (psi unwrapped)."""
    tau = t - t0
    degree = 2 if len(t) >= 6 else 1
    coef = [np.polyfit(tau, poses[:, j], degree) for j in range(3)]
    x, y, psi = (np.polyval(c, 0.0) for c in coef)
    dx, dy, dpsi = (c[-2] for c in coef)
    c, s = math.cos(psi), math.sin(psi)
    return np.array([x, y, psi, c * dx + s * dy, -s * dx + c * dy, dpsi])  # world -> body velocities, eq. (19)


def split_windows(log: RunLog, window: float, track: FinTrack | None = None,
                  horizon: float | None = None) -> LogWindows:
    """Cut each episode of ``log`` into windows of about ``window`` s (the last one takes a short rest).

    Args:
        log: The run log.
        window: Window length [s]; ``math.inf``: one window per episode (open loop).
        track: The log's replayed fins (default: replayed now).
        horizon: Keep only the first ``horizon`` s of each episode (``None``: all).
    """
    track = track if track is not None else replay_fins(log)
    window_t, starts, sample_t, sample_window, observed, weight = [], [], [], [], [], []
    for ep in log.episodes:
        t, poses, conf = ep.pose_t, ep.poses.copy(), ep.confidence
        if horizon is not None:
            keep = t <= t[0] + horizon + 1e-9 if len(t) else t > 0
            t, poses, conf = t[keep], poses[keep], conf[keep]
        if len(t) < _MIN_SAMPLES:
            continue
        poses[:, 2] = np.unwrap(poses[:, 2])
        span = t[-1] - t[0]
        count = max(1, int(round(span / window))) if math.isfinite(window) else 1
        edges = t[0] + span * np.arange(1, count) / count
        label = np.searchsorted(edges, t, side="right")
        for k in range(count):
            rows = np.flatnonzero(label == k)
            if len(rows) < _MIN_SAMPLES:
                continue
            t0 = float(t[rows[0]])
            head = rows[t[rows] <= t0 + _START_FIT]
            head = head if len(head) >= 4 else rows[:4]
            window_t.append(t0)
            starts.append(initial_state(t[head], poses[head], t0))
            sample_window.append(np.full(len(rows), len(window_t) - 1))
            sample_t.append(t[rows])
            observed.append(poses[rows])
            weight.append(conf[rows])
    if not window_t:
        raise ValueError(f"{log.path}: no episode holds {_MIN_SAMPLES} poses or more: nothing to fit")
    return LogWindows(log, track, np.array(window_t), np.array(starts), np.concatenate(sample_t),
                      np.concatenate(sample_window), np.concatenate(observed), np.concatenate(weight),
                      noise_levels(log.episodes))
