"""Every bad input of ``pectoral-deploy``: a one-line error, exit status 2, nothing written, no code of the input run.

Before: a symlink to ``/dev/zero`` as a parameters, calibration or policy file was read until the memory ran out;
200 000-deep JSON, a mass of 1e300 or a K file holding ``[]`` gave tracebacks; implausible physics (drag x1000, a
fish ten times smaller, K of 1e300, negated or without its spline) was accepted; a policy folder's pickles ran
before the other checks refused the run; Ctrl-C printed a traceback; a failed start left its files behind.
"""

import json
import os
import pickle
import zipfile
from pathlib import Path

import pytest

from pectoral_gym.hardware import deploy, deploy_runs
from pectoral_gym.model.kfunctions import default_scaling_path
from pectoral_gym.model.params import FishParams, params_dict


class _Hostile:
    """Unpickling this writes the file ``marker``: code from the input ran."""

    def __init__(self, marker: str):
        self.marker = marker

    def __reduce__(self):
        return (Path(self.marker).write_text, ("ran",))


def _params_file(folder: Path, name: str, **changes) -> str:
    path = folder / name
    path.write_text(json.dumps({**params_dict(FishParams()), **changes}))
    return str(path)


def _scaled(factor: float) -> dict:
    """Table 1's fish scaled geometrically by ``factor``: lengths, areas, masses and inertias (same density)."""
    p = FishParams()
    powers = {"body_length": 1, "body_height": 1, "fin_offset": 1, "fin_span": 1, "fin_chord": 1, "wetted_area": 2,
              "body_mass": 3, "added_mass_x": 3, "added_mass_y": 3, "fin_mass": 3, "fin_effective_mass": 3,
              "body_inertia": 5, "added_inertia": 5, "moment_coef": 5}
    return {name: getattr(p, name) * factor ** n for name, n in powers.items()}


def _k_file(folder: Path, change) -> str:
    data = json.loads(default_scaling_path().read_text())
    change(data)
    path = folder / "k.json"
    path.write_text(json.dumps(data))
    return str(path)


def _scale_k(data: dict, factor: float) -> None:
    for terms in data["functions"].values():
        for term in terms:
            term["coef"] *= factor
    for name, values in data["spline"]["coefficients"].items():
        data["spline"]["coefficients"][name] = [v * factor for v in values]


def _polynomial_only(data: dict) -> None:
    """A K file without its spline whose polynomial alone is plausible: K = 1 (a --quick identification's kind)."""
    data.pop("spline")
    for name in data["functions"]:
        data["functions"][name] = [{"coef": 1.0 if name != "K_fy" else 0.0, "powers": [0] * len(data["features"])}]


def _policy_folder(folder: Path, marker: Path) -> str:
    run = folder / "run"
    run.mkdir()
    (run / "config.yaml").write_text("algo: ppo\ntask: goal\ncontrol_period: 0.5\n")
    with zipfile.ZipFile(run / "best_model.zip", "w") as archive:
        archive.writestr("data", "{}")
    (run / "vecnormalize.pkl").write_bytes(pickle.dumps(_Hostile(str(marker))))
    return str(run)


def _zero(folder: Path, name: str) -> str:
    link = folder / name
    os.symlink("/dev/zero", link)
    return str(link)


def _broken(folder: Path) -> str:
    path = folder / "cal.json"
    path.write_text("{not json")
    return str(path)


def _deep(folder: Path) -> str:
    path = folder / "deep.json"
    path.write_text("[" * 200_000 + "]" * 200_000)
    return str(path)


HAND = ["--controller", "hand", "--emulate", "--lockstep"]

CASES = {
    "params_dev_zero": lambda d: [*HAND, "--params", _zero(d, "p.json")],
    "emulate_params_dev_zero": lambda d: [*HAND, "--emulate-params", _zero(d, "p.json")],
    "calibration_dev_zero": lambda d: [*HAND, "--calibration", _zero(d, "cal.json")],
    "params_deep_json": lambda d: [*HAND, "--params", _deep(d)],
    "params_mass_1e300": lambda d: [*HAND, "--params", _params_file(d, "p.json", body_mass=1e300)],
    "params_drag_x1000": lambda d: [*HAND, "--params", _params_file(d, "p.json", drag_coef=387.0)],
    "params_ten_times_smaller": lambda d: [*HAND, "--params", _params_file(d, "p.json", **_scaled(0.1))],
    "params_too_short_for_the_markers": lambda d: [*HAND, "--params", _params_file(d, "p.json", **_scaled(0.7))],
    "params_sinks": lambda d: [*HAND, "--params", _params_file(d, "p.json", body_mass=0.795 * 3)],
    "params_added_mass_wrong_sign": lambda d: [*HAND, "--params", _params_file(d, "p.json", added_mass_x=0.095)],
    "emulate_params_stiff": lambda d: [*HAND, "--emulate-params", _params_file(d, "p.json", body_inertia=1e-9,
                                                                                added_inertia=0.0)],
    "k_empty_list": lambda d: [*HAND, "--scaling", _k_file(d, lambda k: k.clear())],
    "k_1e300": lambda d: [*HAND, "--scaling", _k_file(d, lambda k: _scale_k(k, 1e300))],
    "k_negated": lambda d: [*HAND, "--scaling", _k_file(d, lambda k: _scale_k(k, -1.0))],
    "k_no_spline": lambda d: [*HAND, "--scaling", _k_file(d, lambda k: k.pop("spline"))],
    "k_no_spline_real_robot": lambda d: ["--controller", "hand", "--port", "/dev/null", "--camera", "0",
                                         "--scaling", _k_file(d, _polynomial_only)],
    "k_dev_zero": lambda d: [*HAND, "--scaling", _zero(d, "k.json")],
    "policy_pickle_dev_zero": lambda d: ["--policy", _policy_dev_zero(d), "--emulate", "--lockstep"],
    "policy_pickle_not_run_before_checks": lambda d: ["--policy", _policy_folder(d, d / "ran"), "--emulate",
                                                      "--lockstep", "--calibration", _broken(d)],
}


