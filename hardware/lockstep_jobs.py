"""Independent lockstep episodes for ``deploy --emulate --lockstep``: each on a fresh rig, in one or more processes.

Episode ``k`` of a run with seed ``s`` runs on a rig of its own (emulated robot, radio link, camera,
:class:`pectoral_gym.hardware.clock.VirtualClock` from time 0, env) opened with the seed ``s + k``, the seed
its start, target and controller are reset with too. Its records therefore depend on ``s + k`` and the
arguments alone, never on the episodes run before it or on the process it runs in: episode ``k`` of
``--seed s`` is episode 0 of ``--seed s+k`` (apart from its number), and :func:`run_lockstep` gives the same
results for any number of worker processes. The controller is built once per process and reset per episode.

Workers are started with the ``spawn`` method (numba's and the clock's threads in the parent make ``fork``
unsafe); each takes the next episode index from the parent when it is free, and sends back the episode's
lines of ``steps.jsonl`` and its summary; the parent hands them on in episode order.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import multiprocessing
import signal
import threading
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from types import SimpleNamespace
from typing import Any

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.deploy import make_controller, random_start, run_episode, solver_summary
from pectoral_gym.hardware.deploy_checks import check_frame_size, first_frame
from pectoral_gym.hardware.emurig import RigConditions, open_rig
from pectoral_gym.hardware.radio.linkstatus import LinkStats
from pectoral_gym.hardware.safety.rules import SafetyConfig, install_stop_handlers
from pectoral_gym.hardware.signal_latch import end_as

__all__ = ["EpisodeError", "EpisodeResult", "LockstepJob", "episode_time_limit", "merge_link", "merge_solver",
           "run_lockstep", "shift_records"]

RUN_LOG_GAP = 1.0  # s between one episode's last run-log record and the next episode's start in a merged run log

_JOIN_TIMEOUT = 5.0  # wall s a terminated worker gets to end before it is killed
# Wall seconds the parent waits for any worker's next result: far above an episode's (seconds to a minute, plus a
# cold numba compile of up to ~100 s), far below "for ever".
EPISODE_WALL_TIMEOUT = 1800.0
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
        summary: :func:`pectoral_gym.hardware.deploy.run_episode`'s summary.
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


class _Runner:
    """Runs episodes of ``job``, each on a fresh rig, with one controller (``controller``, or built at first use)."""

    def __init__(self, job: LockstepJob, controller: Any = None, handle_signals: bool = True):
        from pectoral_gym.hardware.vision.cameramodel import CameraModel

        self.job, self.controller, self.handle_signals = job, controller, handle_signals
        self.latch: _SignalLatch | None = None  # run_lockstep's, for episodes in the calling thread
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


class _SignalLatch:
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


def merge_link(healths: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One link report for a run of independent episodes: each counter summed, the rest the last episode's link."""
    out = dict(healths[-1])
    for counter in (f.name for f in dataclasses.fields(LinkStats)):
        out[counter] = sum(int(h[counter]) for h in healths)
    return out


def shift_records(text: str, episode: int, after: float | None) -> tuple[list[dict[str, Any]], float | None]:
    """An episode's run-log records (on its rig's clock, from 0) moved to start :data:`RUN_LOG_GAP` after ``after``.

    A run log's time never goes backwards (``docs/run-log.md``), but every lockstep episode has a clock of its own:
    the merged log puts the episodes one after another, each record's ``t`` shifted by the same amount (none for
    ``after=None``, the first), and its ``episode`` record numbered ``episode``. Returns ``(the records, the last
    shifted t)`` (``after`` if there is no record).
    """
    records = [json.loads(line) for line in text.splitlines() if line]
    if not records:
        return [], after
    shift = 0.0 if after is None else after + RUN_LOG_GAP - min(r["t"] for r in records)
    for record in records:
        record["t"] += shift
        if record["type"] == "episode":
            record["episode"] = int(episode)
    return records, max(r["t"] for r in records)


def merge_solver(solvers: Sequence[Mapping[str, Any] | None]) -> dict[str, Any] | None:
    """:func:`pectoral_gym.hardware.deploy.solver_summary` over the episodes' solver figures (``None``: no solver)."""
    parts = [s for s in solvers if s is not None]
    if not parts:
        return None
    total = SimpleNamespace(solve_times=[t for s in parts for t in s["solve_times"]],
                            failures=sum(s["failures"] for s in parts), late=sum(s["late"] for s in parts))
    return solver_summary(total)


