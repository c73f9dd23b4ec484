"""The liveness check's fish-model predictions over replayed fins, several replays and starts in one batch.

:class:`pectoral_gym.hardware.safety.liveness.LivenessWatch` predicts, for each replay of the fins (a shadow's
snapshots, :class:`pectoral_gym.hardware.safety.shadow_fins.ShadowFins`), the motion by the averaged and the
blade-element model from the least-squares line's start, and the blade-element model's end position from a state
fitted to the poses. The models advance every fish on its own (the same compiled step, the same substeps, whatever
the others do), so fish that are advanced in the same segments can share one model: each fish's path is then,
float for float, the one a model of it alone gives.
:class:`Predictions` batches what has the same segments: the fitted start's path and its finite-difference
paths, and the replays whose snapshots fall at the same instants.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from pectoral_gym.model.models import AveragedModel, FishModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.segment_runs import run_schedule
from pectoral_gym.model.spec import FULL_REFERENCE

__all__ = ["Predictions", "SnapshotArrays", "batches", "fit_line", "paths", "stack"]

#: Finite-difference steps of the fitted start's velocities ``(index in the state, step)`` [m/s, m/s, rad/s]: a
#: fraction of the speeds met.
VELOCITY_STEPS = ((3, 0.005), (4, 0.005), (5, 0.02))
_PATHS_PER_START = 1 + len(VELOCITY_STEPS)  # a Gauss-Newton step's path and its finite-difference paths

Snapshot = tuple[float, np.ndarray, np.ndarray]  # (t [s], fins (rows, 2, fields), pending (rows, 2, 4))


def fit_line(poses: np.ndarray, at: float) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares line through ``(t, X, Y, psi)`` rows: ``(X, Y, psi)`` at ``at`` and the rates."""
    t = poses[:, 0] - at
    if len(poses) < 2 or np.ptp(t) <= 0:
        return poses[:, 1:4].mean(axis=0), np.zeros(3)
    design = np.stack([np.ones_like(t), t], axis=1)
    coef, *_ = np.linalg.lstsq(design, poses[:, 1:4], rcond=None)
    return coef[0], coef[1]


