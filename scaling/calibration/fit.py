"""The fit: the uncertain FishParams fields from run logs, by windowed shooting and robust least squares.

Unknowns: the log of each fitted field relative to its prior (Table 1 or the user's value; log-parameters
keep every field's sign and make a relative change the unit; a fin's servo offset, which may be zero, moves
by ``theta`` rad instead: ``identifiability.ADDITIVE_FIELDS``), and per window its starting state (the
nuisances of :mod:`~pectoral_gym.scaling.calibration.windows`). Residuals: the full model's poses minus the
camera's at every logged frame, divided by the camera noise estimated from the poses and weighted by the
frame's confidence; plus a weak Gaussian prior on each log-parameter (``prior_sigma``), which only holds
what the logs leave open. :func:`scipy.optimize.least_squares` (trust-region reflective) minimises them
with a robust loss (``soft_l1``: quadratic inside ``f_scale`` noise standard deviations, so Gaussian noise
is weighted as in plain least squares and bad frames count less).

The Jacobian is formed by forward differences in one batched run per log: candidate fish 1..p move one
log-parameter each, and six more move one starting-state component in every window at once (a window's
start only changes its own poses). Uncertainty: the Jacobian at the optimum, the nuisances eliminated by a
Schur complement, scaled by the residual's variance; its eigen-decomposition names the parameter
combinations the logs cannot tell apart.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares
from scipy.sparse.linalg import lsqr

from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import FULL_FAST, FullSpec
from pectoral_gym.runlog import RunLog
from pectoral_gym.scaling.calibration.covariance import gauss_newton_information, window_sandwich_information
from pectoral_gym.scaling.calibration.identifiability import (
    ADDITIVE_FIELDS,
    UNCERTAIN_FIELDS,
    Identifiability,
    analyse,
)
from pectoral_gym.scaling.calibration.replay import replay_fins, simulate
from pectoral_gym.scaling.calibration.windows import LogWindows, split_windows

__all__ = ["Calibration", "CalibrationSettings", "calibrate"]

_H_THETA = 1e-5  # log-parameter step of the finite differences
_H_START = np.array([1e-5, 1e-5, 1e-5, 1e-5, 1e-5, 1e-4])  # m, m, rad, m/s, m/s, rad/s
_FACTOR = 3.0  # the fit keeps each field within this factor of its prior
_START_RANGE = np.array([0.2, 0.2, 1.0, 0.3, 0.3, 2.0])  # m, m, rad, m/s, m/s, rad/s around the first estimate


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of :func:`calibrate`.

    Attributes:
        fields: The FishParams fields to fit (default: the uncertain ones, :data:`UNCERTAIN_FIELDS`).
        window: Shooting window [s]: long enough for drag and turning to show, short enough that the
            model started from the observed pose stays near the path (40 s open loop does not).
        warmup_window: A first fit on windows this short [s] gives the final fit its start (``None``: none).
        prior_sigma: Standard deviation of the Gaussian prior on each log-parameter (0.3: about +-30 %).
        identified_se: A field counts as identified when the logs alone fix it to this relative
            standard error [-] (the prior excluded).
        spec: The full model's integration (default :data:`~pectoral_gym.model.spec.FULL_FAST`).
        loss: The robust loss of :func:`scipy.optimize.least_squares`.
        f_scale: The loss's soft margin, in noise standard deviations.
        max_nfev: Most residual evaluations.
        covariance: ``"window-sandwich"`` (each standard error the larger of the window sandwich's, robust to
            residuals correlated within a window, and Gauss-Newton's) or ``"gauss-newton"`` (independent frames
            only; :mod:`~pectoral_gym.scaling.calibration.covariance`).
    """

    fields: tuple[str, ...] = UNCERTAIN_FIELDS
    window: float = 6.0
    warmup_window: float | None = None
    prior_sigma: float = 0.3
    identified_se: float = 0.02
    spec: FullSpec = FULL_FAST
    loss: str = "soft_l1"
    f_scale: float = 3.0
    max_nfev: int = 200
    covariance: str = "window-sandwich"


@dataclass
class Calibration:
    """What :func:`calibrate` found.

    Attributes:
        params: The calibrated parameters (the prior's other fields unchanged).
        prior: The prior (Table 1 with the known fields).
        fields: The fitted fields.
        identifiability: Standard errors and the combinations the logs cannot tell apart.
        windows: The logs' windows; ``starts`` hold the fitted starting states.
        rms: Root-mean-square residual of ``X, Y, psi`` over all frames, confidence-weighted (m, m, rad).
        sigma: The camera noise estimated from the poses (m, m, rad), mean over the logs.
        nfev: Residual evaluations.
        wall_time: Seconds the fit took (the fins' replay included).
        message: The optimiser's exit message.
        converged: Whether the optimiser met a tolerance, or stopped at ``max_nfev`` with a remaining step under
            0.1 standard errors (``False``: short of the optimum; the estimates and their standard errors are then
            those of an unfinished fit).
        remaining_step: The Gauss-Newton step that remains from the last point, in standard errors (the largest
            over the fields).
    """

    params: FishParams
    prior: FishParams
    fields: tuple[str, ...]
    identifiability: Identifiability
    windows: list[LogWindows]
    rms: np.ndarray
    sigma: np.ndarray
    nfev: int
    wall_time: float
    message: str
    settings: CalibrationSettings = field(default_factory=CalibrationSettings)
    converged: bool = True
    remaining_step: float = 0.0

    @property
    def duration(self) -> float:
        """Logged robot time the fit used [s]."""
        return float(sum(w.log.duration for w in self.windows))


