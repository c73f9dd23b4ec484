"""Is ``--params`` this robot? A short open-loop probe before the first episode, seen by the camera, against the model.

The geofence's stopping distance and the fish's outline come from ``--params``; a description 30 % off in drag
or fin force puts the fish's stop tens of centimetres away from where the geofence planned it. Before the first
episode the deploy drives the robot open loop through :data:`PROBE` (a burst of rowing, a coast, a turn on one
fin, a coast: 12 s), through the whole robot stack and its safety rules, and logs it as a run log. The full
model under ``--params`` then replays the logged commands (the fins through the firmware's rules, as the
calibration does, :mod:`pectoral_gym.scaling.calibration`), each :data:`WINDOW` s window started from the state
that fits its poses best, and the camera's poses are compared with the model's.

The statistic is the position residual beyond the camera's noise. The ``X, Y`` residuals, in units of the
camera's noise ``sigma`` (estimated from the poses themselves, second differences, as the calibration does),
are unit normal deviates under the robot's own model; ``chi2`` is their mean square without the largest 2 % (a
few mis-tracked frames do not move it), scaled to 1 for such deviates, and the **excess**
``sigma sqrt(max(0, chi2 - 1))`` is the model's own miss, in metres. ``--params`` is refused when the excess
exceeds :data:`EXCESS_LIMIT` and ``chi2 - 1`` is significant: more than 5 standard deviations of that estimate
under noise alone (``1.46 / sqrt(n)`` for ``n`` residuals), and more than the uncertainty of the noise's own
estimate (0.25). The limit sits between what calibration accuracy
leaves and what 30 % off in drag or fin size gives: the measurement is in ``docs/calibration.md``, "Checking
--params against the robot".
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.envs.layout import E_TX, E_TY
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model.params import FishParams

__all__ = ["EXCESS_LIMIT", "PROBE", "WINDOW", "ProbeResult", "check_on_lockstep_rig", "check_on_robot",
           "judge_probe", "probe_start", "run_probe"]

_ROW = (0.5, 0.5, 0.0, 0.5)  # one fin's action: rowing forward (the deploy tests' forward pattern)
_REST = (0.0, -1.0, 0.0, 0.0)  # one fin's action: amplitude 0 at mid bias, still
#: The probe: ``(what, seconds, action)``; the action as the env takes it (right fin first).
PROBE = (("burst", 4.0, _ROW + _ROW), ("coast", 3.0, _REST + _REST), ("turn", 3.0, _ROW + _REST),
         ("coast", 2.0, _REST + _REST))
WINDOW = 6.0  # s: the calibration's shooting window (scaling.calibration.fit.CalibrationSettings.window)
#: Largest accepted excess [m] (module docstring); measured in docs/calibration.md, "Checking --params against the
#: robot".
EXCESS_LIMIT = 0.001
_SIGNIFICANCE = 5.0  # standard deviations of chi2 under the camera's noise alone
_TRIM = 0.02  # the largest residuals left out of chi2: a few mis-tracked frames, not the model
# The camera's noise is estimated from the probe's own poses, and 12 s of them fix its variance only to some 10 %:
# for the robot's own parameters behind a 5 mm camera chi2 came out 0.84-1.19 over five robots. A chi2 within
# this of 1 is not counted as the model's (docs/calibration.md, "Checking --params against the robot").
_NOISE_UNCERTAINTY = 0.25
_MIN_SECONDS = 8.0  # a probe cut shorter than this (by a safety stop) tells too little: the deploy refuses


def _trimmed_chi2_1() -> tuple[float, float]:
    """``(mean, spread)`` of the mean of the ``1 - _TRIM`` smallest of ``n`` squared unit normal deviates.

    ``mean`` is its expectation, ``spread / sqrt(n)`` its standard deviation (a one-sided trimmed mean's
    asymptotic variance: the winsorised variance over ``(1 - _TRIM)^2``). With ``x f_1(x) = f_3(x)`` and
    ``x^2 f_1(x) = 3 f_5(x)`` for the chi-squared densities, both are closed forms.
    """
    from scipy.stats import chi2

    keep = 1.0 - _TRIM
    q = float(chi2.ppf(keep, 1))
    mean = float(chi2.cdf(q, 3)) / keep
    second = 3.0 * float(chi2.cdf(q, 5)) / keep
    winsorised = keep * (second - mean ** 2) + _TRIM * (q - mean) ** 2
    return mean, math.sqrt(winsorised) / keep / mean


def probe_start() -> tuple[float, float, float]:
    """Where an emulated probe starts: 0.5 m behind the tank's centre, heading along X (room to row and turn)."""
    return tk.TANK_X / 2 - 0.5, tk.TANK_Y / 2, 0.0


