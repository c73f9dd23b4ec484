"""The run-log format: writer and reader round trip, and the reader's error for each kind of bad record."""

import io
import json
import math

import numpy as np
import pytest

from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.servo import ServoLimits
from pectoral_gym.runlog import (
    RunLogError,
    RunLogWriter,
    dumps_example,
    firmware_dict,
    firmware_from_dict,
    read_run_log,
    validate,
)

BEATS = [[1.5708, 0.5236, 1.0, 2.0], [1.2, 0.3, 0.8, 3.0]]


def _lines() -> list[str]:
    return dumps_example().splitlines()


def _write(tmp_path, lines: list[str]):
    path = tmp_path / "run.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_round_trip(tmp_path):
    limits = ServoLimits(period_min=0.5, max_rate=(1.0, 2.0, 3.0, 4.0))
    path = tmp_path / "run.jsonl"
    with RunLogWriter(path, "emulator", 0.25, FirmwareConfig(watchdog_timeout=0.3, limits=limits),
                      known_params={"body_mass": 0.8}) as log:
        log.episode(0, 1.0)
        log.command(1.1, BEATS)
        log.ack(1.11, seq=3)
        log.pose(1.2, 1.0, 0.5, -3.0, 0.9)
        log.estimate(1.21, state=[1.0, 0.5, -3.0, 0, 0, 0])
        log.safety(1.5, rule="geofence")
        log.stop(1.5)
        log.episode(1, 3.0)
        log.pose(3.1, 1.1, 0.6, 0.1)
    run = read_run_log(path)
    assert run.header["source"] == "emulator" and run.header["control_period"] == 0.25
    assert run.firmware == FirmwareConfig(watchdog_timeout=0.3, limits=limits)
    assert run.known_params == {"body_mass": 0.8}
    first, second = run.episodes
    assert (first.index, first.t_start, second.index, second.t_start) == (0, 1.0, 1, 3.0)
    np.testing.assert_array_equal(first.beats[0], BEATS)
    np.testing.assert_array_equal(first.command_t, [1.1])
    np.testing.assert_array_equal(first.stop_t, [1.5])
    np.testing.assert_array_equal(first.poses, [[1.0, 0.5, -3.0]])
    assert second.confidence.tolist() == [1.0]
    assert [r["type"] for r in run.other] == ["ack", "estimate", "safety"]
    assert math.isclose(run.duration, 0.5 + 0.1)


def test_firmware_dict_round_trip():
    config = FirmwareConfig(max_lease=0.7, limits=ServoLimits(ratio_max=5.0))
    assert firmware_from_dict(json.loads(json.dumps(firmware_dict(config)))) == config


def test_example_reads_back():
    run = read_run_log(io.StringIO(dumps_example()))
    assert len(run.episodes) == 2 and len(run.episodes[0].pose_t) == 2


@pytest.mark.parametrize(("index", "text", "message"), [
    (2, '{"type": "command", "t": 0.1, "beats": [[1.57, 0.5', "not valid JSON"),
    (3, '{"type": "posse", "t": 0.2, "x": 1, "y": 1, "psi": 0, "confidence": 1}', "unknown record type 'posse'"),
    (3, '{"type": "pose", "t": 0.2, "x": 1, "psi": 0, "confidence": 1}', "lacks field(s) ['y']"),
    (3, '{"type": "pose", "t": 0.2, "x": NaN, "y": 1, "psi": 0, "confidence": 1}', "NaN is not a number"),
    (3, '{"type": "pose", "t": 0.2, "x": 1, "y": 1, "psi": 0, "confidence": 1.5}', "confidence must be in [0, 1]"),
    (4, '{"type": "pose", "t": 0.1, "x": 1, "y": 1, "psi": 0, "confidence": 1}', "timestamps go backwards"),
    (2, '{"type": "command", "t": 0.1, "beats": [[3.0, 0.5, 1, 2], [1.5, 0.5, 1, 2]]}',
     "outside the envelope: the stroke"),
    (2, '{"type": "command", "t": 0.1, "beats": [[1.5, 0.5, 0, 2], [1.5, 0.5, 1, 2]]}', "outside the envelope"),
    (2, '{"type": "command", "t": 0.1, "beats": [[1.5, 0.5, 1, 2]]}', "must be 2 rows"),
    (2, '{"type": "command", "t": "soon", "beats": [[1.5, 0.5, 1, 2], [1.5, 0.5, 1, 2]]}', "t must be a number"),
    (7, '{"type": "episode", "episode": 1, "t": 2.0}', "timestamps go backwards: episode starts"),
    (0, '{"type": "episode", "episode": 0, "t": 0.0}', "the first record must be the header"),
])
def test_bad_record_named(tmp_path, index, text, message):
    lines = _lines()
    lines[index] = text
    with pytest.raises(RunLogError) as info:
        validate(_write(tmp_path, lines))
    assert info.value.line == index + 1
    assert message in info.value.reason
    assert str(info.value).startswith(f"{tmp_path / 'run.jsonl'}:{index + 1}: ")


