"""The fin replay's checkpoint: a look-ahead run from it and restored leaves no trace."""

import numpy as np

from pectoral_gym.model.finreplay import FinReplay

BEATS = [np.array([[1.5, 0.6, 0.5, 1.0], [1.7, 0.4, 0.7, 2.0]]),  # (bias [rad], amplitude [rad], period [s], ratio)
         np.array([[1.2, 0.3, 0.4, 3.0], [1.9, 0.7, 0.6, 1.0]]),
         np.array([[1.57, 0.5, 0.8, 1.0], [1.57, 0.5, 0.8, 1.0]])]


def _trace(replay: FinReplay, times: list[float]) -> np.ndarray:
    out = []
    for t in times:
        replay.advance(t)
        firmware = replay.firmware  # what the next command and turning point start from
        handed = firmware.handed if firmware.handed is not None else np.full((2, 4), np.nan)
        out.append(np.concatenate([replay.fins.ravel(), replay.model.state.ravel(), [replay.model.time],
                                   firmware.command.ravel(), firmware.setpoint.ravel(), handed.ravel(),
                                   [firmware.running, firmware.halt]]))
    return np.array(out)


def test_a_look_ahead_from_a_checkpoint_leaves_the_replay_as_it_was():
    plain, probed = FinReplay(), FinReplay()
    for replay in (plain, probed):
        replay.command(0.0, BEATS[0])
        replay.advance(0.73)
    saved = probed.checkpoint()
    probed.command(0.9, BEATS[1])  # a command the look-ahead assumes, then forgets
    probed.advance(2.5)
    assert not np.array_equal(probed.fins, plain.fins)  # the look-ahead did move the fins
    probed.restore(saved)
    before = [np.arange(0.8, 2.0, 0.1), np.arange(2.2, 4.0, 0.1)]  # the first command runs on, then a new one
    traces = []
    for replay in (plain, probed):
        first = _trace(replay, list(before[0]))
        replay.command(2.1, BEATS[2])
        traces.append(np.concatenate([first, _trace(replay, list(before[1]))]))
    np.testing.assert_array_equal(traces[1], traces[0])
