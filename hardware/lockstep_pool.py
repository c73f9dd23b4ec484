"""Worker processes for lockstep episodes, which may be started before their job is known.

A :class:`LockstepPool` spawns its workers at once; each can do its start-up (the imports of the rig, the camera
model, numba's kernels loaded by a short episode of the hand law, the imports of torch and Stable-Baselines3)
while the parent does something else, e.g. train the policy the workers will run. The start-up runs in a thread of
its own at the lowest priority (Linux's ``SCHED_IDLE``: it runs only on a core nothing else wants; nice 19 would
still take a share of a core beside a parent at nice 10, scheduler weights 15 against 110), on any core, so that
the parent's own work keeps its cores. The episodes run at the worker's own priority, on its own core. A worker
then takes one job (:class:`~pectoral_gym.hardware.lockstep_episode.LockstepJob`), and episode indices until it is
told to stop: :func:`pectoral_gym.hardware.lockstep_jobs.run_lockstep` deals them out. Nothing a worker does
before its job changes an episode's results, which depend on its seed and the job alone
(:mod:`pectoral_gym.hardware.lockstep_jobs`).

Each worker runs its episodes on a core of its own where there are enough cores, as batch work (``SCHED_BATCH``):
see :mod:`pectoral_gym.hardware.lockstep_jobs`. A worker ignores Ctrl-C (it reaches the whole process group: the
parent ends the workers) and ends when its pipe closes, so a parent that dies leaves no worker behind. The pool
ends every worker on every path out of its ``with`` block; within it, SIGTERM ends the parent as
``SystemExit(143)`` (where no handler of its own is installed), so that the block's end still runs.

This module imports only the standard library at its top: a spawned worker imports it before its start-up is
moved to the low-priority thread.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

__all__ = ["LockstepPool", "START_UP_NICE", "START_UP_WAIT"]

START_UP_NICE = 19  # the niceness of a worker's start-up thread where there is no SCHED_IDLE
START_UP_WAIT = 300.0  # wall s a run waits for a start-up at the worker's own priority before it replaces the worker
_JOIN_TIMEOUT = 5.0  # wall s a terminated worker gets to end before it is killed


class LockstepPool:
    """``size`` spawned lockstep workers, started now, each taking one job later (a context manager).

    Args:
        size: Workers, >= 1.
        cores: The core each runs its episodes on, or ``None`` for any (:func:`~pectoral_gym.hardware.
            lockstep_jobs.worker_cores`'s list; default: not pinned).
        warm_up: Do the start-up before the job comes (a pool started ahead of its job); ``False`` for a pool
            whose job follows at once, where the first episode does the same work.
        policy: Also import torch and Stable-Baselines3 in the start-up (the job will run a trained policy).
        idle: Run the start-up at the lowest priority (Linux's ``SCHED_IDLE``, else nice
            :data:`START_UP_NICE`); ``False``: at the worker's own.

    Attributes:
        conns: The parent's end of each worker's pipe, in worker order.
        procs: The worker processes, in the same order.
        used: A run took the workers (a pool serves one run).
        replaced: Workers replaced by fresh ones when the run came, their start-up unfinished (:meth:`take`).
    """

    def __init__(self, size: int, cores: list[int | None] | None = None, warm_up: bool = True,
                 policy: bool = True, idle: bool = True):
        if size < 1:
            raise ValueError(f"a pool needs at least one worker, got {size}")
        self.cores = [None] * size if cores is None else list(cores)
        if len(self.cores) != size:
            raise ValueError(f"{len(self.cores)} cores given for {size} workers")
        self.conns: list[Connection] = []
        self.procs: list[Any] = []
        self.used = False
        self.replaced = 0
        self._warm_up, self._policy, self._idle = warm_up, policy, idle
        self._restore: Callable[[], None] = lambda: None
        try:
            for rank in range(size):
                self._start(rank, warm_up)
        except BaseException:
            self.close()
            raise

    def _start(self, rank: int, warm_up: bool) -> None:
        """Start worker ``rank`` (in place of the one before, if any)."""
        ctx = multiprocessing.get_context("spawn")  # numba's and the clock's threads in the parent: no fork
        conn, child = ctx.Pipe()
        proc = ctx.Process(target=_worker, args=(child, self.cores[rank], warm_up, self._policy, self._idle),
                           name=f"lockstep-worker-{rank}", daemon=True)
        proc.start()
        child.close()
        if rank < len(self.procs):
            self.conns[rank], self.procs[rank] = conn, proc
        else:
            self.conns.append(conn)
            self.procs.append(proc)

    def take(self) -> None:
        """Make every worker ready to take its job at once (before the job is sent; a run calls it).

        A start-up at the worker's own priority is waited for. One at the lowest priority that has not ended is
        replaced by a fresh worker without it: on a busy machine the rest of it could take far longer than a start
        at the worker's own priority, and would hold up the episodes meanwhile.
        """
        if not self._warm_up:
            return
        for rank, conn in enumerate(self.conns):
            try:
                ready = conn.poll(0.0 if self._idle else START_UP_WAIT) and conn.recv() == ("ready", None)
            except (EOFError, OSError):  # it died: a fresh one runs the episodes, or names their failure
                ready = False
            if not ready:
                proc = self.procs[rank]
                proc.terminate()
                proc.join(_JOIN_TIMEOUT)
                if proc.is_alive():
                    proc.kill()
                    proc.join()
                conn.close()
                self._start(rank, warm_up=False)
                self.replaced += 1

    def __len__(self) -> int:
        return len(self.procs)

    def __enter__(self) -> LockstepPool:
        """Make SIGTERM end this thread as ``SystemExit(143)`` until the block ends (main thread, default only)."""
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL):
            signal.signal(signal.SIGTERM, _sigterm)
            self._restore = _restore_sigterm
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.close()
        finally:
            self._restore()
            self._restore = lambda: None

    def close(self, finished: bool = False) -> None:
        """End every worker and join it (idempotent).

        ``finished``: every worker was told to stop and may end by itself; otherwise (a failure, Ctrl-C, a pool
        never used) the live ones are terminated at once.
        """
        for proc in self.procs:
            if not finished and proc.is_alive():
                proc.terminate()
        for conn, proc in zip(self.conns, self.procs, strict=True):
            proc.join(_JOIN_TIMEOUT)
            if proc.is_alive():
                proc.kill()
                proc.join()
            conn.close()


def _sigterm(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _restore_sigterm() -> None:
    if signal.getsignal(signal.SIGTERM) is _sigterm:  # not if someone installed their own on top since
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _worker(conn: Connection, core: int | None, warm_up: bool, policy: bool, idle: bool) -> None:
    """A worker: start up, take the job, run the episodes the parent sends (``None``: stop), reply to each.

    Replies: ``("ready", None)`` once the start-up ended (with ``warm_up`` only), then ``("result",
    EpisodeResult)`` for each episode, or ``("error", (message, setup, log))``, after which it ends.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the parent ends us
    if hasattr(os, "SCHED_BATCH"):  # the threads made from here on inherit it (on Linux a thread's own setting)
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    if warm_up:  # unpinned: on the core the parent leaves idle, where there is one
        threading.Thread(target=_start_up, args=(conn, policy, idle), name="lockstep-start-up", daemon=True).start()
    with contextlib.suppress(EOFError, OSError):  # the parent is gone: nobody to report to
        job = conn.recv()  # blocked without the interpreter lock: the start-up has it to itself
        if job is None:
            return
        if core is not None:  # before the rig's threads start: they inherit it
            with contextlib.suppress(OSError):  # a core taken away since: run anywhere, as unpinned
                os.sched_setaffinity(0, {core})
        _serve(conn, job)


def _serve(conn: Connection, job: Any) -> None:
    """Run ``job``'s episodes as the parent sends their indices, until ``None``."""
    from pectoral_gym.hardware.lockstep_episode import EpisodeError, EpisodeRunner

    try:
        runner = EpisodeRunner(job, handle_signals=False)
    except BaseException as err:  # noqa: BLE001 - reported to the parent, which names it
        conn.send(("error", (_describe(err), isinstance(err, ValueError), "")))
        return
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


def _start_up(conn: Connection, policy: bool, idle: bool) -> None:
    """The start-up a job's first episode would pay, at the lowest priority with ``idle``; then ``"ready"``.

    A failure here is left for the job to meet and report (it may not need what failed). The parent sends the job
    only after ``"ready"``, so the worker's own thread never waits for this one at its low priority.
    """
    if idle:
        _lower_this_thread()
    try:
        from pectoral_gym.hardware.lockstep_episode import EpisodeRunner, LockstepJob

        # the imports, the camera model, the rig's and the env's kernels
        EpisodeRunner(LockstepJob(controller="hand", max_steps=2), handle_signals=False).run(0)
        if policy:
            import pectoral_gym.agents.training.policy  # noqa: F401 - lazy in agents/: pulls in torch and SB3
    except Exception:  # noqa: BLE001, S110 - the job meets it again, and reports it
        pass
    finally:
        with contextlib.suppress(OSError):
            conn.send(("ready", None))


def _lower_this_thread() -> None:
    """The calling thread (and those it makes) to the lowest priority; Linux only, where it is a thread's own."""
    if sys.platform == "linux":
        with contextlib.suppress(OSError):
            if hasattr(os, "SCHED_IDLE"):
                os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            else:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), START_UP_NICE)


def _describe(err: BaseException) -> str:
    """What went wrong, for the parent to print: the error and its traceback (an unexpected failure)."""
    if isinstance(err, (RuntimeError, OSError)):  # e.g. a policy that cannot be loaded: one line
        return str(err)
    return f"{type(err).__name__}: {err}\n{''.join(traceback.format_exception(err)).rstrip()}"