def _policy_dev_zero(folder: Path) -> str:
    run = Path(_policy_folder(folder, folder / "ran"))
    (run / "vecnormalize.pkl").unlink()
    os.symlink("/dev/zero", run / "vecnormalize.pkl")
    return str(run)


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_one_line_exit_2_nothing_written(case, tmp_path, capsys):
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    argv = CASES[case](inputs)
    if case == "k_empty_list":
        Path(argv[-1]).write_text("[]")
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as ended:
        deploy.main([*argv, "--episodes", "1", "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert ended.value.code == 2
    assert "Traceback" not in err and lines[-1].startswith(("pectoral-deploy: error:", "deploy.py: error:",
                                                            "__main__.py: error:")), err
    assert not out.exists()  # nothing written
    assert not (inputs / "ran").exists()  # no code of the input ran


def test_plausible_inputs_pass_the_same_checks(tmp_path):
    # the checks refuse the bad inputs above for what they are, not everything: Table 1's fish and a fish 30 % off
    # in drag are plausible robots (whether they are *this* robot is the probe's question)
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.hardware.deploy_checks import check_scaling
    from pectoral_gym.hardware.deploy_cli import fish_params

    for changes in ({}, {"drag_coef": 0.387 * 1.3}, {"drag_coef": 0.387 * 0.7}, _scaled(1.3)):
        fish_params(_params_file(tmp_path, "p.json", **changes))
    c = EnvConfig()
    check_scaling(str(default_scaling_path()), {"bias_range": c.bias_range})


def test_ctrl_c_is_one_line_and_exit_130(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(deploy_runs, "run_real_time", interrupted)
    code = deploy.main(["--controller", "hand", "--emulate", "--no-progress", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 130 and "Traceback" not in err and err.strip().endswith("interrupted: the fins were stopped")
    assert not (tmp_path / "out").exists()


def test_failed_start_leaves_no_files(tmp_path, capsys, monkeypatch):
    out = tmp_path / "a" / "out"

    def fails_at_first_reset(request, name, controller, settings, model, log_path, run_log, notify):
        log_path.with_name("run.jsonl").write_text('{"type": "header"}\n')  # what the start had written
        log_path.write_text("")
        raise deploy_runs.DeployError("no fish seen for 5.0 s at reset")

    monkeypatch.setattr(deploy_runs, "run_real_time", fails_at_first_reset)
    assert deploy.main(["--controller", "hand", "--emulate", "--no-progress", "--out", str(out)]) == 1
    assert not (tmp_path / "a").exists() and "no fish seen" in capsys.readouterr().err


def test_displaced_run_exit_3_and_summary_says_so(tmp_path, capsys, monkeypatch):
    summary = {"episode": 0, "return": 0.0, "steps": 1, "terminated": False, "truncated": True,
               "safety_stop": "taken_over", "success": False, "final_distance": 0.5}

    def displaced(request, name, controller, settings, model, log_path, run_log, notify):
        log_path.write_text(json.dumps({"episode": 0, "step": 0, "event": "reset", "pose": [1, 0.5, 0],
                                        "target": [1.5, 0.5]}) + "\n")
        return [summary], {"sent": 1, "acked": 1, "retries": 0, "crc_errors": 0}, None, 0.1, "taken_over"

    monkeypatch.setattr(deploy_runs, "run_real_time", displaced)
    code = deploy.main(["--controller", "hand", "--emulate", "--episodes", "5", "--no-progress",
                        "--out", str(tmp_path)])
    assert code == deploy.EXIT_DISPLACED == 3
    assert json.loads((tmp_path / "summary.json").read_text())["ended"] == "taken_over"
    assert "another session took the robot over" in capsys.readouterr().err


def test_a_ctrl_c_lost_in_a_finaliser_still_ends_a_lockstep_run():
    # a Ctrl-C that arrives while a weakref callback runs (a lockstep rig's garbage being collected) was printed as
    # "Exception ignored" and lost: the run went on
    import weakref

    from pectoral_gym.hardware.signal_latch import SignalLatch

    class Garbage:
        pass

    def interrupted(_):
        raise KeyboardInterrupt

    with SignalLatch() as latch:
        latch.check()  # nothing latched: nothing raised
        thing = Garbage()
        ref = weakref.ref(thing, interrupted)
        del thing  # the callback's KeyboardInterrupt is unraisable
        assert ref() is None
        with pytest.raises(KeyboardInterrupt):
            latch.check()
