"""Results across seeds (pectoral_gym.agents.studies.seeds).

Across-seed statistics by hand, the command end to end at tiny sizes.
"""

import json
import math

import numpy as np
import pytest
import yaml

from pectoral_gym.agents.studies.seeds import aggregate, iqm, main, summarize_seeds
from pectoral_gym.agents.studies.solve_time import check_held_out

TINY = ["--quick", "--timesteps", "1024", "--episodes", "3", "--probe-episodes", "2", "--no-progress"]


def test_iqm_is_the_mean_of_the_middle_half():
    assert iqm([3.0, 0.0, 2.0, 1.0]) == pytest.approx(1.5)  # drop 0 and 3
    assert iqm([1.0, 2.0, 3.0, 4.0, 100.0]) == pytest.approx(3.0)  # drop 1 and 100: an outlier does not move it
    assert iqm([1.0, float("nan"), 3.0]) == pytest.approx(2.0)
    assert math.isnan(iqm([]))


def test_bootstrap_interval_of_two_seeds_by_hand():
    # resamples of (0, 1): (0, 0), (0, 1), (1, 0), (1, 1), IQM of two values = their mean: 0, 1/2, 1/2, 1 with
    # probabilities 1/4, 1/2, 1/4; the 2.5 % and 97.5 % quantiles of that are 0 and 1
    a = aggregate([0.0, 1.0], n_resamples=4000, seed=1)
    assert (a["ci_low"], a["ci_high"]) == (0.0, 1.0)
    assert a["iqm"] == a["mean"] == a["median"] == 0.5 and a["n"] == 2
    # at 40 %, the quantiles 0.3 and 0.7 both fall on 1/2
    a = aggregate([0.0, 1.0], confidence=0.4, n_resamples=4000, seed=1)
    assert (a["ci_low"], a["ci_high"]) == (0.5, 0.5)


def test_aggregate_edge_cases_and_repeatability():
    values = [0.91, 0.88, 0.83, 0.90, 0.97]
    a, b = aggregate(values, seed=3), aggregate(values, seed=3)
    assert a == b
    assert min(values) <= a["ci_low"] <= a["iqm"] <= a["ci_high"] <= max(values)
    assert a["iqm"] == pytest.approx((0.88 + 0.90 + 0.91) / 3)
    assert aggregate([0.7])["ci_low"] == aggregate([0.7])["ci_high"] == 0.7
    assert aggregate([0.9, 0.9, 0.9])["ci_low"] == 0.9
    assert aggregate([float("nan")])["iqm"] is None
    with pytest.raises(ValueError, match="confidence"):
        aggregate(values, confidence=1.0)


def _run(seed, averaged, full, rand, solve_s=None):
    def metric(v):
        return {"mean": v, "ci_low": v, "ci_high": v, "n": 100}
    evaluations = {label: {"success": metric(v), "time_to_goal": metric(40.0)}
                   for label, v in (("averaged", averaged), ("full", full), ("full+rand", rand))}
    solve = {"time_to_solve_s": solve_s, "solved": solve_s is not None}
    return {"seed": seed, "evaluations": evaluations, "time_to_solve": solve}


def test_summary_counts_the_seeds_that_meet_each_target():
    runs = [_run(0, 0.97, 0.96, 0.92, 30.0), _run(1, 0.99, 0.95, 0.85), _run(2, 0.90, 0.80, 0.91, 50.0)]
    summary = summarize_seeds(runs)
    assert summary["targets"]["success full"]["seeds_met"] == [0, 1]
    assert summary["targets"]["success full+rand"]["seeds_met"] == [0, 2]
    assert summary["targets"]["gap averaged-full"]["seeds_met"] == [0]  # gaps 0.01, 0.04, 0.10
    assert summary["figures"]["gap averaged-full"]["max"] == pytest.approx(0.10)
    assert summary["figures"]["time to solve [s]"]["n"] == 2  # seed 1 did not solve: left out
    assert summary["figures"]["success full"]["iqm"] == pytest.approx(np.mean([0.80, 0.95, 0.96]))


