"""Evaluation metrics on hand-made trajectories, bootstrap intervals, and the batched evaluation loop."""

import json
import math

import numpy as np
import pytest

from pectoral_gym.agents.training.evaluate import evaluate, format_table, main, plot_trajectories, write_json
from pectoral_gym.agents.training.metrics import (
    Trajectory,
    bootstrap_ci,
    episode_metrics,
    path_length,
    summarize,
    time_to_goal,
    tracking_error,
)

ENV = "PectoralFish-Averaged-v0"


def make_trajectory(xy, distance, reward, work, dt=0.5, success=False, wall=False):
    xy = np.asarray(xy, dtype=float)
    return Trajectory(xy=xy, psi=np.zeros(len(xy)), target=np.zeros_like(xy), distance=np.asarray(distance, float),
                      reward=np.asarray(reward, float), fin_work=np.asarray(work, float), control_period=dt,
                      success=success, wall=wall)


def test_path_length_of_a_3_4_5_polyline():
    # (0,0) -> (3,0) -> (3,4): 3 + 4 = 7; the straight line (0,0)-(3,4) would be 5
    assert path_length([[0, 0], [3, 0], [3, 4]]) == pytest.approx(7.0)
    assert path_length([[1, 1]]) == 0.0
    with pytest.raises(ValueError, match="shape"):
        path_length([1, 2, 3])


def test_goal_episode_metrics_by_hand():
    # 4 steps of 0.5 s along x by 0.1 m each, success at the end
    traj = make_trajectory(xy=[[0, 0], [0.1, 0], [0.2, 0], [0.3, 0], [0.4, 0]],
                           distance=[0.45, 0.35, 0.25, 0.15, 0.05], reward=[1, 1, 1, 11],
                           work=[0.1, 0.2, 0.3, 0.4], success=True)
    m = episode_metrics(traj, "goal")
    assert m["success"] == 1.0
    assert m["time_to_goal"] == pytest.approx(2.0)  # 4 steps * 0.5 s
    assert m["path_length"] == pytest.approx(0.4)
    assert m["final_distance"] == pytest.approx(0.05)
    assert m["fin_work"] == pytest.approx(1.0)
    assert m["mean_fin_power"] == pytest.approx(0.5)  # 1 J over 2 s
    assert m["return"] == pytest.approx(14.0)
    assert m["wall"] == 0.0
    assert m["length"] == 4.0
    assert "tracking_error" not in m


def test_failed_goal_episode_has_no_time_to_goal():
    traj = make_trajectory(xy=[[0, 0], [0, 0.1]], distance=[1.0, 0.9], reward=[-10], work=[0.0], wall=True)
    m = episode_metrics(traj, "goal")
    assert m["success"] == 0.0 and m["wall"] == 1.0
    assert math.isnan(m["time_to_goal"]) and math.isnan(time_to_goal(traj))


def test_tracking_error_excludes_the_reset_sample():
    # distances after the three steps: 0.2, 0.4, 0.6 -> mean 0.4 (the reset sample 10.0 is not a step)
    traj = make_trajectory(xy=np.zeros((4, 2)), distance=[10.0, 0.2, 0.4, 0.6], reward=[0, 0, 0], work=[0, 0, 0])
    assert tracking_error(traj.distance) == pytest.approx(0.4)
    m = episode_metrics(traj, "track")
    assert m["tracking_error"] == pytest.approx(0.4)
    assert "success" not in m
    with pytest.raises(ValueError, match="task"):
        episode_metrics(traj, "dance")


def test_bootstrap_interval_contains_the_mean_and_is_seeded():
    values = np.random.default_rng(1).normal(3.0, 1.0, 200)
    low, high = bootstrap_ci(values, seed=7)
    assert low < values.mean() < high
    # standard error 1/sqrt(200) ~ 0.071: a 95 % interval is about +-0.14 wide
    assert 0.08 < (high - low) / 2 < 0.2
    assert bootstrap_ci(values, seed=7) == (low, high)
    assert bootstrap_ci(values, seed=8) != (low, high)


def test_bootstrap_edge_cases():
    assert bootstrap_ci([2.5]) == (2.5, 2.5)
    assert all(math.isnan(v) for v in bootstrap_ci([]))
    assert bootstrap_ci([1.0, 1.0, 1.0]) == (1.0, 1.0)
    assert bootstrap_ci([0.0, 1.0, np.nan] * 20, seed=0)[0] >= 0.0
    with pytest.raises(ValueError):
        bootstrap_ci([1, 2], confidence=1.5)


