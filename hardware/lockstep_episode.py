"""One lockstep episode of ``deploy --emulate --lockstep`` on a fresh rig: the job, its result, the runner.

:mod:`pectoral_gym.hardware.lockstep_jobs` runs these episodes in one or more processes. Episode ``k`` of a run with
seed ``s`` runs on a rig of its own (emulated robot, radio link, camera,
:class:`pectoral_gym.hardware.clock.VirtualClock` from time 0, env) opened with the seed ``s + k``, the seed its
start, target and controller are reset with too. The controller is built once per process and reset per episode.
"""

from __future__ import annotations

import contextlib
import io
import math
import signal
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.deploy_checks import check_frame_size, first_frame
from pectoral_gym.hardware.deploy_controllers import make_controller
from pectoral_gym.hardware.deploy_episodes import random_start, run_episode
from pectoral_gym.hardware.emurig import RigConditions, open_rig
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.hardware.signal_latch import end_as

__all__ = ["EpisodeError", "EpisodeResult", "EpisodeRunner", "EpisodeSignalLatch", "LockstepJob",
           "episode_time_limit"]

_RESET_ALLOWANCE = 60.0  # simulated s an episode's resets, stop confirmations and camera checks may take at most


def episode_time_limit(job: LockstepJob) -> float:
    """Simulated seconds past which an episode's rig counts as stuck (``LockstepError``: a run that cannot end).

    Twice the episode's steps at its control period, plus :data:`_RESET_ALLOWANCE`: a step that overruns its
    period by as much again, every reset wait at its time-out, and still far below what a loop that never ends
    runs to. The run then ends with one line naming the waiting threads, instead of hanging.
    """
    period = float(job.settings.get("control_period", 0.5))
    return 2.0 * job.max_steps * period + _RESET_ALLOWANCE


@dataclass(frozen=True)
class LockstepJob:
    """Everything a process needs to run any episode of a lockstep deployment (picklable).

    Attributes:
        controller: ``"policy"``, ``"nmpc"`` or ``"hand"``.
        policy: Run folder or ``.zip`` of the policy (``controller="policy"`` only).
        seed: The run's seed: episode ``k`` is seeded with ``seed + k``.
        conditions: The emulated radio's and camera's conditions.
        settings: ``HardwareFishEnv`` keyword arguments (``task``, ``control_period`` [s], ...).
        safety: The safety supervisor's settings.
        max_steps: Steps per episode, >= 1.
        calibration: Camera calibration file, or ``None`` for the emulator's camera model.
        take_over: Take control of a robot another session drives (``HardwareFishEnv``'s ``take_over``).
        params: The emulated fish's :class:`pectoral_gym.model.params.FishParams` (``None``: Table 1's).
        scaling: The K file the hand law and the NMPC plan with (``None``: the shipped K).
        firmware: The emulated robot's rules (``pectoral_gym.hardware.emulated_firmware.FIRMWARES``).
    """

    controller: str = "hand"
    policy: str | None = None
    seed: int = 0
    conditions: RigConditions = RigConditions()
    settings: Mapping[str, Any] = field(default_factory=lambda: {"task": "goal", "control_period": 0.5})
    safety: SafetyConfig = SafetyConfig()
    max_steps: int = 240
    calibration: str | None = None
    take_over: bool = False
    params: Any = None
    scaling: str | None = None
    firmware: str = "python"


@dataclass
class EpisodeResult:
    """One episode's output.

    Attributes:
        episode: Its index.
        log: Its lines of ``steps.jsonl``.
        summary: :func:`pectoral_gym.hardware.deploy_episodes.run_episode`'s summary.
        link: The link's :meth:`~pectoral_gym.hardware.radio.link.RadioLink.health` once the rig is closed.
        solver: The controller's solve times [s], failed and late steps in this episode, or ``None`` for a
            controller that does not solve (``{"solve_times", "failures", "late"}``).
        run_log: Its records of the run log (:mod:`pectoral_gym.runlog`, no header), on its rig's clock
            (from 0).
    """

    episode: int
    log: str
    summary: dict[str, Any]
    link: dict[str, Any]
    solver: dict[str, Any] | None = None
    run_log: str = ""


class EpisodeError(RuntimeError):
    """An episode failed.

    Attributes:
        episode: Its index.
        setup: The failure is the settings', found by the rig or the env (``ValueError``): a bad argument.
        log: The episode's lines of ``steps.jsonl`` up to the failure.
    """

    def __init__(self, episode: int, message: str, setup: bool = False, log: str = ""):
        super().__init__(message)
        self.episode, self.setup, self.log = episode, setup, log


