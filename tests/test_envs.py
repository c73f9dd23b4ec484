"""The single-fish Gymnasium environments: API, seeding, rewards, settings (episode ends and starts:
``tests/test_env_episodes.py``)."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym import FishParams
from pectoral_gym.envs import EnvConfig, PectoralFishEnv
from pectoral_gym.model.tank import StopRule
from pectoral_gym.registration import ENV_IDS, registered_settings

IDS = ["PectoralFish-Averaged-v0", "PectoralFish-Full-v0"]
ALL_IDS = sorted(ENV_IDS)
TASKS = ["goal", "track"]
GOAL_TERMS = ["reward_progress", "reward_goal", "reward_wall", "reward_energy", "reward_time"]
TRACK_TERMS = ["reward_tracking", "reward_wall", "reward_energy"]


def rollout(env, seed, steps, action_seed=0):
    """Observations, rewards and infos of a random rollout (resets when an episode ends)."""
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    records = [(obs, None, None)]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 8).astype(np.float32))
        records.append((obs, reward, info))
        if terminated or truncated:
            obs, _ = env.reset()
            records.append((obs, None, None))
    return records


def _make(env_id, **kwargs):
    """``gym.make`` without Gymnasium's notice that a -v0 id has a newer version (its intended behaviour)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*is out of date", DeprecationWarning)
        return gym.make(env_id, **kwargs)


@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("task", TASKS)
def test_gymnasium_env_checker(env_id, task):
    env = _make(env_id, task=task)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_v0_ids_say_a_newer_version_exists():
    with pytest.warns(DeprecationWarning, match="out of date"):
        gym.make("PectoralFish-Averaged-v0").close()


@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("task", TASKS)
def test_sb3_env_checker(env_id, task):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = _make(env_id, task=task)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(env, warn=True)
    env.close()


def test_registry_and_spaces():
    for env_id, model in zip(IDS, ["averaged", "full"], strict=True):
        spec = gym.spec(env_id)
        assert spec.max_episode_steps == 240
        # The id states every setting of its version; those of v0 are EnvConfig's own defaults.
        assert spec.kwargs["model"] == model and EnvConfig(**spec.kwargs) == EnvConfig(model=model)
        assert spec.vector_entry_point == "pectoral_gym.envs.vector:PectoralFishVectorEnv"
        env = gym.make(env_id)
        assert env.action_space == gym.spaces.Box(-1, 1, (8,), np.float32)
        space = env.observation_space
        assert space.shape == (19,) and space.dtype == np.float32 and space.is_bounded("both")
        # hand values at the defaults (control period 0.5 s, ref_speed 0.03 m/s): margin 2 m/s * 0.5 s = 1 m
        np.testing.assert_allclose(space.low[:4], [-1.0, -1.0, -1, -1]) and np.testing.assert_allclose(
            space.high[:4], [3.30, 2.15, 1, 1], rtol=1e-6)
        np.testing.assert_allclose(space.high[7:11], [math.hypot(4.30, 3.15)] * 2 + [0.0303] * 2, rtol=1e-6)
        np.testing.assert_array_equal(space.low[11:], -1.0)
        np.testing.assert_array_equal(space.high[11:], 1.0)
        assert env.unwrapped.config.model == model


def test_observation_structure_covers_the_observation_in_order():
    env = gym.make("PectoralFish-Averaged-v0")
    structure = env.unwrapped.observation_structure
    assert list(structure) == ["position", "heading", "velocity", "target", "target_velocity", "last_action"]
    assert sum(structure.values()) == env.observation_space.shape[0]
    obs, _ = env.reset(seed=3)
    blocks = np.split(obs, np.cumsum(list(structure.values()))[:-1])
    np.testing.assert_allclose(np.hypot(*blocks[1]), 1.0, rtol=1e-6)  # (cos psi, sin psi)
    np.testing.assert_array_equal(blocks[2], 0.0)  # at rest after a reset
    assert np.hypot(*blocks[3]) == pytest.approx(math.dist(obs[:2], env.unwrapped.target), rel=1e-5)


def _documented_arguments():
    """``{name: default text}`` of the Arguments table in the env's docstring."""
    section = PectoralFishEnv.__doc__.split("## Arguments")[1].split("##")[0]
    rows = [line.split("|")[1:3] for line in section.splitlines() if line.strip().startswith("| ``")]
    return {name.strip().strip("`"): default.strip() for name, default in rows}