class _Problem:
    """Residuals and Jacobian of the windowed-shooting fit (module docstring)."""

    def __init__(self, windows: list[LogWindows], prior: FishParams, fields: tuple[str, ...],
                 settings: CalibrationSettings):
        self.windows, self.prior, self.fields, self.settings = windows, prior, fields, settings
        self.p = len(fields)
        self.values = np.array([getattr(prior, name) for name in fields])
        counts = [len(w.window_t) for w in windows]
        self.offsets = np.concatenate([[0], np.cumsum(counts)])
        self.size = self.p + 6 * int(self.offsets[-1])
        self.rows = 3 * sum(len(w.sample_t) for w in windows)
        self._x: np.ndarray | None = None
        self._r = self._J = None

    def clusters(self) -> np.ndarray:
        """``(rows,)`` the shooting window (numbered over all logs) of each data residual."""
        return np.concatenate([np.repeat(self.offsets[k] + w.sample_window, 3) for k, w in enumerate(self.windows)])

    def params(self, theta: np.ndarray) -> FishParams:
        """The candidate of log-parameters ``theta`` (an offset: ``prior + theta`` rad; other fields: the prior's)."""
        return self.prior.replace(**{n: float(v + t if n in ADDITIVE_FIELDS else v * math.exp(t))
                                     for n, v, t in zip(self.fields, self.values, theta, strict=True)})

    def x0(self, theta: np.ndarray | None = None) -> np.ndarray:
        theta = np.zeros(self.p) if theta is None else theta
        return np.concatenate([theta, *(w.starts.ravel() for w in self.windows)])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Each field within a factor :data:`_FACTOR` of its prior, each start near its first estimate.

        (An offset stays within ``log(_FACTOR)`` rad of its prior.) Without them a trial step far from the data can
        ask the integrator for a fish of absurd stiffness.
        """
        x0 = self.x0()  # the log-parameters' bounds are about the prior (0)
        width = np.concatenate([np.full(self.p, math.log(_FACTOR)), np.tile(_START_RANGE, int(self.offsets[-1]))])
        return x0 - width, x0 + width

    @staticmethod
    def residual(out: np.ndarray, lw: LogWindows) -> np.ndarray:
        """``(n, s, 3)`` normalised residuals of candidate poses ``out`` against the camera's."""
        d = out - lw.observed
        d[..., 2] = np.remainder(d[..., 2] + math.pi, 2.0 * math.pi) - math.pi
        return d / lw.sigma * np.sqrt(lw.weight)[:, None]

    def evaluate(self, x: np.ndarray) -> None:
        """Residuals and Jacobian at ``x``, cached."""
        if self._x is not None and np.array_equal(x, self._x):
            return
        p, theta = self.p, x[:self.p]
        base = self.params(theta)
        candidates = [base, *(self.params(theta + _H_THETA * np.eye(p)[i]) for i in range(p)), *([base] * 6)]
        r = np.empty(self.rows + p)
        dense = np.zeros((self.rows + p, p))  # the log-parameters' columns
        rows_z, cols_z, vals_z = [], [], []  # the starting states' columns: each pose depends on its window's only
        row = 0
        for k, lw in enumerate(self.windows):
            lo, hi = self.offsets[k], self.offsets[k + 1]
            starts = np.broadcast_to(x[p + 6 * lo:p + 6 * hi].reshape(-1, 6), (len(candidates), hi - lo, 6)).copy()
            for j in range(6):
                starts[1 + p + j, :, j] += _H_START[j]
            res = self.residual(simulate(lw.track, candidates, lw.window_t, starts, lw.sample_t,
                                         self.settings.spec), lw)
            m = res.shape[1] * 3
            r[row:row + m] = res[0].ravel()
            dense[row:row + m] = ((res[1:1 + p] - res[0]) / _H_THETA).reshape(p, m).T
            rows = row + np.arange(m)
            for j in range(6):
                rows_z.append(rows)
                cols_z.append(p + 6 * (lo + np.repeat(lw.sample_window, 3)) + j)
                vals_z.append(((res[1 + p + j] - res[0]) / _H_START[j]).ravel())
            row += m
        r[row:] = theta / self.settings.prior_sigma  # the weak prior on each log-parameter
        dense[row:] = np.eye(p) / self.settings.prior_sigma
        rr, cc = np.nonzero(dense)
        J = sparse.csr_matrix((np.concatenate([dense[rr, cc], *vals_z]),
                               (np.concatenate([rr, *rows_z]), np.concatenate([cc, *cols_z]))),
                              shape=(self.rows + p, self.size))
        self._x, self._r, self._J = x.copy(), r, J

    def fun(self, x: np.ndarray) -> np.ndarray:
        self.evaluate(x)
        return self._r

    def jac(self, x: np.ndarray) -> sparse.csr_matrix:
        self.evaluate(x)
        return self._J


