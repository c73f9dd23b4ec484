"""The "Your own robot" walk-through of docs/calibration.md, run as written (each python command with --quick).

The commands are parsed from docs/calibration.md, so the test cannot drift from the text; ``--quick`` is the
documented smoke-run flag of ``scaling identify|validate``, ``pectoral_gym.agents.training.train`` and
``pectoral_gym.agents.training.evaluate``. The deploys (an identification run, then the trained policy on the
emulated robot) run shortened: 2 episodes of at most 16 steps each.
"""

import json
import os
import re
import shlex
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.versions import LATEST_FULL

ROOT = Path(__file__).resolve().parents[1]
QUICK = {("pectoral_gym.scaling", "identify"), ("pectoral_gym.scaling", "validate"),
         ("pectoral_gym.agents.training.train",), ("pectoral_gym.agents.training.evaluate",)}


def walkthrough_commands(text: str) -> list[str]:
    """The shell commands of the block after the ``<!-- walkthrough ... -->`` marker."""
    match = re.search(r"<!-- walkthrough\b.*?-->\s*```bash\n(.*?)```", text, re.S)
    if match is None:
        raise AssertionError("docs/calibration.md has no walk-through block (<!-- walkthrough ... --> then ```bash)")
    joined = match.group(1).replace("\\\n", " ")
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.strip().startswith("#")]


SHORT_DEPLOY = ("--episodes", "2", "--max-episode-steps", "16")  # the last of a repeated flag wins (argparse)


def with_quick(command: str) -> str:
    """``command`` with ``--quick`` appended if it is one of the CLIs that take it; a deploy shortened."""
    tokens = shlex.split(command)
    if tokens[:2] == ["python", "-m"] and (tuple(tokens[2:3]) in QUICK or tuple(tokens[2:4]) in QUICK):
        return command + " --quick"
    if tokens[:3] == ["python", "-m", "pectoral_gym.hardware.deploy"]:
        return command + " " + " ".join(SHORT_DEPLOY)
    return command


def test_parsing_joins_continuations_and_adds_quick_only_where_documented():
    text = "x\n<!-- walkthrough: t -->\n```bash\n# c\necho 1 > a\n" \
           "python -m pectoral_gym.agents.training.train --a 1 \\\n    --b 2\n" \
           "python -m pectoral_gym.scaling validate --c\npython -m pectoral_gym steady\n```\n"
    commands = walkthrough_commands(text)
    assert commands == ["echo 1 > a", "python -m pectoral_gym.agents.training.train --a 1      --b 2",
                        "python -m pectoral_gym.scaling validate --c", "python -m pectoral_gym steady"]
    assert [with_quick(c).endswith("--quick") for c in commands] == [False, True, True, False]


def test_the_readme_walk_through_runs_as_written(tmp_path):
    commands = walkthrough_commands((ROOT / "docs" / "calibration.md").read_text())
    text = "\n".join(commands)
    # What the walk-through must show: an identification run logged, the model calibrated from
    # the log, K identified for it, training on the full model with params=, evaluation on the full model, the
    # policy deployed on the (emulated) robot, the hand law beside it planning with the robot's K.
    assert "fin_span" in commands[0]
    assert re.search(r"python -m pectoral_gym\.hardware\.deploy --controller excite .*--out id-run", text)
    assert re.search(r"python -m pectoral_gym\.scaling calibrate --logs id-run/run\.jsonl .*--out robot\.json", text)
    assert re.search(r"python -m pectoral_gym.scaling identify .*--params robot\.json", text)
    # on the recommended ids (pectoral_gym.versions.LATEST), as the rest of the docs
    assert re.search(rf"python -m pectoral_gym\.agents\.training\.train .*{LATEST_FULL}.*\"params\"", text)
    assert re.search(rf"python -m pectoral_gym\.agents\.training\.evaluate .*{LATEST_FULL}", text)
    assert re.search(rf"python -m pectoral_gym\.hardware\.deploy --policy runs/{LATEST_FULL}/robot", text)
    assert "-v1" not in text and "-v0" not in text
    assert re.search(r"python -m pectoral_gym\.hardware\.deploy --controller hand .*--scaling k/", text)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    python = bin_dir / "python"  # `python` in the commands is the interpreter running the tests
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    python.chmod(python.stat().st_mode | stat.S_IEXEC)
    work = tmp_path / "robot"
    work.mkdir()
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "PYTHONPATH": str(ROOT),
           "MPLBACKEND": "Agg"}
    for command in commands:
        run = subprocess.run(["bash", "-c", with_quick(command)], cwd=work, env=env, capture_output=True, text=True,
                             timeout=900)
        assert run.returncode == 0, (command, run.stdout[-1500:], run.stderr[-3000:])
    calibrated = json.loads((work / "robot.json").read_text())
    assert calibrated["fin_span"] == 0.07  # measured, kept; the uncertain fields fitted from the log
    k = ScalingFunctions.load(work / "k" / "scaling_coefficients.json")
    assert k.identified_params["fin_span"] == 0.07  # identified for the calibrated robot
    assert k.identified_params["drag_coef"] == calibrated["drag_coef"]
    assert k.metadata["quick"] is True
    evaluation = json.loads(next((work / "runs" / "eval").glob("*/metrics.json")).read_text())
    assert evaluation["env_id"] == LATEST_FULL
    # the trained robot, on the full model: the run folder's copy of robot.json
    assert Path(evaluation["env_kwargs"]["params"]).name == "params.json"
    assert json.loads((work / evaluation["env_kwargs"]["params"]).read_text()) == calibrated
    assert "scaling" not in evaluation["env_kwargs"]
    deployed = json.loads((work / "robot-run" / "summary.json").read_text())
    assert deployed["emulation"]["params"]["fin_span"] == 0.07 and len(deployed["episodes"]) == 2
    hand = json.loads((work / "hand-run" / "summary.json").read_text())
    assert hand["settings"]["params"]["fin_span"] == 0.07 and len(hand["episodes"]) == 2


def test_quick_identify_refuses_install(capsys):
    from pectoral_gym.scaling.cli import main

    with pytest.raises(SystemExit) as stop:  # a usage error, as every bad argument
        main(["identify", "--quick", "--install"])
    assert stop.value.code == 2
    assert "--install" in capsys.readouterr().err.splitlines()[-1]
