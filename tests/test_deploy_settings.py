"""What the deploy runs a controller with, checked before anything moves: the env settings taken from a policy's
run folder (task, control period, ranges; a mismatch refused, a simulated camera or command delays noted and not
applied), the version a robot env starts from, and the baselines' stopping band (the supervisor's widened as the
robot-ready envs widen it).

The deploy end to end, its arguments and its resources: ``tests/test_deploy.py``.
"""

import pytest

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.safety.rules import SafetyConfig


class _Trained:
    """A stand-in for pectoral_gym.agents.training.policy.SB3Controller (no torch): what a run folder records."""

    name = "ppo"

    def __init__(self, obs_size=19, action_size=8, trained=None, trained_from="run/config.yaml"):
        self.obs_size, self.action_size = obs_size, action_size
        self.trained = trained or {}
        self.trained_from = trained_from if trained else None


def test_policy_settings_default_to_its_own_and_a_mismatch_is_refused():
    from pectoral_gym.hardware.deploy_checks import env_settings

    goal = _Trained(trained={"task": "goal", "control_period": 0.5, "observe_fins": False})
    settings, notes = env_settings(goal, None, None)
    assert settings == {"observe_fins": False, "task": "goal", "control_period": 0.5} and not notes
    with pytest.raises(ValueError, match="trained with task 'goal'.*pass --task goal"):
        env_settings(goal, "track", None)
    with pytest.raises(ValueError, match="control_period 0.5"):
        env_settings(goal, None, 1.0)
    assert env_settings(goal, "goal", 0.5)[0]["task"] == "goal"
    track = _Trained(trained={"task": "track", "control_period": 1.0, "observe_fins": True,
                              "amplitude_range": [0.0, 0.4]}, obs_size=27)
    settings, _ = env_settings(track, None, None)
    assert settings["task"] == "track" and settings["control_period"] == 1.0 and settings["observe_fins"]
    assert settings["amplitude_range"] == (0.0, 0.4)  # the policy's action mapping
    with pytest.raises(ValueError, match="inconsistent"):
        env_settings(_Trained(obs_size=19, trained={"observe_fins": True}), None, None)
    with pytest.raises(ValueError, match="observation entries"):
        env_settings(_Trained(obs_size=23), None, None)
    with pytest.raises(ValueError, match="returns 4 actions"):
        env_settings(_Trained(action_size=4), None, None)
    # a bare .zip records nothing: the observation size is checked, the rest said not to be
    settings, notes = env_settings(_Trained(obs_size=27), "track", None)
    assert settings == {"observe_fins": True, "task": "track", "control_period": 0.5}
    assert len(notes) == 2 and "not checked" in notes[0]
    # a baseline gets the v1 envs' goals
    assert env_settings(None, None, None) == ({"task": "goal", "control_period": 0.5, "goal_inset": 0.3}, [])


def test_the_robot_env_starts_from_the_version_the_deploy_names():
    """What a robot env builds with no argument set is the id the deploy's checks compare a policy with."""
    from pectoral_gym.hardware.deploy_checks import ROBOT_ENV_BASE
    from pectoral_gym.hardware.stack import env_config
    from pectoral_gym.versions import ENV_VERSIONS

    named = EnvConfig(**{**ENV_VERSIONS[ROBOT_ENV_BASE].settings(), "task": "track", "control_period": 0.7})
    assert env_config("track", 0.7, {}) == named
    assert ROBOT_ENV_BASE == "PectoralFish-Full-v0"


def test_the_deploys_controllers_keep_the_geofence_widened_by_5_cm():
    from pectoral_gym.agents.baselines import make_baseline
    from pectoral_gym.hardware.deploy_controllers import make_controller
    from pectoral_gym.model.tank import StopRule
    from pectoral_gym.versions import ROBOT

    def shield_band(rule):  # the hand law's shield around ``rule`` (its own reserve on top)
        return make_baseline("hand", config, shield={"band": rule}).shield.band

    config = EnvConfig(model="full")
    assert ROBOT.stop_rule.as_tuple() == pytest.approx((0.10, 0.15, 0.03))  # the robot's 5 cm rule + 5 cm
    hand = make_controller("hand", config, step_budget=1.0)  # the default geofence: the robot-ready envs' band
    assert hand.shield.band == shield_band(StopRule(0.10, 0.15, 0.03))
    wide = make_controller("hand", config, step_budget=1.0, safety=SafetyConfig(stop_rule=StopRule(0.2, 0.15, 0.03)))
    assert wide.shield.band == shield_band(StopRule(0.25, 0.15, 0.03))


def test_a_policy_trained_through_the_simulated_camera_runs_on_the_real_one():
    """EnvConfig.sensing is recorded in a run, noted by the deploy, never applied on top of the robot's camera."""
    from pectoral_gym.hardware.deploy_checks import env_settings
    from pectoral_gym.hardware.env import HardwareFishEnv

    sensed = _Trained(obs_size=27, trained={"task": "goal", "control_period": 0.5, "observe_fins": True,
                                            "sensing": {"latency": 0.05}})
    settings, notes = env_settings(sensed, None, None)
    assert "sensing" not in settings and any("simulated camera" in note for note in notes)
    with pytest.raises(ValueError, match="sensing .* must not be set here"):
        HardwareFishEnv("loop://", None, sensing={"latency": 0.05})


def test_a_policy_trained_with_simulated_command_delays_runs_on_the_robots_own():
    """EnvConfig.timing is recorded in a run, noted by the deploy, never applied on top of the robot's clock."""
    from pectoral_gym.hardware.deploy_checks import env_settings
    from pectoral_gym.hardware.env import HardwareFishEnv

    timed = _Trained(obs_size=27, trained={"task": "goal", "control_period": 0.5, "observe_fins": True,
                                           "timing": {"command_latency": [0.0, 0.1]}})
    settings, notes = env_settings(timed, None, None)
    assert "timing" not in settings and any("simulated command delays" in note for note in notes)
    with pytest.raises(ValueError, match="timing .* must not be set here"):
        HardwareFishEnv("loop://", None, timing={})
