"""The ``pectoral-fish`` command line: output contracts, argument errors, files written."""

from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess

import pytest

from pectoral_gym.tools.cli import main

STEADY_KEYS = {"vx", "vy", "omega", "speed", "radius", "period", "drift_angle", "converged", "model", "right", "left"}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PATTERN = "90,20,1,4"


def run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    assert main(list(argv)) == 0
    out = capsys.readouterr().out
    assert len(out.strip().splitlines()) == 1, "--json prints exactly one line"
    return json.loads(out)


def test_model_presets_are_the_specs_they_name(capsys):
    # The fast integration converges to the same periodic steady state as the reference (docs/model.md 6):
    # an independent integration of the same equations; the paper's Taylor forcing differs from the exact one.
    full = run_json(capsys, "steady", "--model", "full", "--right", PATTERN, "--json")
    fast = run_json(capsys, "steady", "--model", "full-fast", "--right", PATTERN, "--json")
    assert fast["speed"] == pytest.approx(full["speed"], rel=0.01) and fast["omega"] == pytest.approx(full["omega"],
                                                                                                       rel=0.01)
    exact = run_json(capsys, "steady", "--model", "averaged", "--right", PATTERN, "--json")
    paper = run_json(capsys, "steady", "--model", "averaged-paper", "--right", PATTERN, "--json")
    assert paper["speed"] != exact["speed"] and paper["model"] == "averaged-paper"


@pytest.mark.parametrize("model", ["full", "averaged"])
def test_steady_json_keys_and_turn_direction(capsys, model):
    right = run_json(capsys, "steady", "--model", model, "--right", PATTERN, "--json")
    left = run_json(capsys, "steady", "--model", model, "--left", PATTERN, "--json")
    for res in (right, left):
        assert set(res) == STEADY_KEYS
        assert res["model"] == model
        assert res["converged"] is True
        assert res["radius"] == pytest.approx(res["speed"] / abs(res["omega"]), rel=1e-12)
        assert res["period"] == pytest.approx(2 * math.pi / abs(res["omega"]), rel=1e-12)
        assert res["speed"] == pytest.approx(math.hypot(res["vx"], res["vy"]), rel=1e-12)
    assert right["omega"] > 0, "right fin alone turns the fish left"
    assert left["omega"] < 0, "left fin alone turns the fish right"
    assert right["right"] == [90, 20, 1, 4] and right["left"] is None
    assert left["left"] == [90, 20, 1, 4] and left["right"] is None
    # Mirror images.
    assert left["omega"] == pytest.approx(-right["omega"], rel=1e-9)
    assert left["vy"] == pytest.approx(-right["vy"], rel=1e-9)


@pytest.mark.parametrize("argv", [
    ["--right", PATTERN, "--left", PATTERN],  # symmetric: straight ahead
    [],  # both fins at rest
])
def test_steady_json_symmetric_has_null_radius_and_period(capsys, argv):
    res = run_json(capsys, "steady", "--json", *argv)
    assert set(res) == STEADY_KEYS
    assert res["radius"] is None and res["period"] is None
    assert res["omega"] == pytest.approx(0.0, abs=1e-9)


def test_steady_table_has_units(capsys):
    assert main(["steady", "--right", PATTERN]) == 0
    out = capsys.readouterr().out
    for unit in ("m/s", "rad/s", "left turn", "deg"):
        assert unit in out


@pytest.mark.parametrize(("argv", "reason"), [
    (["steady", "--right", "90,20,1"], "--right needs 4 comma-separated numbers G0,GA,TP,ZETA"),
    (["steady", "--left", "90,x,1,4"], "--left needs 4 comma-separated numbers G0,GA,TP,ZETA"),
    (["steady", "--right", "90,-5,1,4"], "FinBeat.amplitude must be >= 0"),
    (["steady", "--right", "170,20,1,4"], "leaves [0, 180] deg"),
    (["steady", "--left", "90,20,0,4"], "FinBeat.period must be > 0"),
    (["steady", "--right", "90,20,1,nan"], "FinBeat.ratio must be finite"),
    (["steady", "--model", "hybrid"], "invalid choice"),
    (["steady", "--model", "full-fast", "--scaling", "none"], "--scaling applies to averaged models only"),
    (["steady", "--model", "averaged", "--forcing", "taylor"], "unrecognized arguments: --forcing"),
    (["simulate", "--duration", "0", "--out", "unused"], "--duration must be a finite number > 0"),
    (["simulate", "--sample", "-1", "--out", "unused"], "--sample must be a finite number > 0"),
    (["step-rate", "--steps", "0"], "--steps must be >= 1"),
    (["frobnicate"], "invalid choice"),
    ([], "required"),
])
def test_bad_arguments_exit_2_with_one_line_reason(capsys, tmp_path, monkeypatch, argv, reason):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1, err
    assert reason in errors[0]
    assert not list(tmp_path.iterdir()), "nothing is written on an argument error"


def test_simulate_writes_csv_and_png(capsys, tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", "--right", PATTERN, "--duration", "2", "--sample", "0.1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    csv_path, png_path = out / "trajectory.csv", out / "trajectory.png"
    assert str(csv_path) in printed and str(png_path) in printed
    with csv_path.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "X", "Y", "psi", "vx", "vy", "omega", "gamma_right_deg", "gamma_left_deg"]
    data = [[float(v) for v in row] for row in rows[1:]]
    assert len(data) == 21
    assert data[0][:4] == [0.0, 1.15, 0.575, 0.0]  # default start: tank centre, heading 0
    assert data[-1][0] == pytest.approx(2.0)
    assert all(70 - 1e-9 <= r[7] <= 110 + 1e-9 for r in data), "right fin stays in its stroke"
    assert all(r[8] == pytest.approx(90.0) for r in data), "left fin at rest at 90 deg"
    assert png_path.read_bytes()[:8] == PNG_MAGIC