def run_lockstep(job: LockstepJob, episodes: Sequence[int], jobs: int = 1,
                 on_result: Callable[[EpisodeResult], None] | None = None, progress: bool = True,
                 controller: Any = None) -> list[EpisodeResult]:
    """Run the episodes ``episodes`` of ``job``, each on a fresh rig; returns their results in the order given.

    Args:
        job: The deployment.
        episodes: Episode indices (distinct).
        jobs: Processes: 1 runs in this thread (which joins each episode's lockstep); more start that many
            workers (at most one per episode), each running one episode at a time.
        on_result: Called with each result in the order of ``episodes``, as soon as those before it are in.
        progress: Show a progress bar over the episodes.
        controller: A controller for ``jobs=1`` (e.g. the policy the caller loaded already); else one is built.

    Raises:
        EpisodeError: An episode (or a worker) failed; every worker is ended first.
    """
    from tqdm import tqdm

    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    order = list(episodes)
    done: dict[int, EpisodeResult] = {}
    results: list[EpisodeResult] = []

    def collect(result: EpisodeResult) -> None:
        done[result.episode] = result
        bar.update(1)
        while len(results) < len(order) and order[len(results)] in done:
            results.append(done.pop(order[len(results)]))
            if on_result is not None:
                on_result(results[-1])

    with tqdm(total=len(order), desc="episodes", disable=not progress) as bar:
        if jobs == 1:
            runner = _Runner(job, controller)
            runner.latch = _SignalLatch()
            restore = runner.latch.install()
            try:
                for episode in order:
                    runner.latch.take()  # a signal that came between two rigs ends the run here
                    collect(runner.run(episode))
            finally:
                restore()
        elif order:
            _run_workers(job, order, min(jobs, len(order)), collect)
    return results


def _run_workers(job: LockstepJob, order: list[int], jobs: int, collect: Callable[[EpisodeResult], None]) -> None:
    """Run ``order``'s episodes in ``jobs`` spawned workers; every worker is ended and joined on every path out."""
    ctx = multiprocessing.get_context("spawn")
    queue = list(reversed(order))  # popped from the end: the lowest index first
    busy: dict[Connection, int] = {}  # a worker's pipe -> the episode it runs
    procs: dict[Connection, Any] = {}
    finished = False
    restore = install_stop_handlers(lambda: None)  # SIGTERM too ends in the finally below (main thread only)
    try:
        for rank in range(jobs):
            conn, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, job), name=f"lockstep-worker-{rank}", daemon=True)
            proc.start()
            child.close()
            procs[conn] = proc
            busy[conn] = queue.pop()
            conn.send(busy[conn])
        while busy:
            ready = wait(list(busy), timeout=EPISODE_WALL_TIMEOUT)  # a message, or EOF when its worker died
            if not ready:  # every clock wait ends or fails in simulated time: a worker stuck outside the clock
                episode = min(busy.values())
                raise EpisodeError(episode, f"no episode ended within {EPISODE_WALL_TIMEOUT:g} s of wall time "
                                            f"(episodes {sorted(busy.values())} running): a worker is stuck")
            for conn in ready:
                episode = busy[conn]
                try:
                    kind, payload = conn.recv()
                except (EOFError, OSError):
                    procs[conn].join(_JOIN_TIMEOUT)
                    raise EpisodeError(episode, f"its worker process ended (exit code {procs[conn].exitcode})") \
                        from None
                if kind == "error":
                    raise EpisodeError(episode, *payload)
                collect(payload)
                busy.pop(conn)
                if queue:
                    busy[conn] = queue.pop()
                    conn.send(busy[conn])
                else:
                    conn.send(None)  # no more work: the worker ends
        finished = True
    finally:
        restore()
        for proc in procs.values():
            if not finished and proc.is_alive():  # a failure or Ctrl-C: the other workers' episodes are moot
                proc.terminate()
        for conn, proc in procs.items():
            proc.join(_JOIN_TIMEOUT)
            if proc.is_alive():
                proc.kill()
                proc.join()
            conn.close()


def _worker(conn: Connection, job: LockstepJob) -> None:
    """A worker process: run the episodes the parent sends (``None``: stop), reply with each result or the error."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the parent ends us
    try:
        runner = _Runner(job, handle_signals=False)
    except BaseException as err:  # noqa: BLE001 - reported to the parent, which names it
        with contextlib.suppress(OSError):
            conn.send(("error", (_describe(err), isinstance(err, ValueError), "")))
        return
    with contextlib.suppress(EOFError, OSError):  # the parent is gone: nobody to report to
        while (episode := conn.recv()) is not None:
            try:
                result = runner.run(episode)
            except BaseException as err:  # noqa: BLE001 - reported to the parent, which names the episode
                if isinstance(err, EpisodeError):
                    conn.send(("error", (str(err), err.setup, err.log)))
                else:
                    conn.send(("error", (_describe(err), False, "")))
                return
            conn.send(("result", result))


def _describe(err: BaseException) -> str:
    """What went wrong, for the parent to print: the error and its traceback (an unexpected failure)."""
    if isinstance(err, (RuntimeError, OSError)):  # e.g. a policy that cannot be loaded: one line
        return str(err)
    return f"{type(err).__name__}: {err}\n{''.join(traceback.format_exception(err)).rstrip()}"