def test_signature_and_documented_defaults_are_envconfigs():
    import dataclasses
    import inspect

    from pectoral_gym.envs import EnvConfig

    fields = {f.name: f.default for f in dataclasses.fields(EnvConfig)}
    parameters = inspect.signature(PectoralFishEnv).parameters
    assert list(parameters) == ["render_mode", *fields]
    assert all(parameters[name].default == default for name, default in fields.items())
    documented = _documented_arguments()
    assert set(documented) == set(parameters)
    for name, text in documented.items():
        default = fields.get(name)
        if text.startswith("``"):  # a literal: None or a string
            assert text.strip("`").strip('"') == str(default), name
        elif text.endswith("deg"):
            assert np.radians([float(v) for v in text[1:-5].split(",")]).tolist() == pytest.approx(default), name
        else:
            default = default.as_tuple() if isinstance(default, StopRule) else default  # documented as a triple
            assert pytest.approx(default) == eval(text), name  # noqa: S307 - a number or a tuple of numbers


@pytest.mark.parametrize("env_id", IDS)
def test_seeded_reset_reproducible_and_seeds_differ(env_id):
    env = gym.make(env_id, max_episode_steps=20)
    first = rollout(env, 7, 30)
    second = rollout(env, 7, 30)
    other = rollout(env, 8, 30)
    for (o1, r1, _), (o2, r2, _) in zip(first, second, strict=True):
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
    assert not np.array_equal(first[0][0], other[0][0])


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("task", TASKS)
def test_reward_is_the_sum_of_its_terms(env_id, task):
    env = gym.make(env_id, task=task, max_episode_steps=40)
    names = GOAL_TERMS if task == "goal" else TRACK_TERMS
    absent = set(GOAL_TERMS + TRACK_TERMS) - set(names)
    n_steps = 0
    for _, reward, info in rollout(env, 3, 120):
        if info is None:
            continue
        n_steps += 1
        assert set(names) <= set(info) and not absent & set(info)
        assert isinstance(reward, float)
        assert reward == sum(info[name] for name in names)  # summed in this order by the kernel
        assert info["distance"] >= 0
        if task == "goal":
            assert isinstance(info["is_success"], np.bool_)
            assert info["reward_time"] == -0.01
        else:
            assert info["tracking_error"] == info["distance"]
            assert info["reward_tracking"] == pytest.approx(-info["distance"])
        assert info["reward_energy"] <= 0
    assert n_steps == 120


def test_energy_term_matches_mean_fin_power():
    from pectoral_gym.model.averaging import mean_fin_power

    env = gym.make("PectoralFish-Averaged-v0", energy_weight=2.0)
    env.reset(seed=0)
    action = np.array([0.2, 1.0, -1.0, 1.0, -0.5, 0.0, 0.5, 0.0], np.float32)
    _, _, _, _, info = env.step(action)
    p = FishParams()
    power_right = mean_fin_power(math.radians(30), 0.5, 5.0, p.fin_span, p.fin_drag_constant)
    power_left = mean_fin_power(math.radians(15), 1.625, 3.0, p.fin_span, p.fin_drag_constant)
    assert info["reward_energy"] == pytest.approx(-2.0 * (power_right + power_left) * 0.5, rel=1e-6)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises_and_leaves_the_env_usable(bad):
    env = gym.make("PectoralFish-Averaged-v0")
    obs, _ = env.reset(seed=0)
    action = np.zeros(8, np.float32)
    action[3] = bad
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(action)
    np.testing.assert_array_equal(env.unwrapped.last_observation, obs)
    env.step(np.zeros(8, np.float32))


def test_actions_are_clipped_and_reported_in_the_observation():
    env = gym.make("PectoralFish-Averaged-v0")
    obs0, _ = env.reset(seed=1)
    np.testing.assert_allclose(obs0[11:], [0, -1, -1 / 3, -1] * 2, atol=1e-7)  # rest pattern, default ranges
    big = np.array([5, 5, -5, 5, 0.5, 2, -1, 0], np.float32)
    obs1, r1, *_ = env.step(big)
    np.testing.assert_allclose(obs1[11:], np.clip(big, -1, 1))
    env.reset(seed=1)
    obs2, r2, *_ = env.step(np.clip(big, -1, 1))
    np.testing.assert_array_equal(obs1, obs2)
    assert r1 == r2