def test_summarize_success_rate_ignores_nan():
    s = summarize([1.0, 0.0, 1.0, 1.0, np.nan])
    assert s.mean == pytest.approx(0.75) and s.n == 4
    assert 0.0 <= s.low <= s.mean <= s.high <= 1.0
    assert s.as_dict()["mean"] == pytest.approx(0.75)
    assert summarize([np.nan]).as_dict()["mean"] is None


class StraightController:
    """Both fins beat alike: the fish swims straight ahead."""

    name = "straight"

    def __init__(self):
        self.resets = []

    def reset(self, seed=None):
        self.resets.append(seed)

    def act(self, obs):
        action = np.zeros(8, dtype=np.float32)
        action[[1, 5]] = 1.0  # full amplitude
        action[[3, 7]] = 1.0  # fast power stroke
        return action


class StraightBatch(StraightController):
    def act_batch(self, obs):
        return np.stack([self.act(o) for o in obs])


def test_evaluation_is_seeded_and_independent_of_batching():
    single = StraightController()
    one = evaluate(single, ENV, n_episodes=6, seed=11)
    assert single.resets == list(range(11, 17))  # episode k reset with seed + k
    factory = evaluate(StraightController, ENV, n_episodes=6, seed=11, n_envs=4)
    batch = evaluate(StraightBatch(), ENV, n_episodes=6, seed=11, n_envs=3)
    for other in (factory, batch):
        assert [e["return"] for e in other.episodes] == pytest.approx([e["return"] for e in one.episodes])
        for a, b in zip(one.trajectories, other.trajectories, strict=True):
            np.testing.assert_array_equal(a.xy, b.xy)


def test_evaluation_trajectories_match_the_environment():
    import gymnasium as gym

    result = evaluate(StraightController(), ENV, n_episodes=2, seed=3)
    env = gym.make(ENV)
    controller = StraightController()
    for k, traj in enumerate(result.trajectories):
        obs, _ = env.reset(seed=3 + k)
        xy, rewards, work = [obs[:2]], [], []
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(controller.act(obs))
            xy.append(obs[:2])
            rewards.append(reward)
            work.append(-info["reward_energy"])  # energy_weight = 1 J^-1
            done = terminated or truncated
        np.testing.assert_allclose(traj.xy, np.array(xy), rtol=0, atol=1e-6)
        np.testing.assert_allclose(traj.reward, rewards)
        np.testing.assert_allclose(traj.fin_work, work)
        assert traj.wall == (info["reward_wall"] < 0)
        assert traj.success == info["is_success"]
    # the target is fixed in the goal task and reconstructed from the body-frame observation
    assert np.ptp(result.trajectories[0].target, axis=0) == pytest.approx([0, 0], abs=1e-5)


def test_fin_work_without_energy_term_matches_with_it():
    a = evaluate(StraightController(), ENV, n_episodes=2, seed=5)
    b = evaluate(StraightController(), ENV, n_episodes=2, seed=5, env_kwargs={"energy_weight": 0.0})
    assert b.metrics["fin_work"].mean == pytest.approx(a.metrics["fin_work"].mean, rel=1e-5)


def test_evaluation_errors():
    with pytest.raises(ValueError, match="n_episodes"):
        evaluate(StraightController(), ENV, n_episodes=0)
    with pytest.raises(ValueError, match="unknown env id"):
        evaluate(StraightController(), "CartPole-v1", n_episodes=1)
    with pytest.raises(TypeError):
        evaluate(42, ENV, n_episodes=1)
    with pytest.raises(ValueError, match="factory"):
        evaluate(StraightController(), ENV, n_episodes=4, n_envs=2)


def test_json_plot_and_table(tmp_path):
    result = evaluate(StraightController, ENV, n_episodes=3, seed=0, env_kwargs={"task": "track"})
    data = json.loads(write_json(result, tmp_path / "m.json").read_text())
    assert data["task"] == "track" and data["n_episodes"] == 3
    assert set(data["metrics"]["tracking_error"]) == {"mean", "ci_low", "ci_high", "n"}
    assert len(data["episodes"]) == 3
    png = plot_trajectories(result, tmp_path / "t.png")
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert "tracking_error" in format_table([result])


def test_cli_rejects_bad_arguments(capsys, tmp_path):
    assert main(["--policy", str(tmp_path / "nothing"), "--episodes", "1", "--out", str(tmp_path)]) == 2
    assert "neither" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--env", ENV])  # needs --policy or --controller