def test_held_out_episode_seeds_are_checked():
    check_held_out([0, 1, 2], n_envs=32, eval_episodes=50, probe_episodes=100, report_episodes=100)
    with pytest.raises(ValueError, match="reported episodes and the training resets of seed 9990"):
        check_held_out([9990], n_envs=32, eval_episodes=50, probe_episodes=100, report_episodes=100)
    with pytest.raises(ValueError, match="probe episodes and the reported"):
        check_held_out([0], n_envs=32, eval_episodes=50, probe_episodes=100, report_episodes=100,
                       probe_seed=10_050)


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("seeds") / "serial"
    assert main([*TINY, "--seeds", "5", "6", "--jobs", "1", "--out", str(out)]) == 0
    return out


def test_command_writes_per_seed_and_across_seed_results(serial_run, capsys):
    report = json.loads((serial_run / "seeds.json").read_text())
    assert report["settings"]["seeds"] == [5, 6] and [r["seed"] for r in report["per_seed"]] == [5, 6]
    for run in report["per_seed"]:
        assert set(run["evaluations"]) == {"averaged", "full", "full+rand"}
        for label, evaluation in run["evaluations"].items():
            assert evaluation["success"]["n"] == 3
            assert (serial_run / f"seed{run['seed']}" / f"eval_{label}.json").is_file()
        assert (serial_run / f"seed{run['seed']}" / "best_model.zip").is_file()
        probes = run["time_to_solve"]["probes"]
        assert probes and all(p["timesteps"] <= run["timesteps"] for p in probes)
    summary = report["summary"]
    fulls = [r["evaluations"]["full"]["success"]["mean"] for r in report["per_seed"]]
    assert summary["figures"]["success full"]["iqm"] == pytest.approx(np.mean(fulls))  # two seeds: the mean
    markdown = (serial_run / "seeds.md").read_text()
    assert "| 5 |" in markdown and "| 6 |" in markdown and "IQM" in markdown and "--seeds 5 6" in markdown
    assert "wall hits, averaged / full" in markdown
    assert (serial_run / "seeds.png").read_bytes()[:4] == b"\x89PNG"
    # the same seeds into the same folder are refused
    assert main([*TINY, "--seeds", "5", "--out", str(serial_run)]) == 2
    assert "exists" in capsys.readouterr().err


@pytest.mark.slow  # spawns two worker processes (torch, numba imports): about 30 s unloaded, 90 s on a busy machine
def test_parallel_jobs_give_the_same_results_as_one_process(serial_run, tmp_path):
    out = tmp_path / "parallel"
    assert main([*TINY, "--seeds", "5", "6", "--jobs", "2", "--out", str(out)]) == 0
    serial = json.loads((serial_run / "seeds.json").read_text())
    parallel = json.loads((out / "seeds.json").read_text())
    for a, b in zip(serial["per_seed"], parallel["per_seed"], strict=True):
        assert a["seed"] == b["seed"]
        assert a["evaluations"] == b["evaluations"]  # same seed, same run, whatever process it ran in
        assert [e["success"] for e in a["training_evaluations"]] == [e["success"] for e in b["training_evaluations"]]


def test_training_on_the_fast_full_model_is_evaluated_at_the_reference_steps(tmp_path):
    out = tmp_path / "full"
    assert main([*TINY, "--probe-every", "0", "--seeds", "3", "--out", str(out), "--env", "PectoralFish-Full-v0",
                 "--hyperparams", "env_kwargs.integration=fast"]) == 0
    report = json.loads((out / "seeds.json").read_text())
    assert report["settings"]["train_env"] == "PectoralFish-Full-v0"
    assert yaml.safe_load((out / "seed3" / "config.yaml").read_text())["env_kwargs"]["integration"] == "fast"
    for label in ("averaged", "full", "full+rand"):
        assert "integration" not in json.loads((out / "seed3" / f"eval_{label}.json").read_text())["env_kwargs"]


def test_bad_arguments_fail_precisely(tmp_path, capsys):
    assert main([*TINY, "--seeds", "1", "1", "--out", str(tmp_path / "a")]) == 2
    assert "distinct" in capsys.readouterr().err
    assert main([*TINY, "--seeds", "1", "--jobs", "0", "--out", str(tmp_path / "b")]) == 2
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "--jobs" in capsys.readouterr().out
