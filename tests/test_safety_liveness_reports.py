"""The liveness check's replays fed the robot's latch reports (LATCH, docs/protocol.md): they follow its fins.

The robot (the firmware's rules, :class:`pectoral_gym.model.finreplay.FinReplay`) takes each command somewhere between
its send and its acknowledgement, where none of the three replays (taking it at the send, half way, at the
acknowledgement) need take it; its reports of the half-strokes it started come a return delay late, some lost.
"""

import math

import numpy as np

from pectoral_gym.hardware.safety.geofence import SpeedBound
from pectoral_gym.hardware.safety.liveness import LivenessWatch
from pectoral_gym.hardware.safety.shadow_fins import REWIND, ShadowFins
from pectoral_gym.model import strokes
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.servo import ServoLimits

P = FishParams()
RETURN = 0.3  # the radio's return delay [s]: of every acknowledgement and report


def _robot_and_watch(seed, reports, loss=0.3, duration=12.0, freeze_at=math.inf):
    """A new random pattern sent every 0.5 s from 0.5 s; the robot takes each 0.02-0.6 s after its send.

    The watch sees the robot's fish at 33 frames per second (frozen from ``freeze_at`` [s] on) and, if ``reports``,
    the reports of the half-strokes it started (not of a fin holding still: the firmware sends none), each lost with
    probability ``loss``. Returns the watch, the first stop ``(t, reason)`` or ``None``, and the robot's fin angles
    ``(times (n,), angles (n, 2))`` every 0.01 s.
    """
    rng = np.random.default_rng(seed)
    sends = [(0.5 + 0.5 * k, rng.uniform((1.2, 0.1, 0.6, 1.0), (1.9, 0.5, 1.6, 3.0), (2, 4)))
             for k in range(int((duration - 1.0) / 0.5))]
    takes = [(sent + rng.uniform(0.02, 0.6), beats) for sent, beats in sends]
    acks = [taken + RETURN for taken, _ in takes]
    bound = SpeedBound(P, ServoLimits())
    bound.reset(0.0)
    bound.running(0.0, 100.0)
    watch = LivenessWatch(P, bound, pose_noise=0.005)
    robot = FinReplay(P)
    robot.model.state[0] = (1.0, 0.5, 0.0, 0.0, 0.0, 0.0)
    now = [0.0]
    starts: list[float | None] = [None, None]
    in_flight, times, angles, stop, frozen = [], [], [], None, None
    for k in range(1, int(round(duration / 0.01)) + 1):
        t = now[0] = k / 100
        while sends and sends[0][0] <= t + 1e-9:
            (sent, beats), ack = sends.pop(0), acks.pop(0)
            watch.command(sent, beats, lambda ack=ack: ack if now[0] >= ack else None)
        while takes and takes[0][0] <= t + 1e-9:
            robot.command(*takes.pop(0))
        robot.advance(t)
        fins = robot.model.fins[0]
        times.append(t)
        angles.append(strokes.fin_angles(robot.model.fins)[0][0].copy())
        for f in range(2):
            start = robot.model.time - fins[f, strokes.ELAPSED]
            if starts[f] is not None and abs(start - starts[f]) < 1e-9:
                continue
            starts[f] = start
            if fins[f, strokes.ANGLE_FROM] != fins[f, strokes.ANGLE_TO] and rng.uniform() >= loss:
                in_flight.append((start + RETURN, (start, f, fins[f, strokes.BIAS:strokes.RATIO + 1].copy(),
                                                   float(fins[f, strokes.ANGLE_FROM]), bool(fins[f, strokes.POWER]))))
        while reports and in_flight and in_flight[0][0] <= t + 1e-9:
            watch.latch(*in_flight.pop(0)[1])
        if k % 3 == 0:
            pose = robot.model.state[0, :3].copy()
            if t >= freeze_at:
                frozen = pose if frozen is None else frozen
                pose = frozen
            reason = watch.sighting(t, *pose)
            if reason and stop is None:
                stop = (t, reason)
    return watch, stop, (np.array(times), np.array(angles))


def _errors(watch, robot, since=2.0):
    """Each replay's mean error of its fin angles from the robot's [rad], at its snapshots from ``since`` [s] on."""
    times, angles = robot
    out = []
    for shadow in (watch._early, *watch._later):
        errors = []
        for t, fins, _ in shadow.view(times[-1]):
            k = int(np.argmin(abs(times - t)))
            if t >= since and abs(times[k] - t) <= 0.005:  # the robot's angle within 5 ms of the snapshot's
                errors.append(float(np.abs(strokes.fin_angles(fins)[0][0] - angles[k]).max()))
        assert len(errors) > 150
        out.append(float(np.mean(errors)))
    return out


