"""Lockstep emulation: the virtual clock, the in-process radio, and a deployment that repeats itself for a seed."""

from __future__ import annotations

import json
import os
import threading

import numpy as np
import pytest

from pectoral_gym.hardware.clock import REAL_CLOCK, LockstepError, VirtualClock
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.channel import RadioChannel
from pectoral_gym.hardware.radio.pipe import StreamPair


def _in_thread(fn, timeout: float = 60.0):
    """Run ``fn`` in a plain thread (a fresh VirtualClock takes the calling thread in; pytest's must stay out).

    Returns its value or raises its error; fails the test if it has not ended within ``timeout`` wall seconds.
    """
    out: dict = {}

    def body():
        try:
            out["value"] = fn()
        except BaseException as err:  # noqa: BLE001 - re-raised in the test's thread
            out["error"] = err

    thread = threading.Thread(target=body, daemon=True)
    thread.start()
    thread.join(timeout=timeout)
    assert not thread.is_alive(), "the lockstep scenario did not finish"
    if "error" in out:
        raise out["error"]
    return out["value"]


def test_real_clock_is_the_standard_library():
    import time

    assert REAL_CLOCK.monotonic is time.monotonic and REAL_CLOCK.sleep is time.sleep and not REAL_CLOCK.virtual
    assert isinstance(REAL_CLOCK.event(), threading.Event)


def test_sleep_jumps_to_the_wake_up_time():
    def scenario():
        clock = VirtualClock()
        clock.sleep(100.0)
        clock.sleep(0.0)  # no wait
        clock.sleep(-1.0)
        return clock.monotonic()

    assert _in_thread(scenario) == 100.0


