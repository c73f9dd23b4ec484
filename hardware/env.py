"""``HardwareFishEnv``: the fish tasks on the real robot (XBee radio out, overhead camera in)."""

from __future__ import annotations

import atexit
import math
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from pectoral_gym.envs.layout import ACTION_SIZE, E_TX, E_TY
from pectoral_gym.envs.observation import observation_bounds
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.envs.tasks.table import TaskState
from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.env_reset import EpisodeStart
from pectoral_gym.hardware.radio.link import RadioLink
from pectoral_gym.hardware.radio.linkclock import renewal_lease
from pectoral_gym.hardware.run_recorder import RunRecorder
from pectoral_gym.hardware.safety.rules import SafetyConfig, check_action, install_stop_handlers
from pectoral_gym.hardware.stack import env_config, open_stack
from pectoral_gym.sensing.observer import PREDICT_AFTER_FRAMES

__all__ = ["HardwareFishEnv"]


class HardwareFishEnv(EpisodeStart, gym.Env):
    r"""The robotic fish in a real tank: actions go out over the XBee radio, observations come from a camera.

    ## Description

    The same tasks, spaces and rewards as the simulated envs
    (:class:`~pectoral_gym.envs.fish_env.PectoralFishEnv`), on the settings of the simulation-only full-model id
    (:data:`pectoral_gym.versions.SIMULATION_IDS`, ``EnvConfig``'s defaults) where ``**kwargs`` set no other
    (``observe_fins=True``: the robot-ready ids' observation), computed by the same task core
    (:class:`pectoral_gym.envs.tasks.table.TaskState`, the task table's row for ``task``) on the
    *estimated* state: for the same states and commands both give the same observations, rewards and
    ``info`` (``tests/test_task_core.py``). An overhead camera frame is tracked
    (:class:`pectoral_gym.hardware.vision.tracker.MarkerTracker`: red front marker, blue back marker) and a high-gain
    observer (:class:`pectoral_gym.hardware.vision.observer.HighGainObserver`) estimates the body-frame velocities. Each
    ``step`` sends the fin command through :class:`pectoral_gym.hardware.radio.link.RadioLink` and then watches the
    camera for one ``control_period`` of wall-clock time (real-time pacing). The fins latch a new pattern at their next
    stroke turning point, as in simulation. With an emulated robot (:mod:`pectoral_gym.hardware.emulator`) the
    experiment clock may run ``speed`` times faster than the wall clock, or on simulated time (``clock``, a
    :class:`pectoral_gym.hardware.clock.VirtualClock`: lockstep emulation, ``docs/hardware.md``).

    ## Action Space

    ``Box(-1, 1, (8,), float32)``, mapped exactly as in ``PectoralFishEnv``; then the PC-side safety
    rules clip the command to the servo limits and rate-limit it
    (:class:`pectoral_gym.hardware.safety.rules.CommandFilter`). The task core is given the command actually sent,
    normalised: the observation's last action and the energy term are those of that command. A non-finite action raises
    ``ValueError`` and nothing is sent.

    The entries (bias, amplitude, period, ratio of the right fin, then the left) and their ranges are
    ``PectoralFishEnv``'s Action Space table.

    ## Observation Space

    ``Box(-inf, inf, (19,), float32)``, as in ``PectoralFishEnv``, from the observer's estimate.

    | Num   | Observation                                            | Unit  |
    |-------|--------------------------------------------------------|-------|
    | 0-1   | X, Y, position in the tank (estimated)                 | m     |
    | 2-3   | cos psi, sin psi (heading, estimated)                  | -     |
    | 4-6   | vx, vy (body frame), omega: estimates averaged over the control period | m/s, m/s, rad/s |
    | 7-8   | target position relative to the fish, body frame       | m     |
    | 9-10  | target velocity, body frame (zero for ``goal``)        | m/s   |
    | 11-18 | the command actually sent, normalised (after clipping and rate limiting) | - |

    ## Rewards

    The terms of ``PectoralFishEnv`` (``reward_progress``, ``reward_goal``, ``reward_wall``,
    ``reward_energy``, ``reward_time`` for ``goal``; ``reward_tracking``, ``reward_wall``,
    ``reward_energy`` for ``track``; a registered task's own), each in ``info``, evaluated on the
    estimated state and the command sent.

    ## Starting State

    The fish is wherever it is: ``reset`` stops the fins and waits (up to ``stop_timeout`` s) for the robot
    to confirm they are still, calls ``reset_hook(np_random)`` (e.g. "put the fish back at rest", or
    placing an emulated fish), waits up to ``reset_timeout`` s for tracked poses in frames captured after
    the hook returned (plus ``safety.max_frame_lead``) and starts the observer there; the task draws its
    episode as in simulation and adapts it to the actual
    start (``TaskState.reset_at``). ``goal``: the goal redrawn until it lies 0.3 to 1.0 m from the
    actual start; ``track``: the reference ellipse drawn as in simulation.

    ## Episode End

    * Termination: the task's own ends (nose or tail outside the tank; ``goal`` reached), or the
      **geofence** (:class:`pectoral_gym.hardware.safety.geofence.Geofence`): some part of the fish, fin tips included,
      closer to a wall than its stopping distance at the measured speed (with its uncertainty, at most the
      physical bound :class:`pectoral_gym.hardware.safety.geofence.SpeedBound`) plus ``safety.stop_rule.margin``
      (``info["safety_stop"] = "geofence"``).
    * Truncation: ``max_episode_steps`` steps; tracking lost for longer than ``safety.tracking_timeout``
      (``"tracking_lost"``, with the reason in ``info["tracking"]["reason"]``: the tracker's, or a
      rejected frame's, e.g. ``"frozen_frame"``, ``"timestamp_future"``); no answer from the robot for
      ``safety.link_timeout`` (``"link_lost"``); this PC no longer controls the robot (the link's
      ``control_lost``: ``"taken_over"``, ``"robot_busy"``, ``"robot_rebooted"``); :meth:`stop` or a
      signal (``"stop"``, latched until :meth:`rearm`). Several at once: reported by priority
      (``pectoral_gym.hardware.safety.supervisor.PRIORITY``, ``docs/guide/safety.md``), all in ``info["safety_stops"]``.
    * A safety supervisor (:class:`pectoral_gym.hardware.safety.supervisor.Supervisor`) applies these rules in its own
      thread, also while the program is outside ``step()``, and sends STOP the moment one trips; the next
      ``step()`` reports it. Every command carries a lease (``safety.lease``, ``docs/protocol.md``): the
      robot stops by itself unless ``step()`` is called again in time, whatever happens to this process.
    * ``close()`` sends STOP and may be called twice; it also runs at interpreter exit, on leaving a
      ``with`` block, and on Ctrl-C / SIGTERM (handlers installed by the env, ``handle_signals``).

    ``info`` also holds ``"link"`` (:meth:`RadioLink.health`), ``"tracking"`` (``ok``, ``lost_for``,
    ``reason``, ``confidence``, ``frames``, ``lost_frames``), ``"command"`` (the ``(2, 4)`` command sent),
    ``"pose"`` (last measured X, Y, psi), ``"estimate"`` (the state used), ``"overrun"`` (s the step came late).

    ## Arguments

    | Argument            | Default        | Unit | Description |
    |---------------------|----------------|------|-------------|
    | ``port``            |                |      | ``serial_for_url`` URL, serial-like object or :class:`RadioLink` |
    | ``camera``          |                |      | ``camera.open_source`` spec or a frame source |
    | ``task``            | ``"goal"``     |      | ``"goal"``, ``"track"`` or a registered task (``envs.task_core``) |
    | ``control_period``  | 0.5            | s    | time between actions |
    | ``calibration``     | ``None``       |      | calibration JSON; ``None``: default camera model |
    | ``safety``          | defaults       |      | :class:`pectoral_gym.hardware.safety.rules.SafetyConfig` |
    | ``speed``           | 1.0            |      | experiment seconds per wall second (emulated robots only) |
    | ``frame_period``    | 1/30           | s    | camera polling period |
    | ``observer_epsilon``| 0.1            | s    | high-gain observer time constant |
    | ``max_episode_steps`` | 240          |      | truncation |
    | ``reset_hook``      | ``None``       |      | called with ``np_random`` at each reset |
    | ``reset_timeout``   | 5.0            | s    | wall time to wait for a tracked pose at reset |
    | ``**kwargs``        |                |      | other ``EnvConfig`` fields (ranges, weights, ``params``) |
    | ``render_mode``     | ``None``       |      | ``"rgb_array"``: the last camera frame |
    | ``handle_signals``  | ``True``       |      | SIGINT/SIGTERM send STOP (main thread only; restored at close) |
    | ``take_over``       | ``False``      |      | take the robot from another live session (``RadioLink``) |
    | ``stop_timeout``    | 2.0            | s    | wall time ``reset`` waits for the robot to confirm STOP |
    | ``clock``           | ``REAL_CLOCK`` |      | the stack's clock (``pectoral_gym.hardware.clock``) |
    | ``run_log``         | ``None``       |      | the run log (``pectoral_gym.runlog.RunLogWriter``) |

    ## Version History

    * v0: Initial version: leased commands (protocol v2), a safety supervisor thread, frame checks,
      peak-rate servo clipping (the fastest simulated pattern runs at a longer period), STOP at exit and on
      signals; the task core of the simulated envs (``TaskState``), any task of the task table, the energy
      term pricing the command sent; a latched operator stop (:meth:`rearm`), reset waiting for a confirmed
      stop, frames after the hook only, a noise-robust and physically bounded geofence speed, ``step()``
      raising with no episode armed; ``clock`` (lockstep emulation in simulated time; the wall clock by
      default); ``run_log`` (what the model's calibration needs, ``docs/run-log.md``; on the env's experiment
      clock; settable any time).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, port: str | RadioLink, camera, task: str = "goal", control_period: float = 0.5,
                 calibration=None, safety: SafetyConfig | None = None, speed: float = 1.0,
                 frame_period: float = 1.0 / 30.0, observer_epsilon: float = 0.1, max_episode_steps: int = 240,
                 reset_hook: Callable[[np.random.Generator], None] | None = None, reset_timeout: float = 5.0,
                 tracker=None, observer=None, render_mode: str | None = None, handle_signals: bool = True,
                 take_over: bool = False, stop_timeout: float = 2.0, clock: Clock = REAL_CLOCK, run_log=None,
                 **kwargs: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if not (math.isfinite(speed) and speed > 0) or not frame_period > 0 or int(max_episode_steps) < 1:
            raise ValueError("speed and frame_period must be > 0 and max_episode_steps >= 1")
        if not (math.isfinite(stop_timeout) and stop_timeout > 0):
            raise ValueError(f"stop_timeout must be a finite number > 0 s, got {stop_timeout!r}")
        self.config = env_config(task, control_period, kwargs)
        self.safety = safety or SafetyConfig()
        self.speed, self.frame_period = float(speed), float(frame_period)
        self.max_episode_steps = int(max_episode_steps)
        self.reset_hook, self.reset_timeout = reset_hook, float(reset_timeout)
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)
        low, high = observation_bounds(self.config.control_period, self.config.ref_speed,  # the simulated envs'
                                       self.config.observe_fins)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        # A physical system: the checker must not expect equal observations for equal seeds.
        self.spec = EnvSpec("HardwareFish-v0", entry_point="pectoral_gym.hardware.env:HardwareFishEnv",
                            nondeterministic=True)
        self._closed = False
        self._episode = False  # an episode is armed (a reset succeeded and no reset has started since)
        self.stop_timeout = float(stop_timeout)
        self.clock, self.stack, self.recorder = clock, None, RunRecorder(run_log)
        self.link = self.camera = self.supervisor = None
        try:
            self._build(port, camera, calibration, tracker, observer, observer_epsilon, take_over)
        except BaseException:
            self._release()
            raise
        # Lockstep: the signal is taken where the main thread next waits on the clock, never inside its scheduler.
        defer = getattr(self.clock, "defer_signals", None)
        stops = install_stop_handlers if defer is None else defer
        self._restore_signals = stops(self.stop) if handle_signals else (lambda: None)
        atexit.register(self.close)

    def _build(self, port, camera, calibration, tracker, observer, observer_epsilon, take_over) -> None:
        """Open the robot stack (:func:`pectoral_gym.hardware.stack.open_stack`; ``__init__``'s fallible part)."""
        self._origin = self.clock.monotonic()
        stack = open_stack(port, camera, self.config, self.safety, self.speed, self.frame_period, calibration,
                           tracker, observer, observer_epsilon, take_over, origin=self._origin, clock=self.clock)
        self.stack = stack
        self.link, self.camera, self.tracker, self.observer = stack.link, stack.camera, stack.tracker, stack.observer
        self.filter, self.fin_replay, self.geofence = stack.filter, stack.fin_replay, stack.geofence
        self.supervisor, self.watch = stack.supervisor, stack.supervisor.watch
        self._velocity_sum = np.zeros(3)  # observer velocities summed over the current control period
        self._velocity_count = 0
        self.task_state = TaskState(1, self.config)  # the simulated envs' task core, fed the observer's estimate
        self._act = np.zeros((1, ACTION_SIZE))
        self._state = np.zeros(6)
        self._last_measure = -math.inf
        self._steps = 0
        self._observing = False
        self._next_tick = 0.0
        self._lease_end = -math.inf  # experiment time the robot's lease of the last command ends
        self._sent = -math.inf  # experiment time the last command, or its renewal, was sent

    def _release(self) -> None:
        """Release the robot stack, if it was opened (a failed :func:`open_stack` releases its own parts)."""
        if self.stack is not None:
            self.stack.release()

    # ------------------------------------------------------------ clock
    def now(self) -> float:
        """Experiment time [s] (``clock`` time since construction times ``speed``)."""
        return (self.clock.monotonic() - self._origin) * self.speed

    def _sleep(self, duration: float) -> None:
        if duration > 0:
            self.clock.sleep(duration / self.speed)

    def _renewal(self, t: float) -> float | None:
        """The lease of a renewal of the step's command due at experiment time ``t`` (``linkclock.renewal_lease``)."""
        rtt, horizon = getattr(self.link, "rtt", lambda: None)(), getattr(self.link, "deadline_horizon", None)
        if rtt is None or horizon is None:  # a stand-in link, or no round trip measured yet
            return None
        return renewal_lease(t, self._sent, self._lease_end, horizon, rtt * self.speed)

    @property
    def run_log(self):
        """The :class:`pectoral_gym.runlog.RunLogWriter` the env writes to, or ``None`` (settable)."""
        return self.recorder.writer

    @run_log.setter
    def run_log(self, writer) -> None:
        self.recorder.writer = writer

    def _take_latches(self) -> None:
        """The robot's latch reports (``docs/protocol.md``, LATCH): into the run log, for the calibration.

        The supervisor's thread takes them from the link and feeds them to its liveness check's replays first
        (:class:`pectoral_gym.hardware.safety.latch_reports.LatchReports`). Not into the replayed fins the policy
        observes: those stay the fins as the commands make them from the moment they are sent, the timing of the
        simulated envs policies train in (``docs/hardware.md``, "Policies that observe the fins").
        """
        supervisor = self.supervisor
        if not supervisor.armed:  # a reset: also those still in the link (the supervisor's thread feeds no replay)
            supervisor.latches.take(None)
        for t, latch in supervisor.latches.drain():
            self.recorder.latch(t, latch)

    # ------------------------------------------------------------ camera
    def _observe(self) -> None:
        """Feed the observer the supervisor's new measurements (and take the robot's latch reports)."""
        self._take_latches()
        for t, x, y, psi in self.supervisor.drain():
            if self._observing and t > self._last_measure:
                self.recorder.record("pose", t, x, y, psi, self.supervisor.confidence)
                self._state = np.asarray(self.observer.update(t, x, y, psi), dtype=float).copy()
                self._last_measure = t
                self._velocity_sum += self._state[3:6]
                self._velocity_count += 1

    # ------------------------------------------------------------ gym API (reset: EpisodeStart)
    def step(self, action):
        """Send the command, watch the fish for one control period; returns the Gymnasium 5-tuple."""
        arr = check_action(action)  # raises before anything is sent
        if self._closed:
            raise RuntimeError("the environment is closed")
        if not self._episode:
            raise RuntimeError("no episode is armed: call reset() first (before the first reset, or after a reset "
                               "that failed); nothing was sent to the robot")
        task, config = self.task_state, self.config
        now = self.now()
        # The action's patterns (the env's mapping), then the safety rules; each command holds for a period.
        command = self.filter(config.decode(arr.reshape(2, ACTION_SIZE // 2)), config.control_period)
        # The task core gets the command sent: last-action observation and energy term are the sent command's.
        self._act[0] = np.concatenate([config.encode(command[0]), config.encode(command[1])])
        task.apply(self._act)
        sup = self.supervisor
        period, lease = self.config.control_period, self.safety.lease
        self._next_tick = max(self._next_tick + period, now)  # a late step does not shorten the next one
        overrun = max(0.0, now - (self._next_tick - period))
        if now > self._lease_end:  # a late step: the robot's lease ran out
            if self.fin_replay is not None:
                self.fin_replay.stop(self._lease_end)
            self.recorder.record("stop", self._lease_end)
        if sup.send(command, lease):
            self._lease_end, self._sent = now + lease, now
            self.recorder.record("command", now, command)
            if self.fin_replay is not None:
                self.fin_replay.command(now, command)
        self._velocity_sum = np.zeros(3)
        self._velocity_count = 0
        while not sup.reason:
            t = self.now()
            remaining = self._next_tick - t
            if remaining <= 0:
                break
            if self._lease_end - t < remaining + self.safety.step_slack - 1e-3 and sup.send(command, lease):
                self._lease_end, self._sent = t + lease, t  # a long control period: renew while step() runs
            elif (renewal := self._renewal(t)) and sup.send(command, renewal):
                self._sent = t  # a slow radio: the same fins with a deadline from now, the lease's end unchanged
            self._sleep(min(self.frame_period, remaining))
            self._observe()
        self._observe()
        reason = sup.reason
        end = self.now()
        if end - self._last_measure > PREDICT_AFTER_FRAMES * self.frame_period and math.isfinite(self._last_measure):
            self._state = np.asarray(self.observer.predict(end), dtype=float).copy()
        task.observe(self._state[None])
        if self._velocity_count:
            # Velocities as in the simulated envs: means over the control period, not the last estimate
            # (the observer passes part of the fin-beat ripple).
            task.set_mean_velocity(0, self._velocity_sum / self._velocity_count)
        if self.fin_replay is not None:
            if reason:  # the fins were stopped (at the latest now)
                self.fin_replay.stop(end)
            self._observe_fins(end)
        self._steps += 1
        terminated = bool(task.terminated(0)) or "geofence" in sup.fired
        truncated = bool(reason) and not terminated or self._steps >= self.max_episode_steps
        if terminated or truncated:
            sup.trip(reason or "episode_end")
            reason = sup.reason if sup.reason != "episode_end" else reason
        if reason or terminated or truncated:
            self.recorder.record("stop", end)
        info = task.info(0)  # the simulated envs' keys and values
        info.update(safety_stop=reason, safety_stops=list(sup.fired), command=command.tolist(), pose=list(sup.pose),
                    estimate=self._state.tolist(), overrun=overrun, link=self.link.health(),
                    tracking={"ok": sup.track_ok, "lost_for": self.watch.lost_for(end), "reason": self.watch.reason,
                              "confidence": sup.confidence, "frames": sup.frames, "lost_frames": sup.lost_frames,
                              "rejected": dict(sup.frame_check.rejected), "latency": sup.latency})
        return task.obs[0].copy(), task.reward(0), terminated, truncated, info

    def _observe_fins(self, t: float | None = None) -> None:
        """The observation's fin block from the replayed fins at time ``t`` (default: where the replay is)."""
        if t is not None:
            self.fin_replay.advance(t)
        tk.observe_fins(self.fin_replay.fins, self.task_state.obs, float(self.config.period_range[1]))

    @property
    def target(self) -> list[float]:
        """Current target position ``[X, Y]`` in the tank [m]."""
        return self.task_state.ep[0, E_TX:E_TY + 1].tolist()

    def stop(self) -> None:
        """Operator stop: stop the fins now and latch ``"stop"`` until :meth:`rearm`; takes no lock (signal-safe).

        Sends STOP through :meth:`RadioLink.emergency_stop` and sets the supervisor's latch, at any moment
        (during :meth:`reset`, between steps, inside :meth:`step`, from any thread): commands are refused,
        the current step ends with ``"stop"``, and :meth:`reset` raises until :meth:`rearm` is called.
        Harmless after :meth:`close`.
        """
        if self.supervisor is not None:
            self.supervisor.stop_requested = True
        if self.link is not None and not self.link.closed:
            self.link.emergency_stop()

    def render(self):
        """``rgb_array``: the last camera frame as RGB, or ``None`` before the first."""
        if self.render_mode is None:
            gym.logger.warn("You are calling render method without specifying any render mode.")
            return None
        frame = self.supervisor.last_frame
        if frame is None:
            return None
        return np.ascontiguousarray(frame.image[..., ::-1])

    def close(self) -> None:
        """Send STOP, close the link and the camera (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._episode = False
        atexit.unregister(self.close)
        self._restore_signals()
        self._release()
