"""Lockstep progress: integer virtual time, runs that cannot progress end with one line, signals end a run cleanly."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import threading
from types import SimpleNamespace

import pytest
from test_lockstep import _in_thread

from pectoral_gym.hardware import clock as clock_module
from pectoral_gym.hardware.clock import LockstepError, VirtualClock
from pectoral_gym.hardware.env import HardwareFishEnv


def test_the_rounding_case_that_hung_ends_at_the_tick():
    """The env's step loop one rounding step below its tick: origin 0.3 s, clock 2.3 s, tick 2.0 s experiment time.

    ``2.3 - 0.3`` is 2.0 less one rounding step (2.2e-16 s), and ``2.3 + 2.2e-16 == 2.3`` in floating point: a
    float clock that adds the sleep to its time never moved, and ``step()`` slept 2.2e-16 s for ever. The integer
    clock moves at least one tick per wait of any positive length.
    """
    origin, start, tick = 0.3, 2.3, 2.0
    remaining = tick - (start - origin)
    assert 0 < remaining < 3e-16 and start + remaining == start  # the case: a float sum would not move

    def scenario():
        clock = VirtualClock()
        clock.sleep(origin)
        env = SimpleNamespace(clock=clock, _origin=clock.monotonic(), speed=1.0)  # what now() and _sleep() read
        clock.sleep(start - origin)
        assert clock.monotonic() == start and HardwareFishEnv.now(env) < tick
        sleeps = 0
        while (left := tick - HardwareFishEnv.now(env)) > 0:  # step()'s loop, as it is written there
            HardwareFishEnv._sleep(env, min(1 / 30, left))
            sleeps += 1
            assert sleeps < 10, "the virtual time does not move"
        return sleeps, HardwareFishEnv.now(env)

    sleeps, end = _in_thread(scenario)
    assert sleeps == 1 and tick <= end <= tick + 2e-9  # one tick (1 ns) later, not a frame period


def test_every_wait_of_positive_length_moves_the_time_by_at_least_a_tick():
    def scenario():
        clock = VirtualClock(start=1e4)  # where a float's step is 1.8e-12 s
        times = [clock.monotonic()]
        clock.sleep(1e-20)
        times.append(clock.monotonic())
        clock.event().wait(1e-20)
        times.append(clock.monotonic())
        with (cond := clock.condition()):
            cond.wait(1e-20)
        times.append(clock.monotonic())
        return times

    times = _in_thread(scenario)
    assert all(b - a == pytest.approx(1e-9, abs=2e-12) for a, b in zip(times[:-1], times[1:], strict=True))


def test_integer_time_sums_exactly():
    """Ten sleeps of 0.1 s read 1.0 s exactly (a float sum reads 0.9999999999999999)."""
    def scenario():
        clock = VirtualClock()
        for _ in range(10):
            clock.sleep(0.1)
        return clock.monotonic()

    assert sum([0.1] * 10) != 1.0
    assert _in_thread(scenario) == 1.0


def test_a_thread_polling_without_waiting_ends_the_run_in_every_thread(monkeypatch):
    """A loop of zero-length waits never lets the time move: LockstepError, raised in the joining thread too."""
    monkeypatch.setattr(clock_module, "STALL_LIMIT", 5000)

    def scenario():
        clock = VirtualClock()

        def spinner():
            while True:
                clock.sleep(0.0)

        thread = clock.thread(spinner, "spinner")
        thread.start()
        with pytest.raises(LockstepError, match="stands still") as err:
            thread.join()
        with pytest.raises(LockstepError):  # sticky: any later wait ends the same way
            clock.sleep(1.0)
        return str(err.value)

    message = _in_thread(scenario)
    assert "\n" not in message


def test_threads_waking_each_other_for_ever_at_one_instant_end_the_run(monkeypatch):
    """Two threads notify each other and wait, never for a time: baton passes with the time standing still."""
    monkeypatch.setattr(clock_module, "STALL_LIMIT", 2000)

    def scenario():
        clock = VirtualClock()
        ping, pong = clock.event(), clock.event()

        def player(mine, other):
            while True:
                other.set()
                mine.wait()
                mine.clear()

        threads = [clock.thread(player, "ping", (ping, pong)), clock.thread(player, "pong", (pong, ping))]
        for thread in threads:
            thread.start()
        with pytest.raises(LockstepError, match="baton passes") as err:
            clock.sleep(1.0)
        return str(err.value)

    assert "ping" in _in_thread(scenario)


def test_a_run_past_its_time_limit_ends_with_one_line():
    def scenario():
        clock = VirtualClock(limit=10.0)

        def forever():
            while True:
                clock.sleep(0.25)

        thread = clock.thread(forever, "looper")
        thread.start()
        with pytest.raises(LockstepError, match="limit of 10.0 s") as err:
            thread.join()
        return str(err.value), clock.monotonic()

    message, end = _in_thread(scenario)
    assert "\n" not in message and end <= 10.0


_SIGNALLED_RUN = textwrap.dedent("""
    import os, signal, sys, threading, time
    import numpy as np
    from pectoral_gym.hardware.clock import VirtualClock
    from pectoral_gym.hardware.emulator import EmulatedRobot
    from pectoral_gym.hardware.radio.link import RadioLink
    from pectoral_gym.hardware.radio.pipe import StreamPair

    clock = VirtualClock()
    pair = StreamPair(clock)
    robot = EmulatedRobot(speed=1.0, seed=1, clock=clock, stream=pair.robot).start()
    link = RadioLink(pair.pc, session=5, clock=clock)
    stops = []
    restore = clock.defer_signals(lambda: (stops.append(clock.monotonic()), link.emergency_stop()))
    beats = np.array([[0.0, 0.3, 1.0, 1.0], [0.0, 0.3, 1.0, 1.0]])

    def send_signal():  # a real thread: the signal lands wherever the main thread is, scheduler included
        time.sleep(float(sys.argv[1]))
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=send_signal, daemon=True).start()
    try:
        while True:
            link.set_fins(beats, 0.8)
            for _ in range(50):
                clock.sleep(1e-6)  # many scheduler passes per wall second
    finally:
        link.close()
        robot.stop()
        restore()
        print("closed", len(stops), round(clock.monotonic(), 3) > 0, flush=True)