def prior_params(logs: Sequence[RunLog], known: FishParams | dict[str, float] | None = None) -> tuple[FishParams,
                                                                                                      set[str]]:
    """The prior: Table 1, then the logs' ``known_params``, then ``known``; returns it and the known fields' names."""
    values: dict[str, float] = {}
    for log in logs:
        values.update(log.known_params)
    if isinstance(known, FishParams):
        known = {n: getattr(known, n) for n in known.__dataclass_fields__}
    values.update(known or {})
    return FishParams().replace(**values), set(values)


def calibrate(logs: Sequence[RunLog], prior: FishParams | None = None,
              settings: CalibrationSettings | None = None) -> Calibration:
    """Fit ``settings.fields`` of the robot that wrote ``logs`` (module docstring).

    Args:
        logs: Run logs (:func:`pectoral_gym.runlog.read_run_log`).
        prior: The prior and the values of every field not fitted (default: Table 1 with the logs' ``known_params``).
        settings: Window, prior width, loss, ...

    Returns:
        The :class:`Calibration`.

    Raises:
        ValueError: Without fields to fit, or logs without enough poses.
    """
    settings = settings or CalibrationSettings()
    if not settings.fields:
        raise ValueError("no fields to fit")
    start = time.perf_counter()
    prior = prior if prior is not None else prior_params(logs)[0]
    tracks = [replay_fins(log) for log in logs]
    theta = np.zeros(len(settings.fields))
    # Continuation: short windows first (the model started from each window's poses stays near them even with
    # the prior's parameters, so the fit does not lock onto a wrong turn), then the long ones from that fit.
    for window in ((settings.warmup_window,) if settings.warmup_window else ()) + (settings.window,):
        windows = [split_windows(log, window, track) for log, track in zip(logs, tracks, strict=True)]
        problem = _Problem(windows, prior, tuple(settings.fields), settings)
        # Sparse Jacobian, iterative trust-region solver: the starting states' columns are block-diagonal.
        result = least_squares(problem.fun, problem.x0(theta), jac=problem.jac, bounds=problem.bounds(),
                               method="trf", loss=settings.loss, f_scale=settings.f_scale, x_scale="jac",
                               tr_solver="lsmr", max_nfev=settings.max_nfev)
        theta = result.x[:problem.p]
    problem.evaluate(result.x)
    r, J = problem._r, problem._J
    data = slice(0, problem.rows)
    dof = max(problem.rows - problem.size, 1)
    variance = float(np.sum(r[data] ** 2) / dof)  # the residual's scale: the noise estimate's error absorbed
    gauss_newton = gauss_newton_information(J[data], problem.p, variance)
    info = (window_sandwich_information(J[data], r[data], problem.p, problem.clusters())
            if settings.covariance == "window-sandwich" else None)
    ident = analyse(gauss_newton, variance, tuple(settings.fields), prior, settings.prior_sigma,
                    settings.identified_se, result.x[:problem.p], problem.params, info)
    if info is None and settings.covariance == "window-sandwich":
        ident.statements.insert(0, f"Only {int(problem.offsets[-1])} windows for {problem.p} fields: the standard "
                                "errors assume independent frames (Gauss-Newton) and are too small when the model "
                                "misses the camera by a smooth error; log more time for window-robust ones.")
    if variance > 1.5:  # the model misses some windows by more than the camera's noise: say what helps
        ident.statements.insert(0, f"The residual's variance is {variance:.2f} times the camera noise's: some windows "
                                "are misfitted (a wrong start, or model error) and the estimates may be biased by "
                                "more than their standard errors; try shorter windows (--window 3).")
    # Stopped at the evaluation limit: converged all the same if the Gauss-Newton step that remains from the last
    # point (the prior's rows included) moves every field by under a tenth of its standard error; the common scale,
    # held by the weak prior only, is often still creeping there while every ratio the logs fix has settled.
    remaining = lsqr(J, -r, atol=1e-10, btol=1e-10)[0][:problem.p]
    remaining_se = float(np.max(np.abs(remaining) / np.array([ident.std_error[n] for n in settings.fields])))
    for k, lw in enumerate(windows):
        lw.starts = result.x[problem.p + 6 * problem.offsets[k]:problem.p + 6 * problem.offsets[k + 1]].reshape(-1, 6)
    raw = r[data].reshape(-1, 3) * np.concatenate([np.broadcast_to(w.sigma, (len(w.sample_t), 3)) for w in windows])
    sigma = np.mean([w.sigma for w in windows], axis=0)
    return Calibration(problem.params(result.x[:problem.p]), prior, tuple(settings.fields), ident, windows,
                       np.sqrt(np.mean(raw**2, axis=0)), sigma, int(result.nfev), time.perf_counter() - start,
                       str(result.message), settings, converged=bool(result.status > 0 or remaining_se < 0.1),
                       remaining_step=remaining_se)