def line_state(poses: np.ndarray, at: float, line: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The state ``(X, Y, psi, u, v, r)`` at ``at`` [s] of the line through ``poses`` (body-frame velocities).

    ``line``: ``fit_line(poses, at)`` if the caller has it already.
    """
    pose, rates = fit_line(poses, at) if line is None else line
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([*pose, c * rates[0] + s * rates[1], -s * rates[0] + c * rates[1], rates[2]])


class SnapshotArrays(NamedTuple):
    """Snapshots of the fins as arrays: what :func:`paths` takes in one compiled call, stacked once for several."""

    times: np.ndarray  #: ``(K,)`` [s], increasing
    fins: np.ndarray  #: ``(K, rows, 2, FIN_FIELDS)``
    pending: np.ndarray  #: ``(K, rows, 2, 4)``


def paths(snapshots: Sequence[Snapshot] | SnapshotArrays, states: np.ndarray, t_c: float, times: Sequence[float],
          model: FishModel) -> np.ndarray:
    """Poses ``(len(times), n, 3)`` of ``model``'s ``n`` fish from ``states`` ``(n, 6)`` at ``t_c`` [s].

    ``times`` increase. The fins are set from ``snapshots`` (one every 0.05 s, the fins of one fish, or of groups
    of ``n // rows`` consecutive fish); every fish is advanced in the same segments, to each snapshot and each
    of ``times``, in one compiled call (:func:`pectoral_gym.model.segment_runs.run_schedule`): the same advances
    as one model call per segment, bit for bit.
    """
    # model.reset(states) but the fins, which the kernel sets from the first snapshot, every field
    model.state[:] = states
    model.integral[:] = 0.0
    model.forcing_cache[:] = 0.0
    if not isinstance(snapshots, SnapshotArrays):
        snapshots = stack(snapshots)
    # the snapshots are in time order: the last one at or before t_c, to the last one at or before times[-1]
    last = int(np.searchsorted(snapshots.times, times[-1], side="right"))
    first = int(np.searchsorted(snapshots.times[:last], t_c, side="right")) - 1
    if first < 0:
        raise ValueError(f"no snapshot at or before t_c = {t_c} s")
    return run_schedule(model, snapshots.times[first:last], snapshots.fins[first:last],
                        snapshots.pending[first:last], t_c, np.array(times, dtype=float))


def stack(snapshots: Sequence[Snapshot]) -> SnapshotArrays:
    """``snapshots`` (in time order, all of the same rows) as arrays."""
    return SnapshotArrays(np.array([s[0] for s in snapshots], dtype=float), np.array([s[1] for s in snapshots]),
                          np.array([s[2] for s in snapshots]))


def _instant(snapshot: Snapshot) -> float:
    return snapshot[0]


def batches(views: Sequence[Sequence[Snapshot]], since: float,
            until: float) -> list[tuple[list[int], Sequence[Snapshot] | SnapshotArrays]]:
    """The views (replays' snapshots) grouped by the instants of their snapshots in ``[since, until]`` [s].

    Each group is ``(indices into views, snapshots)``, its snapshots (:class:`SnapshotArrays`) those of the span
    (from the last one at or before ``since`` to the last one at or before ``until``) with the fins and pendings of
    its views stacked in its order: for any start at or after ``since`` and times up to ``until`` they give every
    view the segments its own snapshots give. A view with no snapshot at or before ``since`` is a group of its own,
    whole (its list).
    """
    groups: dict[tuple[float, ...], list[int]] = {}
    spans: dict[int, list] = {}
    alone: list[tuple[list[int], list]] = []
    for index, view in enumerate(views):
        view = view if isinstance(view, list) else list(view)
        first = bisect.bisect_right(view, since, key=_instant) - 1  # in time order: the last one at or before since
        if first < 0:
            alone.append(([index], list(view)))
            continue
        span = view[first:bisect.bisect_right(view, until, lo=first, key=_instant)]
        spans[index] = span
        groups.setdefault(tuple(s[0] for s in span), []).append(index)
    out: list[tuple[list[int], Sequence[Snapshot] | SnapshotArrays]] = []
    for indices in groups.values():
        members = [spans[i] for i in indices]
        # per snapshot, the members' fins one after the other: each member's stacked, joined along the rows
        fins, pending = (_joined([np.array([s[field] for s in m]) for m in members]) for field in (1, 2))
        out.append((indices, SnapshotArrays(np.array([s[0] for s in members[0]], dtype=float), fins, pending)))
    return out + alone


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    """``parts`` ``(K, rows, ...)`` joined along the rows (a lone part as it is)."""
    return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)


class Predictions:
    """The models the liveness check predicts with, one of each kind per batch size, built once.

    Args:
        params: The fish's parameters.
        views: The most replays predicted together.
    """

    def __init__(self, params: FishParams, views: int):
        self._full = {n: FULL_REFERENCE.build(n, params) for k in range(1, views + 1)
                      for n in (k, _PATHS_PER_START * k)}
        self._averaged = {n: AveragedModel(n=n, params=params) for n in range(1, views + 1)}

    def warm_up(self, snapshots: Sequence[Snapshot] | SnapshotArrays) -> None:
        """Compile or load the models' kernels now (``snapshots``: at least 0 to 0.4 s)."""
        start = np.array([[1.0, 0.5, 0.0, 0.01, 0.0, 0.0]])
        for model in (*self._full.values(), *self._averaged.values()):
            paths(snapshots, np.repeat(start, model.n, axis=0), 0.05, (0.2, 0.4), model)

    def motion(self, snapshots: Sequence[Snapshot] | SnapshotArrays, views: int, start: np.ndarray, t_c: float,
               times: Sequence[float], blade_element: bool = False) -> np.ndarray:
        """The averaged (or blade-element) model's poses ``(len(times), views, 3)`` from ``start`` ``(6,)`` at ``t_c``.

        ``t_c`` and ``times`` in s. The blade-element model evaluates the fins' forces from their angle and rate at
        every instant (the paper's eqs. 1-20), so a lone transitional half-stroke (a jump of the bias at zero
        amplitude) pushes the fish by what that one sweep gives; the averaged model spreads a stroke's forcing
        over it as a beat's.
        """
        model = self._full[views] if blade_element else self._averaged[views]
        return paths(snapshots, np.repeat(start[None], views, axis=0), t_c, times, model)

    def fitted(self, snapshots: Sequence[Snapshot] | SnapshotArrays, views: int, before: np.ndarray, reach: float,
               times: Sequence[float]) -> np.ndarray:
        """Poses ``(len(times), views, 3)`` of the blade-element model started in the state that fits ``before``.

        Per view: the state ``(X, Y, psi, u, v, r)`` at ``t_s`` (``before``'s first row) is the least-squares fit
        of the model's path, driven by the view's replayed fins, to ``before``'s poses (positions, and headings
        times ``reach`` [m]): two Gauss-Newton steps from the line through them. A line's slope is the window's
        mean velocity; the fish's own velocity surges with every stroke, and the path the fins drive is what the
        fins' forces give from the instantaneous one. The position and heading derivatives are exact (the
        dynamics do not depend on where the fish is or where it points: a shift moves the path, a turn rotates
        it about the start); the velocity ones are finite differences. The views' steps are taken together.
        """
        t_s, fit_times = float(before[0, 0]), tuple(float(t) for t in before[:, 0])
        states = np.repeat(line_state(before, t_s)[None], views, axis=0)
        target = before[:, 1:4] * np.array([1.0, 1.0, reach])
        going = [True] * views  # a view whose step is not finite keeps its state
        for _ in range(2):
            starts = np.repeat(states, _PATHS_PER_START, axis=0)
            for row, (j, h) in enumerate(VELOCITY_STEPS, start=1):
                starts[row::_PATHS_PER_START, j] += h
            scaled = paths(snapshots, starts, t_s, fit_times, self._full[_PATHS_PER_START * views]) * \
                np.array([1.0, 1.0, reach])
            for view in range(views):
                if not going[view]:
                    continue
                state, block = states[view], scaled[:, _PATHS_PER_START * view:_PATHS_PER_START * (view + 1)]
                base = block[:, 0]
                jac = np.zeros((len(before), 3, 6))
                jac[:, 0, 0] = jac[:, 1, 1] = 1.0
                jac[:, 0, 2], jac[:, 1, 2], jac[:, 2, 2] = -(base[:, 1] - state[1]), base[:, 0] - state[0], reach
                for row, (j, h) in enumerate(VELOCITY_STEPS, start=1):
                    jac[:, :, j] = (block[:, row] - base) / h
                step, *_ = np.linalg.lstsq(jac.reshape(-1, 6), (target - base).reshape(-1), rcond=None)
                if not np.all(np.isfinite(step)):
                    going[view] = False
                    continue
                states[view] = state + step
        return paths(snapshots, states, t_s, times, self._full[views])