def test_cli_scaling_lets_the_baselines_plan_for_another_robot(capsys, tmp_path):
    import dataclasses

    from pectoral_gym.model.kfunctions import ScalingFunctions
    from pectoral_gym.model.params import FishParams, save_params

    robot = FishParams().replace(drag_coef=0.45)
    save_params(robot, tmp_path / "robot.json")
    k = ScalingFunctions.load(None)  # relabelled as identified for the robot: which file is used is what counts
    k.metadata["model_parameters"] = dataclasses.asdict(robot)
    k.save(tmp_path / "k.json")
    common = ["--controller", "hand", "--env", "PectoralFish-Full-v1", "--episodes", "1",
              "--env-kwargs", json.dumps({"params": str(tmp_path / "robot.json")}), "--out", str(tmp_path / "e")]
    assert main(common) == 2  # the shipped K were identified for Table 1's fish
    assert "drag_coef" in capsys.readouterr().err
    assert main([*common, "--scaling", str(tmp_path / "k.json")]) == 0
    for bad, message in ((["--controller", "random", "--scaling", str(tmp_path / "k.json")], "--scaling is the K"),
                         (["--controller", "hand", "--scaling", str(tmp_path / "none.json")], "no coefficients file")):
        with pytest.raises(SystemExit) as exit_:  # a usage error, as pectoral-deploy's
            main([*bad, "--env", ENV, "--episodes", "1", "--out", str(tmp_path / "r")])
        assert exit_.value.code == 2 and message in capsys.readouterr().err


class FastBeatController(StraightController):
    """Both fins at full amplitude, the shortest period (one beat per 0.5 s step) and the largest ratio."""

    def act(self, obs):
        action = np.zeros(8, dtype=np.float32)
        action[[1, 5]] = 1.0
        action[[2, 6]] = -1.0
        action[[3, 7]] = 1.0
        return action


def test_swept_work_prices_the_first_stroke_from_rest_by_what_it_sweeps():
    """From rest at 90 deg, the first power stroke sweeps 90 -> 120 deg (half 15 deg) where a regular one
    sweeps 60 -> 120 deg (half 30 deg); after it every 0.5 s step holds one regular beat, priced alike."""
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.model.params import FishParams

    result = evaluate(FastBeatController(), ENV, n_episodes=1, seed=2)
    traj = result.trajectories[0]
    config, params = EnvConfig(), FishParams()
    assert config.period_range[0] == config.control_period == 0.5
    np.testing.assert_allclose(traj.swept_work[1:], traj.fin_work[1:], rtol=1e-9)
    d1 = 0.5 / (config.ratio_range[1] + 1.0)
    power = 0.75 * params.fin_drag_constant * params.fin_span * 4.0 / 3.0 * (math.pi / d1) ** 2  # per |half|^3
    missing = 2 * power * (math.radians(30) ** 3 - math.radians(15) ** 3)  # both fins
    assert traj.swept_work[0] == pytest.approx(traj.fin_work[0] - missing, rel=1e-9)
    assert result.metrics["swept_work"].mean == pytest.approx(float(np.sum(traj.swept_work)))


def test_trained_env_kwargs_drop_the_other_models_settings(tmp_path):
    import yaml

    from pectoral_gym.agents.training.evaluate import model_kwargs, trained_env_kwargs

    run = {"task": "goal", "observe_fins": True, "integration": "fast", "randomize": {"drag_coef": 0.2}}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({"env_kwargs": run}))
    # a policy trained on the fast full model is evaluated at the reference steps, on either model
    assert trained_env_kwargs(tmp_path, "PectoralFish-Full-v0") == {"task": "goal", "observe_fins": True}
    assert trained_env_kwargs(tmp_path, "PectoralFish-Averaged-v0") == {"task": "goal", "observe_fins": True}
    # a periodic evaluation on the averaged env drops the full model's setting, and the reverse
    assert model_kwargs("PectoralFish-Averaged-v0", {"integration": "fast", "transitions": True}) == {
        "transitions": True}
    assert model_kwargs("PectoralFish-Full-v0", {"integration": "fast", "transitions": True}) == {
        "integration": "fast"}


def test_cli_no_progress_draws_no_bar(capsys, tmp_path):
    """``--no-progress``, as every other command with a progress bar spells it."""
    args = ["--controller", "hand", "--env", ENV, "--episodes", "1", "--out", str(tmp_path / "e")]
    assert main([*args, "--no-progress"]) == 0
    assert "it/s" not in capsys.readouterr().err
    assert main(args) == 0
    assert "it/s" in capsys.readouterr().err
