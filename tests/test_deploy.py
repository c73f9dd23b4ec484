"""End-to-end dry run: ``hardware.deploy --emulate`` with a PPO policy trained for a few steps."""

import json

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401 - registers the ids
from hardware.deploy import main, plot_trajectories, run_episodes
from hardware.emulator import EmulatedRobot
from hardware.env import HardwareFishEnv
from hardware.safety import SafetyConfig
from pectoral_gym.envs.core import EnvConfig

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop


@pytest.fixture(scope="module")
def policy_zip(tmp_path_factory):
    from stable_baselines3 import PPO

    env = gym.make("PectoralFish-Averaged-v0")
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=32)
    path = tmp_path_factory.mktemp("policy") / "ppo.zip"
    model.save(path)
    env.close()
    return path


@pytest.mark.slow  # ~15 s: torch import and a short PPO run
def test_deploy_emulate_end_to_end(policy_zip, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["--policy", str(policy_zip), "--emulate", "--speed", "2", "--episodes", "2", "--max-steps", "3",
                 "--out", str(out), "--quiet", "--tracking-timeout", "1.5"])
    assert code == 0
    lines = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    steps = [r for r in lines if r.get("event") != "reset"]
    assert [r["episode"] for r in lines if r.get("event") == "reset"] == [0, 1]
    assert 2 <= len(steps) <= 6 and all(len(r["command"]) == 2 and len(r["estimate"]) == 6 for r in steps)
    assert all("true_pose" in r and r["link"]["sent"] > 0 for r in steps)
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["episodes"]) == 2
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert "episode 1:" in capsys.readouterr().out


def test_deploy_runs_a_policy_that_observes_the_fins_on_the_fin_replay(tmp_path):
    from stable_baselines3 import PPO

    env = gym.make("PectoralFish-Averaged-v0", observe_fins=True)  # 27 entries: the robot env replays the fins
    path = tmp_path / "fins.zip"
    PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu").save(path)
    out = tmp_path / "run"
    code = main(["--policy", str(path), "--emulate", "--speed", "2", "--episodes", "1", "--max-steps", "3",
                 "--out", str(out), "--quiet", "--tracking-timeout", "1.5"])
    assert code == 0
    steps = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    assert len([r for r in steps if r.get("event") != "reset"]) >= 1


def test_deploy_needs_port_and_camera_without_emulate(tmp_path):
    with pytest.raises(SystemExit):
        main(["--policy", str(tmp_path / "none.zip"), "--out", str(tmp_path)])


class _Forward:
    """A fixed controller (no torch): both fins row forward."""

    name = "forward"

    def reset(self, seed=None):
        pass

    def act(self, obs):
        return np.array([0.5, 0.5, 0.0, 0.5] * 2, dtype=np.float32)


def test_run_episodes_and_plot_on_the_emulator_fast(tmp_path):
    robot = EmulatedRobot(speed=2.0, seed=0, start_pose=(1.0, 0.575, 0.0)).start()
    # 3 s without a sighting before tracking_lost: a slow camera on a loaded machine must not stop the
    # fish before it rows (a loaded run once ended with the fish where it started).
    # 6 steps (3 s of emulated time): a fresh clone's first steps compile numba kernels, and with 3 steps a
    # CI run once ended before the fins had rowed (x 1.0 - 4e-7).
    env = HardwareFishEnv(robot.url, robot.camera(seed=0), speed=2.0, max_episode_steps=6,
                          safety=SafetyConfig(tracking_timeout=3.0))
    try:
        summaries = run_episodes(env, _Forward(), 1, tmp_path / "steps.jsonl", seed=0, robot=robot, progress=False)
    finally:
        env.close()
        robot.stop()
    assert summaries[0]["steps"] == 6 and summaries[0]["truncated"]
    lines = [json.loads(line) for line in (tmp_path / "steps.jsonl").read_text().splitlines()]
    assert len(lines) == 7 and lines[-1]["true_pose"][0] > 1.0  # rowed forward along +X
    plot_trajectories(tmp_path / "steps.jsonl", tmp_path / "trajectory.png")
    assert (tmp_path / "trajectory.png").stat().st_size > 10_000


def _deploy(tmp_path, *extra):
    out = tmp_path / "run"
    code = main(["--emulate", "--speed", "2", "--episodes", "1", "--max-steps", "4", "--out", str(out), "--quiet",
                 "--tracking-timeout", "1.5", *extra])
    assert code == 0
    steps = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    return [r for r in steps if r.get("event") != "reset"], json.loads((out / "summary.json").read_text())


def test_deploy_nmpc_on_the_emulator(tmp_path):
    """``--controller nmpc`` drives the emulated robot: one solve per step, recorded in the summary."""
    steps, summary = _deploy(tmp_path, "--controller", "nmpc")
    assert summary["controller"] == "nmpc" and summary["policy"] is None
    solver = summary["solver"]
    assert solver["solves"] == len(steps) >= 1 and solver["failures"] >= solver["late"] >= 0
    assert all(len(r["command"]) == 2 for r in steps)


def test_deploy_nmpc_sends_the_safe_fallback_when_every_solve_is_late(tmp_path):
    """A solve that ends after its share of the control period is not applied: the fins rest (no plan yet)."""
    steps, summary = _deploy(tmp_path, "--controller", "nmpc", "--solve-fraction", "1e-9")
    assert summary["solver"]["late"] == summary["solver"]["solves"] == len(steps) >= 1
    lowest = EnvConfig(model="full").amplitude_range[0]
    amplitudes = [beat[1] for r in steps for beat in r["command"]]  # command rows: bias, amplitude, period, ratio
    np.testing.assert_allclose(amplitudes, lowest, atol=1e-9)


def test_deploy_controller_and_policy_arguments_must_agree(tmp_path):
    with pytest.raises(SystemExit):
        main(["--controller", "nmpc", "--policy", str(tmp_path / "p.zip"), "--emulate", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        main(["--emulate", "--out", str(tmp_path)])  # --controller policy needs --policy