""")


@pytest.mark.parametrize("delay", [0.5, 1.3])
def test_sigterm_ends_a_lockstep_run_cleanly(tmp_path, delay):
    """SIGTERM mid-run: the stop runs, the run's finally block closes the link and the robot in lockstep, exit 143.

    The signal arrives from a real thread while the main thread spends most of its time inside the scheduler;
    handled there (the stop's write needs the scheduler's lock) it deadlocked.
    """
    script = tmp_path / "run.py"
    script.write_text(_SIGNALLED_RUN)
    try:
        done = subprocess.run([sys.executable, str(script), str(delay)], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("the signalled lockstep run did not end (deadlock)")
    assert done.returncode == 128 + signal.SIGTERM, done.stderr
    assert done.stdout.split() == ["closed", "1", "True"]


def test_signal_deferral_nests_and_is_undone():
    """Outside the main thread nothing is installed; nested deferrals keep the handler until the outermost is undone."""
    before = signal.getsignal(signal.SIGTERM)
    restore = _in_thread(lambda: VirtualClock().defer_signals())
    assert signal.getsignal(signal.SIGTERM) is before
    restore()
    assert threading.current_thread() is threading.main_thread()
    clock = VirtualClock()  # takes this thread in, but nothing here waits on it
    outer = clock.defer_signals()
    inner = clock.defer_signals(lambda: None)
    assert signal.getsignal(signal.SIGTERM) is not before
    inner()
    assert signal.getsignal(signal.SIGTERM) is not before  # the outer still defers
    outer()
    outer()  # undoing twice changes nothing
    assert signal.getsignal(signal.SIGTERM) is before



def test_a_worker_silent_past_the_wall_time_out_ends_the_run(monkeypatch):
    """The parent of worker processes waits for a result at most EPISODE_WALL_TIMEOUT, then ends every worker."""
    import time

    from pectoral_gym.hardware import lockstep_jobs
    from pectoral_gym.hardware.lockstep_jobs import EpisodeError, LockstepJob, run_lockstep

    monkeypatch.setattr(lockstep_jobs, "EPISODE_WALL_TIMEOUT", 0.2)  # shorter than a worker's start-up
    started = time.monotonic()
    with pytest.raises(EpisodeError, match="no episode ended within 0.2 s of wall time"):
        run_lockstep(LockstepJob(max_steps=1), [0, 1], jobs=2, progress=False)
    assert time.monotonic() - started < 30.0


@pytest.mark.slow
def test_fifty_episodes_with_a_third_of_the_frames_dropped_all_end(tmp_path):
    """The run that hung (10 of 50 episodes with 30 % of the camera's frames dropped): every episode ends."""
    import json

    from pectoral_gym.hardware import deploy

    out = tmp_path / "drops"
    args = ["--controller", "hand", "--emulate", "--lockstep", "--episodes", "50", "--jobs", "2", "--camera-drop",
            "0.3", "--seed", "300", "--out", str(out), "--no-progress", "--nice", "0"]
    assert _in_thread(lambda: deploy.main(args), timeout=3000.0) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["episodes"]) == 50


@pytest.mark.slow
@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 128 + signal.SIGTERM)])
def test_a_signal_ends_a_lockstep_deploy_in_its_own_process(tmp_path, signum, code):
    """``pectoral-deploy --lockstep`` (episodes in the deploy's process) signalled mid-episode ends at once, cleanly."""
    import time

    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "pectoral_gym.hardware.deploy", "--controller", "hand",
                             "--emulate", "--lockstep", "--episodes", "50", "--seed", "9", "--out", str(out),
                             "--no-progress", "--nice", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        steps = out / "steps.jsonl"
        deadline = time.monotonic() + 600.0  # a cold numba cache compiles first
        while not (steps.exists() and steps.stat().st_size > 2000):
            assert proc.poll() is None and time.monotonic() < deadline, "the deploy ended or never stepped"
            time.sleep(0.2)
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=60.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the signalled lockstep deploy did not end (deadlock)")
    assert proc.returncode == code, stderr[-2000:]