@dataclass(frozen=True)
class ProbeResult:
    """What the probe found.

    Attributes:
        chi2: The noise-normalised ``X, Y`` residuals' mean square without the largest 2 % (module docstring;
            ``inf``: too short).
        dof: The number of residuals it comes from.
        sigma: The camera's position noise estimated from the poses [m].
        duration: Seconds of poses the probe logged.
        rms: Root-mean-square position residual [m].
        stop: The safety stop that ended the probe early, or ``""``.
        log: The probe's run log (``docs/run-log.md``), for :func:`judge_probe` under other parameters.
    """

    chi2: float
    dof: int
    sigma: float
    duration: float
    rms: float
    stop: str = ""
    log: str = field(default="", repr=False)

    @property
    def excess(self) -> float:
        """The model's own miss beyond the camera's noise [m] (module docstring)."""
        return self.sigma * math.sqrt(max(0.0, self.chi2 - 1.0)) if math.isfinite(self.chi2) else math.inf

    @property
    def significant(self) -> bool:
        """Whether ``chi2`` exceeds 1 by more than noise alone explains."""
        return self.chi2 - 1.0 > max(_SIGNIFICANCE * _trimmed_chi2_1()[1] / math.sqrt(max(self.dof, 1)),
                                     _NOISE_UNCERTAINTY)

    @property
    def accepted(self) -> bool:
        """Whether ``--params`` describes the robot (:data:`EXCESS_LIMIT`) on a probe long enough to tell."""
        return self.duration >= _MIN_SECONDS and not (self.excess > EXCESS_LIMIT and self.significant)

    def why(self) -> str:
        """One line: what the probe saw."""
        if self.duration < _MIN_SECONDS:
            return (f"the probe ran {self.duration:.1f} s of {_MIN_SECONDS:.0f} s needed"
                    f"{f' (stopped: {self.stop})' if self.stop else ''}: place the fish near the tank's centre")
        return (f"over {self.duration:.0f} s of probe the model under --params misses the camera's poses by "
                f"{self.excess * 1000:.1f} mm beyond the camera's noise ({self.sigma * 1000:.1f} mm; rms "
                f"{self.rms * 1000:.1f} mm, chi2 {self.chi2:.1f}); a robot's own parameters miss by under "
                f"{EXCESS_LIMIT * 1000:.1f} mm")


def judge_probe(log, params: FishParams) -> ProbeResult:
    """Compare the probe's run log ``log`` (a :class:`pectoral_gym.runlog.RunLog`) with ``params``' model."""
    from scipy.optimize import least_squares

    from pectoral_gym.scaling.calibration.fit import CalibrationSettings, _Problem
    from pectoral_gym.scaling.calibration.windows import split_windows

    spans = [float(ep.pose_t[-1] - ep.pose_t[0]) for ep in log.episodes if len(ep.pose_t) >= 2]
    duration = max(spans, default=0.0)
    if duration < _MIN_SECONDS:
        return ProbeResult(math.inf, 0, math.nan, duration, math.inf)
    lw = split_windows(log, WINDOW)
    problem = _Problem([lw], params, (), CalibrationSettings(fields=()))
    result = least_squares(problem.fun, problem.x0(), jac=problem.jac, bounds=problem.bounds(), method="trf",
                           x_scale="jac", tr_solver="lsmr", max_nfev=30)
    # X, Y (the heading is the camera's noisiest), in noise units without the fit's confidence weights: under the
    # robot's own model each is then a unit normal deviate and chi2 is near 1 whatever the confidences
    r = problem.fun(result.x)[:problem.rows].reshape(-1, 3)[:, :2] / np.sqrt(np.maximum(lw.weight, 1e-12))[:, None]
    dof = max(1, r.size - 4 * len(lw.window_t))  # each window's fitted position and velocity in X, Y
    sigma = float(np.sqrt(np.mean(lw.sigma[:2] ** 2)))
    rms = float(np.sqrt(np.mean(np.sum((r * lw.sigma[:2]) ** 2, axis=1))))
    # the mean of r^2 without its largest 2 %, over that mean for unit normal deviates: a few mis-tracked frames do
    # not move it, a model that misses does, without bound; the fitted starts' degrees of freedom scale it
    squares = np.sort(r.ravel() ** 2)[:int((1.0 - _TRIM) * r.size)]
    chi2 = float(np.mean(squares) / _trimmed_chi2_1()[0] * r.size / dof)
    return ProbeResult(chi2, r.size, sigma, duration, rms)