def test_replays_that_lost_the_robots_phase_regain_it_from_its_reports():
    # Without reports every replay runs other strokes than the robot most of the time (0.25-0.42 rad off on
    # average); with every report they run the robot's (to the 5 ms between the compared instants); with 30 % lost
    # they infer only after a lost report, until the next one.
    without = _errors(*_robot_and_watch(3, reports=False)[::2])
    every = _errors(*_robot_and_watch(3, reports=True, loss=0.0)[::2])
    lossy = _errors(*_robot_and_watch(3, reports=True)[::2])
    assert min(without) > 0.2, without
    assert max(every) < 0.01, every
    assert all(w * 0.35 > e for w, e in zip(without, lossy, strict=True)), (without, lossy)


def test_a_frozen_camera_is_still_caught_with_the_reports():
    watch, stop, _ = _robot_and_watch(4, reports=True, freeze_at=6.0)
    assert _robot_and_watch(4, reports=True)[1] is None  # live: no stop
    assert stop is not None and stop[1].startswith(("camera frozen", "camera not live")), stop
    assert stop[0] - 6.0 <= 2.5, stop


def _shadow(to):
    shadow = ShadowFins(P, FirmwareConfig(), 0.0)
    shadow.reset(0.0)
    shadow.queue.append((0.0, np.array([[1.5, 0.4, 1.0, 1.0]] * 2), None))
    for k in range(1, int(round(to / 0.05)) + 1):
        shadow.advance(k * 0.05)  # for good, a snapshot every 0.05 s as the sightings make them
    return shadow


REPORT = (1.8, 0, np.array([1.2, 0.3, 0.8, 2.0]), 1.0, True)  # not what the commands make: a stroke from 1.0 rad


def test_a_late_report_rewinds_the_replay_to_start_its_half_stroke_at_its_own_time():
    shadow = _shadow(2.5)
    shadow.latch(*REPORT)
    assert shadow.t == 2.5 and shadow.rewinds == 1
    reference = FinReplay(P, FirmwareConfig())  # the same fins, latched at 1.8 s in order
    reference.command(0.0, np.array([[1.5, 0.4, 1.0, 1.0]] * 2))
    for t, fins, _ in shadow.snapshots:
        if t == 1.8:
            reference.latch(*REPORT)
        reference.advance(t)
        np.testing.assert_allclose(fins, reference.fins, atol=1e-12, err_msg=f"t = {t}")
    start = 2.5 - shadow.snapshots[-1][1][0, 0, strokes.ELAPSED]  # the next after the reported power stroke,
    assert math.isclose(start, 1.8 + 0.8 / 3, abs_tol=0.011)  # a third of its 0.8 s period (ratio 2), a tick late


def test_a_report_the_replay_already_ran_does_not_rewind_it():
    shadow = _shadow(2.5)
    t, fins, _ = next(s for s in shadow.snapshots if s[0] >= 1.3)
    fin = fins[0, 1]
    report = (t - fin[strokes.ELAPSED], 1, fin[strokes.BIAS:strokes.RATIO + 1].copy(), float(fin[strokes.ANGLE_FROM]),
              bool(fin[strokes.POWER]))
    before = list(shadow.snapshots)
    shadow.latch(*report)
    assert shadow.rewinds == 0 and list(shadow.snapshots) == before


def test_a_report_older_than_the_rewind_starts_its_half_stroke_as_far_in_as_the_replay_is():
    shadow = _shadow(1.8 + REWIND + 0.1)
    before = list(shadow.snapshots)
    shadow.latch(*REPORT)
    fins = shadow.replay.fins[0, 0]
    assert fins[strokes.ANGLE_FROM] == 1.0 and math.isclose(fins[strokes.ELAPSED], REWIND + 0.1)
    assert shadow.rewinds == 0 and list(shadow.snapshots) == before  # the snapshots before stay


def test_reports_of_other_fins_are_ignored():
    bound = SpeedBound(P, ServoLimits())
    bound.reset(0.0)
    watch = LivenessWatch(P, bound, pose_noise=0.005)
    assert not watch.latch(*REPORT)  # no command since the reset: not these fins
    watch.reset(1.0)
    watch.command(1.5, np.array([[1.5, 0.4, 1.0, 1.0]] * 2))
    assert not watch.latch(1.2, *REPORT[1:])  # a latch before the first command: an earlier episode's
    assert watch.latch(*REPORT)
