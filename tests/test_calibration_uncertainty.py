"""The calibration's standard errors against closed-form covariances; a fit that stops short says so.

The covariance tests use a linear model shaped like the windowed-shooting fit (shared parameters, a nuisance
offset per window, smooth regressors), whose estimator's covariance is known exactly for any noise covariance:
``(X~'X~)^-1 X~' Sigma X~ (X~'X~)^-1``, ``X~`` the regressors with each window's offset projected out.
"""

import json
import math

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import linalg as sparse_linalg

from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.calibration.covariance import gauss_newton_information, window_sandwich_information
from pectoral_gym.scaling.calibration.synth import write_synthetic_log
from pectoral_gym.scaling.cli import main

WINDOWS, FRAMES = 200, 60  # windows, frames per window


def _ar1(rho: float, n: int) -> np.ndarray:
    """Covariance of a unit-variance AR(1) sequence of ``n`` samples with lag-one correlation ``rho``."""
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return rho ** lags


def _problem(rho: float, seed: int = 0):
    """A windowed linear fit with AR(1) noise: Jacobian ``[X, Z]``, residuals at the optimum, exact covariance."""
    rng = np.random.default_rng(seed)
    t = np.arange(FRAMES) / 30.0
    blocks_x, blocks_z, noise, exact_meat, xtx = [], [], [], np.zeros((2, 2)), np.zeros((2, 2))
    chol = np.linalg.cholesky(_ar1(rho, FRAMES))
    for _ in range(WINDOWS):
        # smooth regressors (a slow sine and a ramp with a random phase and slope): like a parameter's effect on poses
        x = np.column_stack([np.sin(rng.uniform(0.5, 2.0) * t + rng.uniform(0, 2 * math.pi)),
                             rng.uniform(-1, 1) * t])
        blocks_x.append(x)
        blocks_z.append(np.ones((FRAMES, 1)))  # the window's own nuisance: an offset
        noise.append(chol @ rng.standard_normal(FRAMES))
        centred = x - x.mean(axis=0)  # the offset projected out
        exact_meat += centred.T @ _ar1(rho, FRAMES) @ centred
        xtx += centred.T @ centred
    X = np.vstack(blocks_x)
    J = sparse.hstack([sparse.csr_matrix(X), sparse.block_diag(blocks_z)]).tocsr()
    y = np.concatenate(noise)  # truth 0: the data are the noise
    solution = sparse_linalg.lsqr(J, y, atol=1e-14, btol=1e-14)[0]
    r = y - J @ solution  # the residuals at the optimum (model minus data has the opposite sign: the same score)
    exact = np.linalg.inv(xtx) @ exact_meat @ np.linalg.inv(xtx)
    clusters = np.repeat(np.arange(WINDOWS), FRAMES)
    return J, r, clusters, exact


def test_white_residuals_sandwich_equals_gauss_newton():
    """Independent frames: both covariances are the exact one (the sandwich to its sampling error, ~sqrt(2/G))."""
    J, r, clusters, exact = _problem(rho=0.0)
    variance = float(r @ r / (len(r) - J.shape[1]))
    gauss_newton = np.linalg.inv(gauss_newton_information(J, 2, variance))
    sandwich = np.linalg.inv(window_sandwich_information(J, r, 2, clusters))
    assert np.diag(gauss_newton) == pytest.approx(np.diag(exact), rel=0.05)
    assert np.diag(sandwich) == pytest.approx(np.diag(exact), rel=0.35)  # 3.5 sampling sd for 200 windows


def test_correlated_residuals_gauss_newton_too_small_sandwich_right():
    """Smoothly correlated frames (AR(1), rho 0.9): Gauss-Newton's variance is several times too small, the sandwich's
    within its sampling error of the exact one."""
    J, r, clusters, exact = _problem(rho=0.9)
    variance = float(r @ r / (len(r) - J.shape[1]))
    gauss_newton = np.linalg.inv(gauss_newton_information(J, 2, variance))
    sandwich = np.linalg.inv(window_sandwich_information(J, r, 2, clusters))
    assert np.all(np.diag(exact) / np.diag(gauss_newton) > 4.0)  # the textbook covariance's failure
    assert np.diag(sandwich) == pytest.approx(np.diag(exact), rel=0.35)


def test_sandwich_refuses_too_few_windows():
    J, r, clusters, _ = _problem(rho=0.0)
    rows = clusters < 10
    assert window_sandwich_information(J[rows], r[rows], 2, clusters[rows]) is None


def test_cli_says_when_the_fit_stopped_short_and_when_nothing_was_held_out(tmp_path, capsys):
    """A fit cut at 2 evaluations warns on the terminal and in report.md; held-out episodes too short to check
    (20 s against a 40 s horizon) leave nothing checked: exit 2, with what to do."""
    fit, held = tmp_path / "fit.jsonl", tmp_path / "held.jsonl"
    truth = FishParams().replace(drag_coef=0.3870 * 1.2)
    write_synthetic_log(fit, truth, 5, duration=20.0)
    write_synthetic_log(held, truth, 9, duration=21.0, episode_length=20.0, tank=False)
    args = ["calibrate", "--logs", str(fit), "--hold-out", str(held), "--fields", "drag_coef", "--no-plots",
            "--out", str(tmp_path / "robot.json"), "--report", str(tmp_path / "rep")]
    assert main([*args, "--max-evaluations", "2"]) == 2
    err = capsys.readouterr().err
    assert "did not converge" in err and "--max-evaluations 6" in err
    assert "nothing was checked" in err and "--horizon" in err
    assert "did not converge" in (tmp_path / "rep" / "report.md").read_text()
    assert json.loads((tmp_path / "rep" / "report.json").read_text())["converged"] is False
    # the same logs with a horizon the held-out episode spans: checked, converged, exit 0
    assert main([*args, "--horizon", "15"]) == 0
    err = capsys.readouterr().err
    assert "did not converge" not in err and "nothing was checked" not in err
    assert json.loads((tmp_path / "rep" / "report.json").read_text())["held_out"]["episodes"] == 1