def test_threads_interleave_by_wake_up_time_then_first_come():
    """A sleeps 0.3 s three times, B 0.5 s twice: the order follows from the times alone (ties: who waited first)."""
    def scenario():
        clock = VirtualClock()
        log = []

        def worker(name, period, count):
            for _ in range(count):
                clock.sleep(period)
                log.append((round(clock.monotonic(), 9), name))

        threads = [clock.thread(worker, "a", ("a", 0.3, 3)), clock.thread(worker, "b", ("b", 0.5, 2))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        return log, clock.monotonic()

    log, end = _in_thread(scenario)
    assert log == [(0.3, "a"), (0.5, "b"), (0.6, "a"), (0.9, "a"), (1.0, "b")]
    assert end == pytest.approx(1.0)


def test_event_wait_times_out_or_wakes_at_the_setters_time():
    def scenario():
        clock = VirtualClock()
        event = clock.event()
        assert event.wait(0.25) is False and clock.monotonic() == 0.25
        woke = []

        def waiter():
            woke.append((event.wait(10.0), clock.monotonic()))

        thread = clock.thread(waiter, "waiter")
        thread.start()
        clock.sleep(1.0)
        event.set()
        thread.join()
        return woke

    assert _in_thread(scenario) == [(True, 1.25)]


def test_condition_wait_releases_its_lock_and_counts_simulated_time():
    def scenario():
        clock = VirtualClock()
        lock = threading.RLock()
        cond = clock.condition(lock)
        box = []

        def producer():
            clock.sleep(0.5)
            with cond:  # the waiter released the lock while it waited
                box.append(clock.monotonic())
                cond.notify_all()

        thread = clock.thread(producer, "producer")
        with cond:
            thread.start()
            assert cond.wait_for(lambda: box, timeout=2.0)
            timed_out = not cond.wait(0.1)
        thread.join()
        return box, timed_out, clock.monotonic()

    box, timed_out, end = _in_thread(scenario)
    assert box == [0.5] and timed_out and end == pytest.approx(0.6)


def test_everyone_waiting_for_ever_is_an_error():
    def scenario():
        clock = VirtualClock()
        with pytest.raises(LockstepError, match="no timeout"):
            clock.event().wait()
        return True

    assert _in_thread(scenario)


def _frame(payload: bytes) -> bytes:
    return xb.encode_frame(xb.tx_request(payload, xb.BROADCAST))


def test_stream_pair_delivers_at_once_or_after_the_channels_delay():
    def scenario():
        clock = VirtualClock()
        pair = StreamPair(clock)
        pair.pc.write(b"abc")
        assert pair.robot.in_waiting == 3 and pair.robot.read(10) == b"abc"
        assert pair.robot.read(10, timeout=0.2) == b"" and clock.monotonic() == pytest.approx(0.2)
        delayed = StreamPair(clock, RadioChannel(latency=0.1))
        start = clock.monotonic()
        first, second = _frame(b"one"), _frame(b"two")
        delayed.robot.write(first)
        clock.sleep(0.01)
        delayed.robot.write(second)
        got = delayed.pc.read(100)
        at_first = clock.monotonic() - start
        got2 = delayed.pc.read(100)
        return got, at_first, got2, clock.monotonic() - start, first, second

    got, at_first, got2, at_second, first, second = _in_thread(scenario)
    assert got == first and at_first == pytest.approx(0.1)
    assert got2 == second and at_second == pytest.approx(0.11)


def test_stream_pair_loss_is_seeded():
    def lost(seed):
        def scenario():
            clock = VirtualClock()
            pair = StreamPair(clock, RadioChannel(loss=0.5, seed=seed))
            for k in range(40):
                pair.pc.write(_frame(bytes([k])))
            return pair.channel.stats.up_lost, pair.robot.read(10_000, timeout=0)
        return _in_thread(scenario)

    a, b = lost(3), lost(3)
    assert a == b and 0 < a[0] < 40
    assert lost(4) != a


_DEGRADED = ("--radio-latency", "0.05", "--radio-jitter", "0.02", "--radio-loss", "0.1", "--camera-drop", "0.1",
             "--camera-latency", "0.03", "--pose-noise-mm", "2", "--pose-noise-deg", "1")


def _deploy(tmp_path, name, *extra, episodes=2):
    from pectoral_gym.hardware import deploy

    out = tmp_path / name
    args = ["--controller", "hand", "--emulate", "--lockstep", "--episodes", str(episodes), "--max-episode-steps", "8",
            "--seed", "5", "--out", str(out), "--no-progress", "--nice", "0", *extra]
    assert _in_thread(lambda: deploy.main(args)) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary.pop("wall_time") > 0  # the one field that may differ
    return (out / "steps.jsonl").read_text(encoding="utf-8"), summary


def test_lockstep_deployment_repeats_itself_for_a_seed_and_any_jobs(tmp_path):
    """The same seed, degraded radio and camera, in this process and in 2 workers: the same logs, byte for byte."""
    steps_a, summary_a = _deploy(tmp_path, "a", *_DEGRADED, episodes=3)
    steps_b, summary_b = _deploy(tmp_path, "b", *_DEGRADED, "--jobs", "2", episodes=3)
    assert steps_a == steps_b and summary_a == summary_b
    assert (tmp_path / "a" / "run.jsonl").read_bytes() == (tmp_path / "b" / "run.jsonl").read_bytes()  # the run log
    records = [json.loads(line) for line in steps_a.splitlines()]
    assert [r["episode"] for r in records if r.get("event") == "reset"] == [0, 1, 2]
    steps = [r for r in records if "action" in r]
    assert steps and all(r["t"] > 0 for r in steps)
    # the step times are simulated: one control period (0.5 s) apart
    first = [r["t"] for r in steps if r["episode"] == 0]
    assert np.allclose(np.diff(first)[:-1], 0.5, atol=1e-6)
    assert summary_a["link"]["retries"] > 0  # the lossy radio was in the loop
    assert summary_a["emulation"]["lockstep"] and summary_a["emulation"]["conditions"]["radio_loss"] == 0.1


def test_a_lockstep_episode_does_not_depend_on_the_episodes_before_it():
    """Episode 2 after episodes 0 and 1, alone, and as episode 0 of seed + 2: the same records (renumbered)."""
    from pectoral_gym.hardware.emurig import RigConditions
    from pectoral_gym.hardware.lockstep_jobs import LockstepJob, run_lockstep

    conditions = RigConditions(radio_latency=0.05, radio_jitter=0.02, radio_loss=0.1, camera_latency=0.03,
                               camera_drop=0.1, pose_noise=(0.002, 0.02))
    job = LockstepJob(seed=5, conditions=conditions, max_steps=6)
    after = _in_thread(lambda: run_lockstep(job, range(3), progress=False))[2]
    alone = _in_thread(lambda: run_lockstep(job, [2], progress=False))[0]
    shifted = _in_thread(lambda: run_lockstep(LockstepJob(seed=7, conditions=conditions, max_steps=6), [0],
                                              progress=False))[0]
    assert after.log == alone.log and after.summary == alone.summary and after.link == alone.link
    renumbered = [json.dumps({**json.loads(line), "episode": 2}) for line in shifted.log.splitlines()]
    assert renumbered == after.log.splitlines()
    assert after.summary["steps"] == 6 and after.link["retries"] > 0  # a whole episode, over the lossy radio


def _scripted_run(lockstep: bool, steps: int = 6) -> tuple[np.ndarray, list[str]]:
    """Both fins rowing alike from (0.5, 0.575, 0) for ``steps`` periods: the true path, stops.

    The path is ``(t, X, Y, psi)`` rows on the emulated robot's clock, from the first step's command on.
    """
    import contextlib

    from pectoral_gym.hardware.emurig import open_rig
    from pectoral_gym.hardware.env import HardwareFishEnv

    action = np.array([0.0, 1.0, -0.5, 0.0] * 2, dtype=np.float32)  # 90 deg bias, 30 deg amplitude, 0.875 s, ratio 3
    with contextlib.ExitStack() as resources:
        clock, robot, port, camera = open_rig(resources, seed=3, lockstep=lockstep)
        env = HardwareFishEnv(port, camera, task="track", max_episode_steps=steps, handle_signals=False, clock=clock,
                              reset_hook=lambda rng: robot.place(0.5, 0.575, 0.0))
        resources.callback(env.close)
        env.reset(seed=0)
        robot.trace = []  # every physics chunk from now on
        stops = []
        for _ in range(steps):
            *_, terminated, truncated, info = env.step(action)
            stops.append(info["safety_stop"])
        trace, robot.trace = robot.trace, None
    path = np.array([(t, *state[:3]) for t, state, *_ in trace])
    running = np.array([entry[4] for entry in trace])
    path = path[np.argmax(running):]  # from the chunk the firmware first ran the command
    path[:, 0] -= path[0, 0]
    return path, stops


def test_lockstep_and_real_time_agree_on_a_scripted_swim():
    """The same commands from the same start: the same path in simulated time as in real time.

    The paths are compared on the robot's clock from the moment its fins start. In real time a command
    leaves when the operating system runs the control loop; a delay of up to 0.1 s (more than a loaded CI
    machine adds between two steps) moves the path by at most 0.1 s x the fish's speed (below 0.15 m/s
    with these fins), 1.5 cm: the tolerance is 2 cm and 0.05 rad, at 2.5 s after the start (5 periods).
    """
    virtual, stops_virtual = _in_thread(lambda: _scripted_run(True))
    real, stops_real = _scripted_run(False)
    assert stops_virtual == stops_real == [""] * 6  # no rule tripped in either
    at = 2.5
    end_virtual = [np.interp(at, virtual[:, 0], virtual[:, k]) for k in (1, 2, 3)]
    end_real = [np.interp(at, real[:, 0], real[:, k]) for k in (1, 2, 3)]
    assert virtual[-1, 0] > at and real[-1, 0] > at
    assert end_virtual[0] - 0.5 > 0.05  # it swam: the comparison means something
    assert end_virtual[:2] == pytest.approx(end_real[:2], abs=0.02)
    assert abs(end_virtual[2] - end_real[2]) < 0.05


@pytest.mark.parametrize("args, message", [
    (["--lockstep"], "--lockstep needs --emulate"),
    (["--emulate", "--lockstep", "--speed", "2"], "--speed does not apply with --lockstep"),
    (["--emulate", "--radio-loss", "1"], "radio_loss must be in [0, 1)"),
    (["--emulate", "--camera-drop", "-0.1"], "camera_drop must be in [0, 1]"),
    (["--emulate", "--pose-noise-mm", "nan"], "pose_noise must be"),
    (["--emulate", "--radio-latency", "-1"], "radio_latency must be a finite number"),
    (["--port", "/dev/null", "--camera", "0", "--radio-loss", "0.1"], "need --emulate"),
    (["--emulate", "--lockstep", "--jobs", "0"], "--jobs must be >= 1, got 0"),
    (["--emulate", "--lockstep", "--jobs", "two"], "argument --jobs: invalid int value"),
    (["--emulate", "--jobs", "2"], "--jobs needs --emulate --lockstep"),
    (["--port", "/dev/null", "--camera", "0", "--jobs", "2"], "--jobs needs --emulate --lockstep"),
])
def test_lockstep_and_condition_flags_are_checked(args, message, capsys):
    from pectoral_gym.hardware import deploy

    with pytest.raises(SystemExit) as exit_info:
        deploy.main(["--controller", "hand", "--no-progress", *args])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_workers_get_a_core_each_only_when_there_are_enough():
    from pectoral_gym.hardware.lockstep_jobs import worker_cores

    assert worker_cores(2, {3, 1, 7}) == [1, 3]  # the lowest cores, one per worker
    assert worker_cores(1, {5}) == [5]
    assert worker_cores(3, {0, 1}) == [None, None, None]  # two would share a core: none pinned
    assert worker_cores(2, set()) == [None, None]  # cores unknown
    mine = os.sched_getaffinity(0)  # by default: the cores this process may run on
    assert worker_cores(2) == ([None, None] if len(mine) < 2 else sorted(mine)[:2])
