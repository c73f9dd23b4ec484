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
:mod:`pectoral_gym.hardware.lockstep_episode`. The workers (:mod:`pectoral_gym.hardware.lockstep_pool`) may be
started ahead of the run (:func:`start_pool`), to do their start-up while the caller does other work.

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

import dataclasses
import json
import os
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
from pectoral_gym.hardware.lockstep_pool import LockstepPool
from pectoral_gym.hardware.radio.linkstatus import LinkStats
from pectoral_gym.hardware.safety.rules import install_stop_handlers

__all__ = ["EpisodeError", "EpisodeResult", "LockstepJob", "LockstepPool", "episode_time_limit", "merge_link",
           "merge_solver", "run_lockstep", "shift_records", "start_pool", "worker_cores"]

RUN_LOG_GAP = 1.0  # s between one episode's last run-log record and the next episode's start in a merged run log

_JOIN_TIMEOUT = 5.0  # wall s a dead worker's exit code is waited for
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


def start_pool(jobs: int, policy: bool = True, idle: bool = True) -> LockstepPool:
    """``jobs`` lockstep workers for a later :func:`run_lockstep` with ``jobs``, started now and warming up.

    Their episodes are pinned as :func:`run_lockstep` pins its own (:func:`worker_cores`); ``policy``: the job will
    run a trained policy (its imports are part of the start-up); ``idle``: the start-up at the lowest priority
    (:class:`~pectoral_gym.hardware.lockstep_pool.LockstepPool`). A worker whose start-up has not ended when the
    run comes is replaced by a fresh one. Use it as a context manager, which ends the workers.
    """
    return LockstepPool(jobs, worker_cores(jobs), warm_up=True, policy=policy, idle=idle)


def run_lockstep(job: LockstepJob, episodes: Sequence[int], jobs: int = 1,
                 on_result: Callable[[EpisodeResult], None] | None = None, progress: bool = True,
                 controller: Any = None, pool: LockstepPool | None = None) -> list[EpisodeResult]:
    """Run the episodes ``episodes`` of ``job``, each on a fresh rig; returns their results in the order given.

    Args:
        job: The deployment.
        episodes: Episode indices (distinct).
        jobs: Processes: 1 runs in this thread (which joins each episode's lockstep); more start that many
            workers (at most one per episode), each running one episode at a time.
        on_result: Called with each result in the order of ``episodes``, as soon as those before it are in.
        progress: Show a progress bar over the episodes.
        controller: A controller for ``jobs=1`` (e.g. the policy the caller loaded already); else one is built.
        pool: Workers started before (:func:`start_pool`, ``jobs`` of them), which run the episodes instead of
            workers started here (even for ``jobs=1``); a pool serves one run and is ended by it.

    Raises:
        EpisodeError: An episode (or a worker) failed; every worker is ended first.
    """
    from tqdm import tqdm

    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    if pool is not None and len(pool) != jobs:
        raise ValueError(f"the pool has {len(pool)} workers for a run with jobs={jobs}")
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
        if pool is not None:
            _run_workers(job, order, pool, collect)
        elif jobs == 1:
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
            workers = min(jobs, len(order))
            with LockstepPool(workers, worker_cores(workers), warm_up=False) as started:
                _run_workers(job, order, started, collect)
    return results


def _run_workers(job: LockstepJob, order: list[int], pool: LockstepPool,
                 collect: Callable[[EpisodeResult], None]) -> None:
    """Run ``order``'s episodes in ``pool``'s workers (one run per pool); every worker is ended on every path out."""
    if pool.used:
        raise ValueError("this pool of lockstep workers has served a run already; start another")
    pool.used = True
    pool.take()
    queue = list(reversed(order))  # popped from the end: the lowest index first
    busy: dict[Connection, int] = {}  # a worker's pipe -> the episode it runs
    procs = dict(zip(pool.conns, pool.procs, strict=True))
    finished = False
    restore = install_stop_handlers(lambda: None)  # SIGTERM too ends in the finally below (main thread only)
    try:
        for conn in pool.conns:
            conn.send(job if queue else None)  # a worker with no episode to run ends at once
            if queue:
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
        pool.close(finished)
