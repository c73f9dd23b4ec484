"""Independent lockstep episodes for ``deploy --emulate --lockstep``: each on a fresh rig, in one or more processes.

Episode ``k`` of a run with seed ``s`` runs on a rig of its own (emulated robot, radio link, camera,
:class:`pectoral_gym.hardware.clock.VirtualClock` from time 0, env) opened with the seed ``s + k``, the seed
its start, target and controller are reset with too. Its records therefore depend on ``s + k`` and the
arguments alone, never on the episodes run before it or on the process it runs in: episode ``k`` of
``--seed s`` is episode 0 of ``--seed s+k`` (apart from its number), and :func:`run_lockstep` gives the same
results for any number of worker processes. The controller is built once per process and reset per episode.

Workers are started with the ``spawn`` method (numba's and the clock's threads in the parent make ``fork``
unsafe); each takes the next episode index from the parent when it is free, and sends back the episode's
lines of ``steps.jsonl`` and its summary; the parent hands them on in episode order. One episode on its rig:
:mod:`pectoral_gym.hardware.lockstep_episode`.

Each worker runs on a core of its own (:func:`worker_cores`) when there are at least as many cores as workers: a
lockstep rig runs one thread at a time, and every baton pass between its threads wakes the next one; on one core
that is a switch on that core, while threads free to run on any core wake each other across cores, each bringing
its data into the other core's caches (a tenth of a lockstep episode's CPU time went to that). With more workers
than cores, or where the affinity cannot be set, the workers are not pinned. A worker's threads are also scheduled
as batch work (Linux's ``SCHED_BATCH``, at the same nice level): a thread woken by the baton pass then does not
preempt the thread that passed it, which still holds the interpreter lock until it waits; it runs once that one
waits, instead of being switched in, blocking on the lock and being switched out again. Simulated time makes the
scheduling irrelevant to the results: where and how a worker runs never changes them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import multiprocessing
import os
import signal
import traceback
from collections.abc import Callable, Mapping, Sequence
from multiprocessing.connection import Connection, wait
from types import SimpleNamespace
from typing import Any

from pectoral_gym.hardware.deploy_controllers import solver_summary
from pectoral_gym.hardware.lockstep_episode import (  # re-exported: a job and its episodes
    EpisodeError,
    EpisodeResult,
    EpisodeRunner,
    EpisodeSignalLatch,
    LockstepJob,
    episode_time_limit,
)
from pectoral_gym.hardware.radio.linkstatus import LinkStats
from pectoral_gym.hardware.safety.rules import install_stop_handlers

__all__ = ["EpisodeError", "EpisodeResult", "LockstepJob", "episode_time_limit", "merge_link", "merge_solver",
           "run_lockstep", "shift_records", "worker_cores"]

RUN_LOG_GAP = 1.0  # s between one episode's last run-log record and the next episode's start in a merged run log

_JOIN_TIMEOUT = 5.0  # wall s a terminated worker gets to end before it is killed
# Wall seconds the parent waits for any worker's next result: far above an episode's (seconds to a minute, plus a
# cold numba compile of up to ~100 s), far below "for ever".
EPISODE_WALL_TIMEOUT = 1800.0


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


def worker_cores(jobs: int, available: set[int] | None = None) -> list[int | None]:
    """The core each of ``jobs`` workers is pinned to: the lowest ``jobs`` of ``available``, or ``None`` for each.

    ``available``: the cores this process may run on (default: its affinity mask; ``None`` where the platform
    does not tell). No worker is pinned when there are fewer cores than workers (two pinned to one core could not
    use a free one) or when the cores are not known.
    """
    if available is None and hasattr(os, "sched_getaffinity"):
        available = os.sched_getaffinity(0)
    if not available or jobs > len(available):
        return [None] * jobs
    return sorted(available)[:jobs]


def merge_solver(solvers: Sequence[Mapping[str, Any] | None]) -> dict[str, Any] | None:
    """:func:`~pectoral_gym.hardware.deploy_controllers.solver_summary` over the episodes' solver figures.

    ``None`` where no episode has a solver.
    """
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
            runner = EpisodeRunner(job, controller)
            runner.latch = EpisodeSignalLatch()
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
        for rank, core in enumerate(worker_cores(jobs)):
            conn, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, job, core), name=f"lockstep-worker-{rank}", daemon=True)
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


def _worker(conn: Connection, job: LockstepJob, core: int | None = None) -> None:
    """A worker process: run the episodes the parent sends (``None``: stop), reply with each result or the error.

    ``core``: the core it runs on (its threads, made after this, inherit it), or ``None``: any. It runs as batch
    work (``SCHED_BATCH``) where the platform has it (the module docstring).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the parent ends us
    if core is not None:
        with contextlib.suppress(OSError):  # a core taken away since: run anywhere, as unpinned
            os.sched_setaffinity(0, {core})
    if hasattr(os, "SCHED_BATCH"):  # the threads made from here on inherit both settings
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    try:
        runner = EpisodeRunner(job, handle_signals=False)
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