class EpisodeRunner:
    """Runs episodes of ``job``, each on a fresh rig, with one controller (``controller``, or built at first use)."""

    def __init__(self, job: LockstepJob, controller: Any = None, handle_signals: bool = True):
        from pectoral_gym.hardware.vision.cameramodel import CameraModel

        self.job, self.controller, self.handle_signals = job, controller, handle_signals
        self.latch: EpisodeSignalLatch | None = None  # run_lockstep's, for episodes in the calling thread
        self.model = CameraModel.default() if job.calibration is None else CameraModel.load(job.calibration)
        if controller is None and job.controller == "policy":
            from pectoral_gym.agents.training.policy import load_policy  # lazy: agents/ pulls in torch

            self.controller = load_policy(job.policy)

    def run(self, episode: int) -> EpisodeResult:
        """Episode ``episode`` on a rig opened with ``job.seed + episode``, closed before this returns."""
        from pectoral_gym.hardware.env import HardwareFishEnv
        from pectoral_gym.hardware.vision.tracker import MarkerTracker
        from pectoral_gym.runlog import RunLogWriter

        job, log, records = self.job, io.StringIO(), io.StringIO()
        try:
            with contextlib.ExitStack() as signals, contextlib.ExitStack() as resources:  # last in, first out
                try:
                    clock, robot, port, camera = open_rig(resources, job.seed + episode, job.conditions,
                                                          lockstep=True, params=job.params, firmware=job.firmware)
                    clock.limit = episode_time_limit(job)
                    if self.latch is not None:  # Ctrl-C and SIGTERM taken at the rig's waits until it is closed
                        signals.callback(self.latch.hand_to(clock))
                    inset = job.settings.get("start_inset", tk.START_INSET)  # the policy's own, as it trained
                    check_frame_size(first_frame(camera, clock=clock), self.model, job.calibration)
                    env = HardwareFishEnv(port, camera, safety=job.safety, max_episode_steps=job.max_steps,
                                          reset_hook=lambda rng: robot.place(*random_start(rng, inset)),
                                          tracker=MarkerTracker(self.model), take_over=job.take_over, clock=clock,
                                          handle_signals=self.handle_signals, **job.settings)
                    resources.callback(env.close)
                    env.run_log = RunLogWriter(records, "emulator", env.config.control_period)
                    if self.controller is None:  # a step's computing costs no simulated time: no budget applies
                        self.controller = make_controller(job.controller, env.config, math.inf, job.safety,
                                                          job.scaling)
                except ValueError as err:  # the settings, found wrong by the rig or the env
                    raise EpisodeError(episode, str(err), setup=True) from err
                stats = self._solver_stats()
                summary = run_episode(env, self.controller, episode, log, job.seed, robot)
        except (RuntimeError, OSError) as err:  # a device's failure (no fish seen, no stop confirmed, ...)
            if isinstance(err, EpisodeError):
                raise
            raise EpisodeError(episode, str(err), log=log.getvalue()) from err
        solver = None
        if stats is not None:  # this episode's share of the controller's running totals
            now = self._solver_stats()
            solver = {"solve_times": now["solve_times"][len(stats["solve_times"]):],
                      "failures": now["failures"] - stats["failures"], "late": now["late"] - stats["late"]}
        run_log = records.getvalue().split("\n", 1)[1]  # the records; the deploy writes one header for the run
        return EpisodeResult(episode, log.getvalue(), summary, env.link.health(), solver, run_log)

    def _solver_stats(self) -> dict[str, Any] | None:
        c = self.controller
        if not hasattr(c, "solve_times"):
            return None
        return {"solve_times": [float(t) for t in c.solve_times], "failures": int(c.failures), "late": int(c.late)}


class EpisodeSignalLatch:
    """Ctrl-C and SIGTERM for lockstep episodes in the calling thread: never acted on inside a rig's scheduler.

    The handler records the signal; :meth:`take` acts on it between rigs, and :meth:`hand_to` passes it to a
    rig's clock, which acts at its main thread's next wait (:meth:`VirtualClock.defer_signals`) and then calls
    this handler back to end the run. Acting: ``KeyboardInterrupt`` for SIGINT, ``SystemExit(143)`` for SIGTERM
    (or the handler installed before, if one was). A second signal acts at once.
    """

    def __init__(self) -> None:
        self.pending: int | None = None
        self._in_rig = False  # a rig's clock has the signals: a call of ours is that clock ending the run
        self._previous: dict[int, Any] = {}

    def install(self) -> Callable[[], None]:
        """Install the handler (main thread only, else nothing); returns a function that restores the old ones."""
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        self._previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
        for sig in self._previous:
            signal.signal(sig, self._handler)

        def restore() -> None:
            for sig, old in self._previous.items():
                if signal.getsignal(sig) == self._handler:
                    signal.signal(sig, old)

        return restore

    def _handler(self, signum: int, frame: Any) -> None:
        if self._in_rig or self.pending is not None:
            self.pending = None
            self._end(signum)
        self.pending = signum

    def _end(self, signum: int) -> None:
        end_as(signum, self._previous.get(signum))

    def take(self) -> None:
        """Act on a recorded signal now (call where no rig is open)."""
        if self.pending is not None:
            signum, self.pending = self.pending, None
            self._end(signum)

    def hand_to(self, clock: Any) -> Callable[[], None]:
        """Let ``clock`` (a rig's :class:`VirtualClock`) take the signals, with any recorded one; returns the undo."""
        restore = clock.defer_signals()
        if restore is None or not self._previous:
            return lambda: None
        self._in_rig = True
        if self.pending is not None:
            clock.record_signal(self.pending)
            self.pending = None

        def undo() -> None:
            self._in_rig = False
            restore()

        return undo
