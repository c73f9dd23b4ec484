"""How much the logs tell about the log-parameters: their information matrix, starting states eliminated.

Two estimates from the Jacobian ``J = [J_theta, J_z]`` of the normalised residuals ``r`` at the optimum
(log-parameters first, then the windows' starting states, each window's six columns touching only its own rows):

- :func:`gauss_newton_information`: ``S / s^2``, ``S`` the Schur complement
  ``J_theta' J_theta - J_theta' J_z (J_z' J_z)^-1 J_z' J_theta`` and ``s^2`` the residual's variance. Its inverse,
  ``s^2 S^-1``, is the textbook covariance; it holds only if the residuals are independent from frame to frame.
  They are not when the model misses the camera by a smooth error (the fins' replay, the integration, any
  physics the model lacks): such an error lasts seconds, i.e. 30-180 consecutive frames, and ``s^2 S^-1`` is
  then too small by about the number of frames it spans.
- :func:`window_sandwich_information`: the cluster-robust ("sandwich") covariance with each shooting window a
  cluster, in its jackknife form: ``V = (G - 1) / G sum_w (S - S_w)^-1 g_w g_w' (S - S_w)^-1``, ``g_w = J~_w' r_w``
  each window's score and ``S_w = J~_w' J~_w`` its information (``J~_w``: the window's ``J_theta`` rows with its
  starting state projected out), ``G`` the number of windows; ``(S - S_w)^-1 g_w`` is, to first order, how far
  the fit moves when window ``w`` is left out. It makes no assumption on how residuals correlate within a window,
  only that windows (each started from its own fitted state) are nearly independent, and comes close to
  ``s^2 S^-1`` for white residuals. Returned as an information ``V^-1``, so the prior adds to it as to the
  Gauss-Newton one.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

__all__ = ["MIN_WINDOWS", "MIN_WINDOWS_PER_FIELD", "gauss_newton_information", "window_sandwich_information"]

#: The sandwich needs many more windows than fitted fields: with ``G`` windows its meat ``B`` has ``G`` terms and
#: each variance is known to about ``sqrt(2 / G)`` (30 % for 20 windows); below ``MIN_WINDOWS`` windows, or
#: ``MIN_WINDOWS_PER_FIELD`` per field, it is not used.
MIN_WINDOWS, MIN_WINDOWS_PER_FIELD = 20, 3


def _schur(J, p: int) -> np.ndarray:
    """``J_t' J_t - J_t' J_z (J_z' J_z)^-1 J_z' J_t``: the log-parameters' ``J'J``, starting states eliminated."""
    H = J.T @ J
    H = H.toarray() if hasattr(H, "toarray") else np.asarray(H)
    Htt, Htz, Hzz = H[:p, :p], H[:p, p:], H[p:, p:]
    if Hzz.size == 0:
        return Htt
    return Htt - Htz @ np.linalg.lstsq(Hzz, Htz.T, rcond=None)[0]


def gauss_newton_information(J, p: int, variance: float) -> np.ndarray:
    """``(p, p)`` information ``S / s^2`` of the log-parameters for independent residuals (module docstring).

    Args:
        J: ``(m, p + 6 w)`` Jacobian of the normalised data residuals, dense or sparse.
        p: Number of log-parameters (the first columns).
        variance: The residual's variance ``s^2``.
    """
    info = _schur(J, p) / max(variance, 1e-12)
    return 0.5 * (info + info.T)


def window_sandwich_information(J, r: np.ndarray, p: int, clusters: np.ndarray) -> np.ndarray | None:
    """``(p, p)`` information ``V^-1`` from the window-clustered sandwich covariance ``V`` (module docstring).

    Args:
        J: ``(m, p + 6 w)`` Jacobian of the normalised data residuals, dense or sparse.
        r: ``(m,)`` the normalised data residuals at the optimum.
        p: Number of log-parameters (the first columns).
        clusters: ``(m,)`` the shooting window of each residual.

    Returns:
        The information, or ``None`` with fewer than :data:`MIN_WINDOWS` windows or :data:`MIN_WINDOWS_PER_FIELD`
        per field (the meat would be too noisy to trust).
    """
    J = sparse.csr_matrix(J)
    labels = np.unique(clusters)
    if len(labels) < max(MIN_WINDOWS, MIN_WINDOWS_PER_FIELD * p):
        return None
    order = np.argsort(clusters, kind="stable")
    bounds = np.searchsorted(clusters[order], labels, side="left").tolist() + [len(order)]
    own, scores = [], []  # each window's information S_w and score g_w
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        rows = order[lo:hi]
        block = J[rows]
        theta = block[:, :p].toarray()
        starts = block[:, p:]
        cols = np.unique(starts.indices)
        if len(cols):  # the window's own starting state, projected out (its Schur complement)
            z = starts[:, cols].toarray()
            theta = theta - z @ np.linalg.lstsq(z, theta, rcond=None)[0]
        own.append(theta.T @ theta)
        scores.append(theta.T @ r[rows])
    S = np.sum(own, axis=0)
    G = len(labels)
    # Jackknife form (CR3): each window's score seen from the fit without it, (S - S_w)^-1 g_w. The plain form
    # S^-1 g_w comes out too small for a combination that few windows fix (the fit has already bent towards their
    # residuals: high leverage), as lift is by the few windows with much sideslip.
    V = np.zeros((p, p))
    for S_w, g_w in zip(own, scores, strict=True):
        step = np.linalg.lstsq(S - S_w, g_w, rcond=None)[0]
        V += np.outer(step, step)
    V *= (G - 1) / G
    info = np.linalg.pinv(0.5 * (V + V.T), hermitian=True)
    return 0.5 * (info + info.T)