def run_probe(env, params: FishParams, seed: int | None = None) -> ProbeResult:
    """Drive ``env``'s robot through :data:`PROBE` (one reset, then open loop) and judge it against ``params``.

    The probe's records go to a run log of their own (not the run's, whose episodes it would renumber); the
    env's run log and its episode numbering are as before afterwards.
    """
    from pectoral_gym.hardware.run_recorder import RunRecorder
    from pectoral_gym.runlog import RunLogWriter, read_run_log

    env = env.unwrapped
    buffer = io.StringIO()
    saved, max_steps = env.recorder, env.max_episode_steps
    env.recorder = RunRecorder(RunLogWriter(buffer, "probe", env.config.control_period))
    env.max_episode_steps = sum(max(1, round(s / env.config.control_period)) for _, s, _ in PROBE) + 1
    stop = ""
    try:
        env.reset(seed=seed)
        env.task_state.ep[0, E_TX:E_TY + 1] = (-1e3, -1e3)  # a goal it never reaches: the probe runs its course
        done = False
        for _, seconds, action in PROBE:
            for _ in range(max(1, round(seconds / env.config.control_period))):
                _, _, terminated, truncated, info = env.step(np.asarray(action, dtype=np.float32))
                if terminated or truncated:
                    stop, done = info.get("safety_stop") or "episode_end", True
                    break
            if done:
                break
    finally:  # the fins run on until the next reset, which stops them and waits for the robot's word
        env.recorder, env.max_episode_steps = saved, max_steps
    result = judge_probe(read_run_log(io.StringIO(buffer.getvalue())), params)
    return ProbeResult(result.chi2, result.dof, result.sigma, result.duration, result.rms, stop, buffer.getvalue())


def check_on_robot(env, params: FishParams, place, seed: int | None = None) -> ProbeResult:
    """Run the probe with ``place`` as the reset hook; ``ValueError`` (one line) unless ``params`` is the robot.

    ``place`` puts the fish where the probe has room (:func:`probe_start`). The hook the env had is restored
    afterwards. On a refusal the fins run on only until the env is closed (its STOP), at most the command's lease.
    """
    hook, env.unwrapped.reset_hook = env.unwrapped.reset_hook, place
    try:
        result = run_probe(env, params, seed)
    finally:
        env.unwrapped.reset_hook = hook
    if not result.accepted:
        raise ValueError(f"--params does not describe this robot: {result.why()}; calibrate it "
                         "(docs/calibration.md) and give the result with --params; the robot was stopped")
    return result


def check_on_lockstep_rig(seed: int, conditions, robot_params: FishParams | None, **env_kwargs) -> ProbeResult:
    """:func:`check_on_robot` on a lockstep rig of its own, closed before this returns.

    The rig: :func:`pectoral_gym.hardware.emurig.open_rig` seeded with ``seed``, the emulated fish
    ``robot_params``; ``env_kwargs`` go to the env, whose ``params`` (default Table 1's) are the ones checked.
    """
    import contextlib

    from pectoral_gym.hardware.emurig import open_rig
    from pectoral_gym.hardware.env import HardwareFishEnv

    with contextlib.ExitStack() as resources:
        clock, robot, port, camera = open_rig(resources, seed, conditions, True, 1.0, robot_params)
        env = HardwareFishEnv(port, camera, clock=clock, handle_signals=False, **env_kwargs)
        resources.callback(env.close)
        return check_on_robot(env, env_kwargs.get("params") or FishParams(), lambda rng: robot.place(*probe_start()),
                              seed)
