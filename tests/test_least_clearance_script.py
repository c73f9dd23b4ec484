"""The safety guide's least-clearance script: the outline's distance to the walls by hand, and its errors."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from pectoral_gym.model.params import FishParams
from pectoral_gym.model.tank import TANK_WIDTH

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "validation" / "hardware" / "least_clearance.py"


def _script():
    spec = importlib.util.spec_from_file_location("least_clearance", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _write(path: Path, poses: list) -> Path:
    path.write_text("".join(json.dumps({"step": i, "true_pose": p}) + "\n" for i, p in enumerate(poses))
                    + json.dumps({"step": 99}) + "\n")
    return path


def test_the_least_clearance_is_the_tail_capsule_to_the_nearest_wall(tmp_path, capsys):
    p = FishParams()
    # heading along +X in mid-tank: the tail's capsule end is at x - L/2 - C_p from the wall X = 0 (by hand); the
    # fin discs sit at x, C_p to either side, far from every wall
    tail_end = 0.5 * p.body_length + p.fin_offset
    steps = _write(tmp_path / "steps.jsonl", [[tail_end + 0.120, TANK_WIDTH / 2, 0.0, 0.0],
                                              [tail_end + 0.035, TANK_WIDTH / 2, 0.0, 0.0],
                                              [tail_end - 0.010, TANK_WIDTH / 2, 0.0, 0.0]])
    least, past, seen = _script().least_clearance(str(steps), _script().tank.Outline.from_params(p))
    assert least == pytest.approx(-0.010, abs=1e-12) and past == 1 and seen == 3
    assert _script().main([str(steps)]) == 0
    assert "least clearance -10 mm over 3 records, records past a wall 1" in capsys.readouterr().out


@pytest.mark.parametrize(("text", "message"), [("{not json\n", "not JSON"), ('{"true_pose": [1, "x", 0]}\n', "finite"),
                                               ('{"step": 1}\n', "no step record has a true_pose")])
def test_bad_logs_end_with_one_line_and_exit_2(tmp_path, capsys, text, message):
    (tmp_path / "steps.jsonl").write_text(text)
    with pytest.raises(SystemExit) as end:
        _script().main([str(tmp_path / "steps.jsonl")])
    assert end.value.code == 2 and message in capsys.readouterr().err
