"""The PC's fin replay (core) against the robot's own state machine, and the wire's resolution of a pattern."""

import math

import numpy as np
import pytest

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio.firmware import Firmware
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import advance_with_firmware, apply_firmware, wire_beats
from pectoral_gym.model.models import FullModel


class _RobotFins:
    """The fins under the robot's full state machine, fed the replay's commands through the wire format.

    The lease and the watchdog are held open (as the replay assumes: the PC keeps the robot running until it
    stops it), so what differs from the replay is only the session, sequence and command-identity bookkeeping.
    """

    def __init__(self) -> None:
        self.firmware, self.model = Firmware(boot=7), FullModel(1, integration="fast")
        self.seq = self.command_id = 0

    def _send(self, msg: pr.Message) -> None:
        self.firmware.receive(pr.decode_message(pr.encode_message(msg)), self.model.time)
        self.firmware.lease_end = self.firmware.last_valid = math.inf

    def command(self, t: float, beats: np.ndarray) -> None:
        advance_with_firmware(self.firmware, self.model, t)
        self.seq, self.command_id = self.seq + 1, self.command_id + 1
        fins = tuple(float(v) for v in np.asarray(beats).reshape(8))
        self._send(pr.Message(pr.MsgType.SET_FINS, self.seq, 5, fins=fins, command=self.command_id, lease=1.0))

    def stop(self, t: float) -> None:
        advance_with_firmware(self.firmware, self.model, t)
        self.seq += 1
        self._send(pr.Message(pr.MsgType.STOP, self.seq, 5))
        apply_firmware(self.firmware, self.model)


def test_replay_runs_the_fins_as_the_robots_state_machine_does():
    # Commands outside the servo limits (clipped, stretched), changes beyond the rate rule's reach, stops and
    # restarts: the replay's fins must be the robot's, bit for bit, at every command and at the end.
    rng = np.random.default_rng(4)
    replay, robot = FinReplay(), _RobotFins()
    t = 0.0
    for k in range(40):
        t += float(rng.uniform(0.05, 1.2))
        if k % 9 == 8:
            replay.stop(t)
            robot.stop(t)
        else:
            beats = rng.uniform([0.0, 0.0, 0.1, 0.2], [3.3, 1.7, 4.5, 7.0], (2, 4))
            replay.command(t, beats)
            robot.command(t, beats)
        np.testing.assert_array_equal(replay.fins, robot.model.fins)
    replay.advance(t + 3.0)
    advance_with_firmware(robot.firmware, robot.model, t + 3.0)
    np.testing.assert_array_equal(replay.fins, robot.model.fins)
    assert robot.firmware.ignored == dict.fromkeys(robot.firmware.ignored, 0)  # every message acted on


def test_wire_resolution_by_hand():
    # mrad, mrad, ms and 1/1000: 1.5707963 rad -> 1571 mrad; 0.8004 s -> 800 ms; ratio 2.9996 -> 3.000.
    beats = np.array([[1.5707963, 0.5236, 0.8004, 2.9996], [0.0, 0.0, 65.535, 1.0]])
    expected = np.array([[1.571, 0.524, 0.8, 3.0], [0.0, 0.0, 65.535, 1.0]])
    np.testing.assert_array_equal(wire_beats(beats), expected)
    msg = pr.decode_message(pr.encode_message(pr.Message(pr.MsgType.SET_FINS, 1, 1, fins=tuple(beats.reshape(8)),
                                                         command=1, lease=0.5)))
    np.testing.assert_array_equal(np.reshape(msg.fins, (2, 4)), expected)  # the protocol's own decoder agrees


@pytest.mark.parametrize("bad, message", [
    (-0.01, "does not fit the wire format"),
    (65.536, "does not fit the wire format"),
    (math.nan, "is not finite"),
])
def test_a_pattern_the_wire_cannot_carry_is_refused_by_the_replay(bad, message):
    beats = np.full((2, 4), 1.0)
    beats[1, 2] = bad
    with pytest.raises(ValueError, match=message):
        FinReplay().command(0.0, beats)
