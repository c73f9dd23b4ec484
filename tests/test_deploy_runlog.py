"""The deploy's run log (``run.jsonl``, docs/run-log.md) and ``--emulate-params``: what a model calibration reads."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from pectoral_gym.model.params import FishParams, save_params
from pectoral_gym.runlog import read_run_log


def _deploy(out, *extra, episodes=2, seed=5, steps=12):
    """The deploy in lockstep (the hand law unless ``extra`` names another controller: the last flag wins)."""
    from pectoral_gym.hardware import deploy

    args = ["--controller", "hand", "--emulate", "--lockstep", "--episodes", str(episodes), "--max-episode-steps",
            str(steps), "--seed", str(seed), "--out", str(out), "--no-progress", "--nice", "0", *extra]
    result: dict = {}
    # a fresh VirtualClock takes the calling thread in: run the deploy in a thread of its own, as tests/test_lockstep.py
    thread = threading.Thread(target=lambda: result.setdefault("status", deploy.main(args)))
    thread.start()
    thread.join(timeout=300.0)
    assert result.get("status") == 0
    steps_log = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    return read_run_log(out / "run.jsonl"), steps_log, json.loads((out / "summary.json").read_text())


def test_a_lockstep_deploy_writes_a_run_log_that_matches_its_steps(tmp_path):
    log, steps, summary = _deploy(tmp_path / "a")
    assert log.header["source"] == "emulator" and log.header["control_period"] == summary["settings"]["control_period"]
    assert [ep.index for ep in log.episodes] == [0, 1]
    for ep in log.episodes:
        sent = [r["command"] for r in steps if r.get("episode") == ep.index and "command" in r]
        # every step sends its command once (the lease renewals inside a step repeat it and are not logged)
        assert len(ep.command_t) == len(sent) and np.allclose(ep.beats, np.asarray(sent))
        assert np.allclose(np.diff(ep.command_t), 0.5, atol=1e-6)  # one control period apart, simulated time
        # the camera's poses at 30 frames per simulated second, after the episode's start and in order
        assert np.all(np.diff(ep.pose_t) > 0) and ep.pose_t[0] >= ep.t_start
        span = ep.pose_t[-1] - ep.pose_t[0]
        assert len(ep.pose_t) == pytest.approx(span * 30.0, rel=0.1)
        assert len(ep.stop_t) >= 1 and ep.stop_t[-1] >= ep.command_t[-1]  # the fins stop at the episode's end
        # the measured poses are the emulated fish's true poses up to the camera's error (mm)
        true = np.array([r["true_pose"][:2] for r in steps if r.get("episode") == ep.index and "action" in r])
        measured = np.array([r["pose"][:2] for r in steps if r.get("episode") == ep.index and "action" in r])
        assert np.max(np.linalg.norm(true - measured, axis=1)) < 0.02
    # the second episode follows the first on the merged log's time line
    assert log.episodes[1].t_start > log.episodes[0].t_end


def test_emulate_params_gives_the_emulated_fish_other_parameters(tmp_path):
    table1 = FishParams()
    heavy = table1.replace(drag_coef=table1.drag_coef * 1.5, fin_force_coef=table1.fin_force_coef * 0.7)
    save_params(heavy, tmp_path / "robot.json")
    # the identification run's controller: the same seeded commands on both fish (a deploy that plans with a model
    # first checks it against the robot: the hand law would need --params and its K for the heavy fish)
    _, nominal_steps, _ = _deploy(tmp_path / "nominal", "--controller", "excite", episodes=1)
    _, heavy_steps, summary = _deploy(tmp_path / "heavy", "--controller", "excite", "--emulate-params",
                                      str(tmp_path / "robot.json"), episodes=1)
    assert summary["emulation"]["params"]["drag_coef"] == pytest.approx(heavy.drag_coef)

    def travelled(steps):
        path = np.array([r["true_pose"][:2] for r in steps if "action" in r])
        return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))

    # the same seed, start and controller: more drag and less fin force make the fish swim less far
    assert travelled(heavy_steps) < 0.9 * travelled(nominal_steps)


def test_emulate_params_refuses_a_bad_file_or_a_real_robot(tmp_path, capsys):
    from pectoral_gym.hardware import deploy

    bad = tmp_path / "bad.json"
    bad.write_text('{"drag_coef": "a lot"}')
    with pytest.raises(SystemExit) as exit_:
        deploy.main(["--controller", "hand", "--emulate", "--emulate-params", str(bad), "--out", str(tmp_path / "o")])
    assert exit_.value.code == 2 and "--emulate-params" in capsys.readouterr().err
    save_params(FishParams(), tmp_path / "ok.json")
    with pytest.raises(SystemExit) as exit_:
        deploy.main(["--controller", "hand", "--port", "/dev/null", "--camera", "0", "--emulate-params",
                     str(tmp_path / "ok.json"), "--out", str(tmp_path / "o")])
    assert exit_.value.code == 2 and "needs --emulate" in capsys.readouterr().err


def test_an_identification_run_logs_varied_fin_patterns(tmp_path):
    # --controller excite: seeded random patterns held 2-6 s (4-12 steps), so 24 steps log several distinct ones
    log, steps, summary = _deploy(tmp_path / "id", "--controller", "excite", episodes=1, steps=24)
    assert summary["controller"] == "excite"
    assert summary["settings"]["goal_radius"] == 0.0  # no goal to reach: no episode ends at one by chance
    beats = log.episodes[0].beats
    distinct = np.unique(beats.reshape(len(beats), -1), axis=0)
    assert len(beats) == 24 and len(distinct) >= 3


def test_params_give_the_supervisor_the_robots_own_stopping_distance(tmp_path, capsys):
    from pectoral_gym.hardware import deploy
    from pectoral_gym.hardware.deploy_cli import make_parser
    from pectoral_gym.hardware.safety.geofence import Geofence
    from pectoral_gym.model import tank
    from pectoral_gym.model.params import body_coefficients

    # less drag: the robot coasts further than Table 1's fish, so its geofence must keep a wider band
    table1 = FishParams()
    slippery = table1.replace(drag_coef=table1.drag_coef * 0.7)
    save_params(slippery, tmp_path / "robot.json")
    assert make_parser("deploy").parse_args(["--params", str(tmp_path / "robot.json")]).params == slippery
    rule = tank.StopRule(0.05, 0.3, 0.01)
    assert Geofence(slippery, rule).k == tank.coast_rate(body_coefficients(slippery))
    assert Geofence(slippery, rule).k < Geofence(table1, rule).k
    # the env the supervisor is built from gets them (a policy: the baselines plan with K, identified for Table 1)
    import gymnasium as gym
    from stable_baselines3 import PPO

    env = gym.make("PectoralFish-Averaged-v0")
    PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu").learn(32).save(
        tmp_path / "ppo.zip")
    env.close()
    _, _, summary = _deploy(tmp_path / "run", "--params", str(tmp_path / "robot.json"), "--emulate-params",
                            str(tmp_path / "robot.json"), "--controller", "policy", "--policy",
                            str(tmp_path / "ppo.zip"), episodes=1, steps=4)
    assert summary["settings"]["params"]["drag_coef"] == pytest.approx(slippery.drag_coef)
    with pytest.raises(SystemExit) as exit_:
        deploy.main(["--controller", "hand", "--emulate", "--lockstep", "--params", str(tmp_path / "robot.json"),
                     "--episodes", "1", "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "drag_coef differ from --params" in err and "--scaling FILE" in err


def _k_file_for(params: FishParams, path) -> str:
    """The shipped K file relabelled as identified for ``params`` (the plumbing's test: which file is used)."""
    import dataclasses

    from pectoral_gym.model.kfunctions import ScalingFunctions

    k = ScalingFunctions.load(None)
    k.metadata["model_parameters"] = dataclasses.asdict(params)
    k.save(path)
    return str(path)


def test_scaling_gives_the_baselines_the_robots_own_k(tmp_path, capsys):
    from pectoral_gym.agents.controllers.fin_map import FinMap
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.hardware import deploy

    robot = FishParams().replace(drag_coef=0.45, fin_force_coef=4.4)
    save_params(robot, tmp_path / "robot.json")
    k_robot = _k_file_for(robot, tmp_path / "k_robot.json")
    # the hand law and the NMPC both plan with the file given, checked against the robot's params
    config = EnvConfig(model="full", params=robot)
    hand = deploy.make_controller("hand", config, 1.0, scaling=k_robot)
    assert hand.fins.spec.scaling == k_robot
    # the planning model's top speed follows the robot's params: drag balance c1 v^2 = 2 f (eq. 20) with f from K
    table1 = FinMap(EnvConfig(model="full"))
    assert hand.fins.max_thrust == pytest.approx(table1.max_thrust * 4.4 / FishParams().fin_force_coef, rel=1e-9)
    nmpc = deploy.make_controller("nmpc", config, 1.0, scaling=k_robot)
    assert nmpc.fins.spec.scaling == k_robot and nmpc.hand.fins.spec.scaling == k_robot
    # a K file identified for another robot is refused, naming the fields
    k_other = _k_file_for(robot.replace(drag_coef=0.5), tmp_path / "k_other.json")
    with pytest.raises(ValueError, match="drag_coef"):
        deploy.make_controller("hand", config, 1.0, scaling=k_other)
    # through the command line, in lockstep, on an emulated fish of those params
    _, steps, summary = _deploy(tmp_path / "run", "--params", str(tmp_path / "robot.json"), "--scaling", k_robot,
                                "--emulate-params", str(tmp_path / "robot.json"), episodes=1, steps=4)
    assert len(steps) >= 1 and summary["settings"]["params"]["fin_force_coef"] == pytest.approx(4.4)
    for bad, message in ((["--controller", "policy", "--policy", "x"], "--scaling is the K"),
                         (["--controller", "hand", "--scaling", str(tmp_path / "none.json")], "no coefficients file")):
        with pytest.raises(SystemExit) as exit_:
            deploy.main([*bad, "--emulate", "--lockstep", "--out", str(tmp_path / "o"), "--no-progress"]
                        + ([] if "--scaling" in bad else ["--scaling", k_robot]))
        assert exit_.value.code == 2 and message in capsys.readouterr().err
