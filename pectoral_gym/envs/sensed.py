"""``EnvConfig.sensing``: the observation seen through a simulated camera and the robot's observer.

With ``sensing`` set, :class:`~pectoral_gym.envs.core.EnvCore` observes as the robot env
(``HardwareFishEnv``) does: a camera captures the fish's pose at ``frame_rate`` frames/s, free of the control
loop (a random first frame phase per episode); each frame is lost with probability ``frame_drop``, carries
Gaussian pose noise (``position_noise`` on X and Y, ``heading_noise`` on psi) and is delivered ``latency``
seconds after its capture, stamped with its capture time. Every frame delivered within a control period is fed
to the high-gain observer (:mod:`pectoral_gym.sensing.observer`, the robot's own arithmetic), then

* the observation's pose (position, heading, and the target seen from it) is the observer's estimate at the
  last delivered frame, or, when that frame is older than ``PREDICT_AFTER_FRAMES`` frame periods, extrapolated
  to the end of the period;
* its velocities are the mean of the observer's estimates at the period's frames (the estimate's own when no
  frame came), as the robot env averages them.

At a reset the observer starts at rest at one noisy frame of the start pose. The levels are drawn per episode
(:meth:`pectoral_gym.sensing.camera.SensingConfig.draw`); the frames' losses and noise per step, both from the
env's own generator after everything else it draws, so an episode starts where it starts without sensing.

Only the observation changes: the reward, the termination (walls, goal, the stopping band), ``info`` and the
fin block are computed on the model's true state, the simulation's privileged truth, exactly as without
``sensing`` (the same episodes for the same seed and actions).

The fish's pose at a frame instant: a *shadow* of each env's model (its arrays copied at the period's start,
:meth:`SensedObservation.before_step`) takes the step's command and is advanced by the model's own kernels
(``strokes.command_one``, ``stepping.advance_one``) from one frame instant to the next, recording the pose
there. The compiled env step is untouched (an env without ``sensing`` runs exactly as before; with it, each
period is integrated a second time in up to ``frame_rate * control_period`` pieces). Interpolating between the
period's end states instead (the cubic Hermite curve through both poses and world-frame rates) misses what a
period holds: on ``PectoralFish-Averaged-v1`` the transitional half-strokes' forcing (``docs/model.md`` 3.7)
kicks the fish within a period, and such a curve was up to 12 mm and 11 deg off the model's pose at frame
instants (rms 0.6 mm, 0.8 deg; on ``-v0``, without transitions, 0.4 mm and 0.5 deg at most;
``docs/notes/2026-12-03-sensing-randomisation.md``). The full model's in-beat ripple is recorded as the
robot's camera would see it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pectoral_gym.envs.tasks.kernels import observe_one
from pectoral_gym.model.jit import njit
from pectoral_gym.model.stepping import advance_one
from pectoral_gym.model.strokes import command_one
from pectoral_gym.sensing.camera import SensingConfig
from pectoral_gym.sensing.observer import (
    A1,
    A2,
    PREDICT_AFTER_FRAMES,
    observer_predict,
    observer_reset,
    observer_update,
)

__all__ = ["SensedObservation"]

# Per-env levels (SensingConfig.draw): the columns of SensedObservation.levels.
_POSITION_NOISE, _HEADING_NOISE, _DROP, _LATENCY, _PHASE = range(5)


@njit
def _reset_kernel(index, noise, levels, state, frame, recorded, period, offset, z, last, estimate, sensed, ep, fish,
                  obs):
    """Start the camera and the observer of the envs in ``index`` at their start states (``noise`` (k, 3))."""
    for k in range(index.shape[0]):
        i = index[k]
        frame[i] = recorded[i] = period[i] = 0
        offset[i] = 0.0
        x = state[i, 0] + levels[i, _POSITION_NOISE] * noise[k, 0]
        y = state[i, 1] + levels[i, _POSITION_NOISE] * noise[k, 1]
        psi = state[i, 2] + levels[i, _HEADING_NOISE] * noise[k, 2]
        observer_reset(i, z, last, estimate, 0.0, x, y, psi)
        for j in range(6):
            sensed[i, j] = estimate[i, j]
        observe_one(i, sensed, ep, fish, obs)


@njit
def _record(i, levels, recorded, poses, t0, t1, lag, frame_dt, beats, everyone, state, fins, cache, pending,
            integral, coef, s, tables):
    """Advance env ``i``'s shadow fish from ``t0`` through the period, recording its pose at each capture <= ``t1``.

    The shadow holds the true model's arrays at the period's start; it takes the step's command as the
    fused step does (``command_one``, ``lag`` seconds into the period: ``envs.timing``) and advances with the
    model's own kernel (``advance_one``) from one capture instant (or the command's) to the next. Frame ``k``'s
    pose goes to ``poses[i, k % poses.shape[1]]``.
    """
    commanded = lag <= 0.0
    if commanded:
        command_one(i, fins, pending, beats, everyone)
    t = t0
    while True:
        capture = levels[i, _PHASE] + recorded[i] * frame_dt
        if capture > t1:
            break
        if not commanded and capture > t0 + lag:  # the command reaches the fins before this frame
            advance_one(i, state, fins, cache, pending, integral, coef, t0 + lag - t, s[1], s[2], s[3], s[4],
                        s[5], tables)
            command_one(i, fins, pending, beats, everyone)
            commanded, t = True, t0 + lag
        advance_one(i, state, fins, cache, pending, integral, coef, capture - t, s[1], s[2], s[3], s[4], s[5],
                    tables)
        t = capture
        slot = recorded[i] % poses.shape[1]
        poses[i, slot, 0], poses[i, slot, 1], poses[i, slot, 2] = state[i, 0], state[i, 1], state[i, 2]
        recorded[i] += 1


@njit
def _step_kernel(skip, draws, levels, frame, recorded, period, offset, timing, poses, z, last, estimate, sensed, ep,
                 fish, obs, frame_rate, epsilon, max_gap, beats, everyone, state, fins, cache, pending, integral, coef,
                 s, tables):
    """One control period of every env not in ``skip``: its frames recorded, delivered, observed.

    Records the frames captured in the period (:func:`_record`), feeds those delivered by its end to the
    observer, then writes the observation (``s``: the model's :class:`~pectoral_gym.envs.fused.StepSettings`;
    ``timing``: each env's command delay and period length, ``offset`` how far its periods' ends have moved
    from the nominal grid).
    """
    frame_dt = 1.0 / frame_rate
    dt = s[0]
    for i in range(skip.shape[0]):
        if skip[i]:
            continue
        t0 = period[i] * dt + offset[i]  # the period [s since the reset]; t1 is the next t0
        offset[i] += timing[i, 1] - dt
        t1 = (period[i] + 1) * dt + offset[i]
        _record(i, levels, recorded, poses, t0, t1, timing[i, 0], frame_dt, beats, everyone, state, fins, cache,
                pending, integral, coef, s, tables)
        latency = levels[i, _LATENCY]
        count = 0
        vx = vy = omega = 0.0
        j = 0
        while j < draws.shape[1] and frame[i] < recorded[i]:
            capture = levels[i, _PHASE] + frame[i] * frame_dt
            if capture > t1 - latency:  # delivered after this period
                break
            slot = frame[i] % poses.shape[1]
            frame[i] += 1
            u = draws[i, j, 0]
            noise_x, noise_y, noise_psi = draws[i, j, 1], draws[i, j, 2], draws[i, j, 3]
            j += 1
            if u < levels[i, _DROP]:
                continue
            observer_update(i, z, last, estimate, capture,
                            poses[i, slot, 0] + levels[i, _POSITION_NOISE] * noise_x,
                            poses[i, slot, 1] + levels[i, _POSITION_NOISE] * noise_y,
                            poses[i, slot, 2] + levels[i, _HEADING_NOISE] * noise_psi, epsilon, A1, A2, max_gap)
            vx += estimate[i, 3]
            vy += estimate[i, 4]
            omega += estimate[i, 5]
            count += 1
        if t1 - last[i, 0] > PREDICT_AFTER_FRAMES * frame_dt:
            observer_predict(i, z, last, estimate, t1)
        for k in range(6):
            sensed[i, k] = estimate[i, k]
        if count > 0:
            sensed[i, 3], sensed[i, 4], sensed[i, 5] = vx / count, vy / count, omega / count
        observe_one(i, sensed, ep, fish, obs)
        period[i] += 1


class SensedObservation:
    """The simulated camera and observer of ``n`` envs (``EnvConfig.sensing``; the module docstring).

    Args:
        model: The envs' batched model (its shapes; its arrays are copied into the shadow before each step).
        settings: The camera and observer settings.
        control_period: The envs' control period [s] (above every latency of ``settings``).
        longest_period: The longest period a step can last [s] (``envs.timing``; default ``control_period``).

    Attributes:
        levels: ``(n, 5)`` each env's episode levels (:data:`pectoral_gym.sensing.camera.LEVELS`).
        estimate: ``(n, 6)`` each observer's latest output ``X, Y, psi, vx, vy, omega``.
        sensed: ``(n, 6)`` the state each observation shows (pose estimate, mean velocities).
        poses: ``(n, r, 3)`` the true poses of the recent frames (frame ``k`` at ``k % r``).
    """

    def __init__(self, model, settings: SensingConfig, control_period: float, longest_period: float | None = None):
        n = model.n
        self.settings, self.dt = settings, float(control_period)
        # frame draws per env and step
        self.frames = settings.frames_per_period(self.dt if longest_period is None else float(longest_period))
        self.levels = np.zeros((n, 5))
        self.frame = np.zeros(n, dtype=np.int64)  # index of each camera's next frame to deliver
        self.recorded = np.zeros(n, dtype=np.int64)  # index of each camera's next frame to capture
        self.period = np.zeros(n, dtype=np.int64)  # control periods since the reset
        self.offset = np.zeros(n)  # the last period's end minus its nominal instant (envs.timing) [s]
        self.poses = np.zeros((n, 2 * self.frames, 3))  # undelivered frames: this period's and the last one's
        self.z, self.last = np.zeros((n, 2, 3)), np.full((n, 4), np.nan)
        self.estimate, self.sensed = np.zeros((n, 6)), np.zeros((n, 6))
        self.draws = np.zeros((n, self.frames, 4))
        self.everyone = np.ones(n, dtype=np.bool_)
        self.shadow = tuple(np.empty_like(a) for a in self._model_arrays(model))
        self._rngs: Sequence[np.random.Generator] = ()

    @staticmethod
    def _model_arrays(model) -> tuple[np.ndarray, ...]:
        return model.state, model.fins, model.forcing_cache, model.pending, model.integral

    def reset(self, index: np.ndarray, rngs: Sequence[np.random.Generator], state: np.ndarray, ep: np.ndarray,
              fish: np.ndarray, obs: np.ndarray) -> None:
        """Draw the levels of the envs in ``index`` (env ``i`` from ``rngs[i]``) and observe their start."""
        self._rngs = rngs
        noise = np.empty((index.size, 3))
        for k, i in enumerate(index):
            self.levels[i] = self.settings.draw(rngs[i])
            noise[k] = rngs[i].standard_normal(3)
        _reset_kernel(index, noise, self.levels, state, self.frame, self.recorded, self.period, self.offset, self.z,
                      self.last, self.estimate, self.sensed, ep, fish, obs)

    def before_step(self, model) -> None:
        """Copy the model's arrays at the period's start into the shadow (before the env step advances them)."""
        for copy, array in zip(self.shadow, self._model_arrays(model), strict=True):
            copy[...] = array

    def step(self, skip: np.ndarray, model, settings, beats: np.ndarray, ep: np.ndarray, fish: np.ndarray,
             obs: np.ndarray, timing: np.ndarray) -> None:
        """After a control period: the frames of the envs not in ``skip`` (drawn from their generators), observed.

        ``settings`` are the model's :class:`~pectoral_gym.envs.fused.StepSettings`, ``beats`` the step's commands,
        ``timing`` ``(n, 2)`` each env's command delay and period length (:mod:`pectoral_gym.envs.timing`).
        """
        draws, frames = self.draws, self.frames
        for i in np.flatnonzero(~skip):
            rng = self._rngs[i]
            draws[i, :, 0] = rng.random(frames)
            draws[i, :, 1:] = rng.standard_normal((frames, 3))
        c = self.settings
        _step_kernel(skip, draws, self.levels, self.frame, self.recorded, self.period, self.offset, timing, self.poses,
                     self.z, self.last, self.estimate, self.sensed, ep, fish, obs, c.frame_rate, c.observer_epsilon,
                     c.max_gap, beats, self.everyone, *self.shadow, model.coef, tuple(settings), model.packed_tables)