def test_action_maps_linearly_to_the_ranges():
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0"))
    env.reset(seed=0)
    env.step(np.array([-1, 1, 0, 0.5, 1, -1, 1, -1], np.float32))
    right, left = env.fin_patterns
    np.testing.assert_allclose(right, [math.radians(45), math.radians(30), 1.25, 4.0])
    np.testing.assert_allclose(left, [math.radians(135), 0.0, 2.0, 1.0])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"bias_range": (2.0, 1.0)},
        {"bias_range": (0.1, 1.5)},  # bias - amplitude < 0
        {"bias_range": (1.0, 3.0)},  # bias + amplitude > pi
        {"amplitude_range": (-0.1, 0.2)},
        {"period_range": (0.0, 1.0)},
        {"period_range": (1.0, math.inf)},
        {"ratio_range": (-1.0, 2.0)},
        {"ratio_range": (math.nan, 2.0)},
        {"control_period": 0.0},
        {"task": "race"},
        {"model": "medium"},
        {"scaling": "none"},  # with the full model
        {"goal_radius": -1.0},
        {"randomize": {"drag_coef": 1.5}},
        {"render_mode": "ascii"},
    ],
)
def test_invalid_settings_raise(kwargs):
    kwargs = {"model": "full", **kwargs}
    with pytest.raises(ValueError):
        PectoralFishEnv(**kwargs)


def test_unknown_randomize_field_lists_the_valid_names():
    with pytest.raises(ValueError, match="body_mass"):
        PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0", dict(randomize={"fin_sapn": 0.1})))


def test_averaged_scaling_none_is_accepted():
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0", dict(scaling="none")))
    env.reset(seed=0)
    env.step(env.action_space.sample())


def test_domain_randomisation_per_episode_and_reproducible():
    widths = {"drag_coef": 0.3, "body_length": 0.2, "fin_span": 0.1}
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0", dict(randomize=widths)))
    base = FishParams()
    env.reset(seed=11)
    p1 = env.fish_params
    env.reset()
    p2 = env.fish_params
    assert p1 != p2
    for p in (p1, p2):
        for name, w in widths.items():
            assert abs(getattr(p, name) / getattr(base, name) - 1) <= w
        assert p.body_mass == base.body_mass
    np.testing.assert_array_equal(env.model.coef[0], pectoral_gym.model.params.coefficient_vector(p2))
    assert env.fish_constants.body_length == p2.body_length
    env.reset(seed=11)
    assert env.fish_params == p1
    plain = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0"))
    plain.reset(seed=11)
    assert plain.fish_params == base


def test_custom_params_are_used():
    params = FishParams(body_length=0.3)
    env = PectoralFishEnv(**registered_settings("PectoralFish-Full-v0", dict(params=params)))
    env.reset(seed=0)
    assert env.fish_params is params
    assert env.fish_constants.body_length == 0.3


def test_render_without_mode_warns():
    env = PectoralFishEnv(**registered_settings("PectoralFish-Averaged-v0"))
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_packed_layouts_cover_their_arrays_once():
    from pectoral_gym.envs import layout

    for prefix, size, wide in (("C_", layout.N_CFG, {"C_RANGES": 8}), ("E_", layout.N_EP, {}),
                               ("F_", layout.N_FISH, {}), ("O_", layout.N_OUT, {})):
        slots = []
        for name in layout.__all__:
            if name.startswith(prefix):
                start = getattr(layout, name)
                slots += range(start, start + wide.get(name, 1))
        assert sorted(slots) == list(range(size)), prefix
    assert layout.ACTION_SIZE == 2 * layout.FIN_ACTIONS == 8


def test_fast_integration_follows_the_reference_full_env():
    """``integration="fast"`` (models.FULL_INTEGRATION) is the same env at a coarser step: same spaces, the
    checkers pass, and 30 random actions (15 s) end within a few millimetres of the reference steps."""
    envs = {name: gym.make("PectoralFish-Full-v0", integration=name) for name in ("reference", "fast")}
    assert envs["fast"].unwrapped.model.min_substeps == 8 and envs["fast"].unwrapped.model.dt_max == 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(envs["fast"].unwrapped, skip_render_check=True)
    actions = np.random.default_rng(4).uniform(-1, 1, (30, 8)).astype(np.float32)
    end = {}
    for name, env in envs.items():
        env.reset(seed=11)
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
        end[name] = env.unwrapped.fish_state.copy()
    assert not np.array_equal(end["fast"], end["reference"])
    np.testing.assert_allclose(end["fast"][:3], end["reference"][:3], rtol=0, atol=5e-3)


@pytest.mark.parametrize("kwargs,match", [({"integration": "rk45"}, "integration must be one of"),
                                          ({"model": "averaged", "integration": "fast"}, "full model only")])
def test_integration_setting_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make("PectoralFish-Full-v0", **kwargs)