def test_bad_header(tmp_path):
    header = json.loads(_lines()[0])
    for change, message in (({"version": 3}, "version 3 is not supported"),
                            ({"format": "csv"}, "format must be"),
                            ({"control_period": -1}, "control_period must be > 0"),
                            ({"firmware": {"max_lease": 5.0}}, "bad firmware"),
                            ({"known_params": {"mass": 1.0}}, "unknown FishParams fields ['mass']")):
        lines = _lines()
        lines[0] = json.dumps({**header, **change})
        with pytest.raises(RunLogError, match=message.replace("[", r"\[").replace("]", r"\]")):
            validate(_write(tmp_path, lines))


def test_log_without_poses(tmp_path):
    lines = [line for line in _lines() if '"pose"' not in line]
    with pytest.raises(RunLogError, match="no pose record"):
        validate(_write(tmp_path, lines))


def test_writer_refuses_bad_values():
    log = RunLogWriter(io.StringIO(), "robot", 0.5)
    with pytest.raises(ValueError, match="finite"):
        log.pose(0.0, math.nan, 0.0, 0.0)
    with pytest.raises(ValueError, match="envelope"):
        log.command(0.0, [[0.1, 0.5, 1.0, 2.0], [1.5, 0.5, 1.0, 2.0]])


def test_pose_line_is_the_json_of_its_record():
    """A pose line is ``json.dumps`` of the record docs/run-log.md gives, whatever the floats; bad ones raise."""
    rng = np.random.default_rng(11)
    values = [0.0, -0.0, 1.0, 1e-320, 1.7976931348623157e308, -1e300, 0.1, 2.0 / 3.0, 12345678.9,
              *rng.normal(scale=1e3, size=40).tolist(), *(10.0 ** rng.uniform(-30, 30, size=20)).tolist()]
    good = [(abs(t), x, y, psi, c) for t, x, y, psi, c in zip(values, values[3:], values[7:], values[11:],
                                                              [0.0, 1.0, 0.5, *rng.uniform(size=60)], strict=False)]
    assert len(good) > 40
    stream = io.StringIO()
    log = RunLogWriter(stream, "robot", 0.5)
    start = len(stream.getvalue())
    for t, x, y, psi, c in good:
        log.pose(t, x, y, psi, c)
    rec = [{"type": "pose", "t": t, "x": x, "y": y, "psi": psi, "confidence": c} for t, x, y, psi, c in good]
    assert stream.getvalue()[start:] == "".join(json.dumps(r) + "\n" for r in rec)
    for bad, match in [((-1e-9, 0.0, 0.0, 0.0, 1.0), ">= 0"), ((0.0, 1e308, 1e308, 0.0, 1.0), None),
                       ((0.0, math.inf, 0.0, 0.0, 1.0), "finite"), ((0.0, 0.0, 0.0, -math.inf, 1.0), "finite"),
                       ((math.nan, 0.0, 0.0, 0.0, 1.0), "finite"), ((0.0, 0.0, 0.0, 0.0, 1.5), r"\[0, 1\]"),
                       ((0.0, 0.0, 0.0, 0.0, math.nan), "finite")]:
        if match is None:  # large but finite: written as any pose
            log.pose(*bad)
            assert json.loads(stream.getvalue().splitlines()[-1])["x"] == bad[1]
            continue
        with pytest.raises(ValueError, match=match):
            log.pose(*bad)