def test_simulate_compare_writes_both_models(capsys, tmp_path):
    argv = ["simulate", "--model", "averaged", "--compare", "--left", PATTERN, "--duration", "1"]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    assert {p.name for p in tmp_path.iterdir()} == {"trajectory.csv", "trajectory_full.csv", "trajectory.png"}


def test_bench_quick_json_has_the_keys(capsys):
    res = run_json(capsys, "step-rate", "--quick", "--json", "--steps", "50")
    assert {"single_env", "vector_env", "num_envs", "ratios", "targets", "all_met", "errors", "settings",
            "environment"} <= set(res)
    assert set(res["single_env"]) == {"PectoralFish-Averaged-v0", "PectoralFish-Full-v0", "CartPole-v1"}
    assert res["num_envs"] == {"PectoralFish-Averaged-v0": 4096, "PectoralFish-Full-v0": 1024,
                               "PectoralFish-Averaged-v0 (PPO settings)": 4096,
                               "PectoralFish-Full-v0 (fast integration)": 4096}
    assert res["vector_env"]["PectoralFish-Averaged-v0 (PPO settings)"] > 0
    assert res["vector_env"]["PectoralFish-Full-v0 (fast integration)"] > 0
    assert set(res["ratios"]) == {"averaged_vs_cartpole", "full_vs_cartpole"}
    assert set(res["targets"]) == {"averaged_vs_cartpole", "full_vs_cartpole", "vector_averaged", "vector_full"}
    for target in res["targets"].values():
        assert {"target", "value", "met", "what"} <= set(target)
    assert res["settings"]["quick"] is True and res["settings"]["steps"] == 50
    assert res["single_env"]["CartPole-v1"] > 0
    assert res["errors"] == {}, res["errors"]


def test_bench_against_keeps_each_rate_best_and_alternates(monkeypatch, tmp_path):
    from pectoral_gym.tools import bench_compare
    other = tmp_path / "other"
    (other / "pectoral_gym").mkdir(parents=True)
    (other / "pectoral_gym" / "__init__.py").write_text("")
    calls = []
    rates = {"this": iter([100.0, 300.0]), "other": iter([200.0, 150.0])}

    def fake_run(root, args):
        name = "other" if root == other.resolve() else "this"
        calls.append(name)
        value = next(rates[name])
        return {"single_env": {"A": value}, "vector_env": {"B": value * 10, "C": None if name == "other" else 1.0},
                "num_envs": {"B": 4, "C": 4}}

    monkeypatch.setattr(bench_compare, "_run", fake_run)
    res = bench_compare.compare(other, rounds=2)
    assert calls == ["this", "other", "this", "other"]
    rows = {r["rate"]: r for r in res["rows"]}
    assert rows["single: A"]["this"] == 300.0 and rows["single: A"]["other"] == 200.0
    assert rows["single: A"]["ratio"] == pytest.approx(1.5)
    assert rows["vector: B @ 4"]["ratio"] == pytest.approx(1.5)
    assert rows["vector: C @ 4"]["other"] is None and rows["vector: C @ 4"]["ratio"] is None
    assert "missing" in bench_compare.format_comparison(res)


def test_bench_against_a_folder_without_the_package_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["step-rate", "--against", str(tmp_path)])
    assert exc.value.code == 2
    assert "holds no pectoral_gym package" in capsys.readouterr().err


def test_bench_against_an_old_checkout_runs_its_bench(tmp_path):
    """A checkout from before 0.2.0 knows the subcommand as ``bench`` only: the comparison runs that."""
    from pectoral_gym.tools import bench_compare
    package = tmp_path / "pectoral_gym"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "__main__.py").write_text(
        "import argparse, json\n"
        "parser = argparse.ArgumentParser()\n"
        "parser.add_argument('command', choices=['bench'])\n"
        "parser.add_argument('--json', action='store_true')\n"
        "parser.parse_args()\n"
        "print(json.dumps({'single_env': {'A': 7.0}}))\n")
    assert bench_compare._run(tmp_path.resolve(), []) == {"single_env": {"A": 7.0}}


@pytest.mark.skipif(shutil.which("pectoral-fish") is None, reason="console script not installed")
def test_console_script_steady_json():
    proc = subprocess.run(["pectoral-fish", "steady", "--right", PATTERN, "--json"],
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert set(res) == STEADY_KEYS and res["omega"] > 0
    bad = subprocess.run(["pectoral-fish", "steady", "--right", "90,20,1"],
                         capture_output=True, text=True, timeout=300, check=False)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


@pytest.mark.slow
def test_bench_against_runs_both_checkouts(capsys):
    from pectoral_gym.tools.bench_compare import checkout_root

    res = run_json(capsys, "step-rate", "--against", str(checkout_root()), "--rounds", "1", "--quick", "--json")
    rows = {r["rate"]: r for r in res["rows"]}
    assert rows["single: CartPole-v1"]["this"] > 0 and rows["single: CartPole-v1"]["other"] > 0
    assert rows["vector: PectoralFish-Averaged-v0 @ 4096"]["ratio"] > 0
