"""Lockstep workers started before their job: the same results, and every worker ended on every path out."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest
from test_lockstep import _in_thread

from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.hardware.lockstep_jobs import EpisodeError, LockstepJob, run_lockstep, start_pool

_CONDITIONS = RigConditions(radio_latency=0.05, radio_loss=0.1, camera_drop=0.1, pose_noise=(0.002, 0.02))
_JOB = LockstepJob(seed=11, conditions=_CONDITIONS, max_steps=6)
_LIVENESS = 120.0  # wall s a test waits for processes to end before it calls them stuck (not a speed limit)


def _ended(pid: int) -> bool:
    """The process ``pid`` is gone or a zombie (an orphan's zombie waits for a reaper that may never come)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def _wait_ended(pids: list[int]) -> bool:
    deadline = time.monotonic() + _LIVENESS
    while not all(_ended(pid) for pid in pids):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.1)
    return True


def _wait_ready(pool) -> None:
    """Until every worker said its start-up ended (its first message, left for the run to read)."""
    deadline = time.monotonic() + _LIVENESS
    while not all(conn.poll() for conn in pool.conns):
        assert time.monotonic() < deadline, "a worker's start-up did not end"
        time.sleep(0.05)


def test_a_run_waits_for_a_start_up_at_the_workers_own_priority():
    with start_pool(2, policy=False, idle=False) as pool:
        pids = [proc.pid for proc in pool.procs]
        assert not any(conn.poll() for conn in pool.conns)  # just started: no start-up has ended
        pooled = run_lockstep(LockstepJob(max_steps=2), range(2), 2, progress=False, pool=pool)
    assert pool.replaced == 0 and [proc.pid for proc in pool.procs] == pids
    assert [r.episode for r in pooled] == [0, 1] and all(r.summary["steps"] == 2 for r in pooled)


@pytest.mark.parametrize("ready", [True, False])
def test_a_pool_started_ahead_gives_the_results_of_one_process(ready):
    """Degraded radio and camera, 3 episodes: in this thread, and in 2 workers started before the run.

    Workers whose start-up ended run the episodes; those still starting up are replaced by fresh ones.
    """
    alone = _in_thread(lambda: run_lockstep(_JOB, range(3), progress=False), timeout=600.0)
    # ready: at the workers' own priority, a start-up a busy machine cannot stall (and that a run waits for);
    # not ready: at the lowest, where a run replaces a start-up that has not ended
    with start_pool(2, policy=False, idle=not ready) as pool:
        if ready:
            _wait_ready(pool)
        pids = [proc.pid for proc in pool.procs]
        pooled = run_lockstep(_JOB, range(3), 2, progress=False, pool=pool)
        assert not any(proc.is_alive() for proc in pool.procs)  # the run ended its workers
        # the start-up takes seconds of imports and a rig: just after the start, none has ended
        assert pool.replaced == (0 if ready else 2)
        assert [proc.pid != pid for proc, pid in zip(pool.procs, pids, strict=True)] == [not ready] * 2
    assert [r.episode for r in pooled] == [0, 1, 2]
    assert [r.log for r in pooled] == [r.log for r in alone]
    assert [r.summary for r in pooled] == [r.summary for r in alone]
    assert [r.run_log for r in pooled] == [r.run_log for r in alone]
    assert all(r.summary["steps"] == 6 for r in alone) and sum(r.link["retries"] for r in alone) > 0


def test_a_pool_serves_one_run_of_its_own_size():
    with start_pool(2, policy=False) as pool:
        with pytest.raises(ValueError, match="the pool has 2 workers for a run with jobs=3"):
            run_lockstep(_JOB, range(3), 3, progress=False, pool=pool)
        assert run_lockstep(_JOB, [4], 2, progress=False, pool=pool)[0].episode == 4  # one episode: one worker idle
        with pytest.raises(ValueError, match="served a run already"):
            run_lockstep(_JOB, [0], 2, progress=False, pool=pool)


def test_a_failing_job_in_a_pool_is_named_by_its_episode_and_ends_the_workers(tmp_path):
    job = LockstepJob(controller="policy", policy=str(tmp_path / "missing"), max_steps=2)
    with start_pool(2) as pool:
        with pytest.raises(EpisodeError) as error:
            run_lockstep(job, [3, 4], 2, progress=False, pool=pool)
        assert error.value.episode in (3, 4) and "missing" in str(error.value)
        assert not any(proc.is_alive() for proc in pool.procs)


def test_an_error_in_the_block_ends_the_waiting_workers():
    """The caller's work fails before the run (the demo's training): the block's end ends the workers."""
    with pytest.raises(RuntimeError, match="training failed"), start_pool(2) as pool:
        pids = [proc.pid for proc in pool.procs]
        assert all(proc.is_alive() for proc in pool.procs)
        raise RuntimeError("training failed")
    assert all(_ended(pid) for pid in pids)  # joined: not even a zombie left
    assert [proc.exitcode for proc in pool.procs] == [-signal.SIGTERM] * 2


def test_the_start_up_lowers_its_own_thread_only():
    from pectoral_gym.hardware.lockstep_pool import _lower_this_thread

    if sys.platform != "linux" or not hasattr(os, "SCHED_IDLE"):
        pytest.skip("a thread's own scheduling policy: Linux")
    seen = {}

    def body():
        _lower_this_thread()
        seen["thread"] = os.sched_getscheduler(0)  # this thread's own

    before = os.sched_getscheduler(0)
    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert seen["thread"] == os.SCHED_IDLE != before
    assert os.sched_getscheduler(0) == before


_PARENT = textwrap.dedent("""
    import sys, time
    from pectoral_gym.hardware.lockstep_jobs import start_pool

    if __name__ == "__main__":
        with start_pool(2) as pool:
            print(*(proc.pid for proc in pool.procs), flush=True)
            time.sleep(600)  # the demo's training
""")


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 128 + signal.SIGTERM),
                                              (signal.SIGINT, None), (signal.SIGKILL, -signal.SIGKILL)])
def test_a_signalled_parent_leaves_no_worker_behind(tmp_path, signum, code):
    """SIGTERM or Ctrl-C to the parent ends it through the block's end; SIGKILL closes the pipes, which ends them."""
    script = tmp_path / "parent.py"
    script.write_text(_PARENT)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        pids = [int(pid) for pid in proc.stdout.readline().split()]
        assert len(pids) == 2, proc.stderr.read()
        time.sleep(0.5)  # the workers in their start-up
        proc.send_signal(signum)
        proc.wait(timeout=_LIVENESS)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if code is None:  # KeyboardInterrupt: Python's exit status for it
        assert proc.returncode in (130, -signal.SIGINT, 1), proc.stderr.read()
    else:
        assert proc.returncode == code, proc.stderr.read()
    assert _wait_ended(pids), "a worker outlived its parent"
