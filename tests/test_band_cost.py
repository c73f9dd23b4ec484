"""The graded band cost (pectoral_gym.envs.cost): by hand at placed states, against the stop rule's numpy
functions, consistent with the env's own episode end, and through the wrappers (Safety-Gymnasium's step, a vector
env)."""

import math

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.envs.cost import BAND_COST_WIDTH, BandCost, SafetyStep, band_cost, env_band_shortfall
from pectoral_gym.model.tank import TANK_LENGTH, TANK_WIDTH, Outline, clearance, coast_rate, stop_need
from pectoral_gym.versions import LATEST_AVERAGED, LATEST_FULL, SIMULATION_IDS


def test_band_cost_by_hand():
    assert band_cost(-0.05, 0.1) == pytest.approx(0.5)
    assert band_cost(-0.02, 0.1) == pytest.approx(0.8)
    assert band_cost(-0.25) == 0.0 and band_cost(0.03) == 1.0 and band_cost(0.0) == 1.0
    np.testing.assert_allclose(band_cost(np.array([-0.2, -0.1, -0.075, 0.5]), 0.1), [0.0, 0.0, 0.25, 1.0])
    for width in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="width must be > 0"):
            band_cost(0.0, width)


def _placed(env, gap, speed):
    """Put the fish heading +X at ``speed`` [m/s], its outline ``gap`` [m] from the wall X = L, mid-tank in Y."""
    params = env.unwrapped.fish_params
    outline = Outline.from_params(params)
    ahead = max(outline.half_length + outline.width, outline.span)  # the outline's reach along +X (psi = 0)
    env.unwrapped.set_fish_state([TANK_LENGTH - gap - ahead, 0.5 * TANK_WIDTH, 0.0, speed, 0.0, 0.0])
    return params


@pytest.mark.parametrize("env_id", [LATEST_AVERAGED, LATEST_FULL])
def test_placed_states_cost_by_hand(env_id):
    env = BandCost(gym.make(env_id))
    env.reset(seed=0)
    rule = env.unwrapped.config.stop_rule
    margin, reaction, contact = rule.margin, rule.reaction_time, rule.contact_speed
    # at rest the need is the margin alone
    _placed(env, margin + 0.05, 0.0)
    assert band_cost(env_band_shortfall(env)) == pytest.approx(0.5)
    _placed(env, margin + 0.2, 0.0)
    assert band_cost(env_band_shortfall(env)) == 0.0
    # at 0.1 m/s towards the wall: margin + v t_r + ln(v / v_c) / k, k = c1 / max(m1, m2)
    params = _placed(env, 0.0, 0.1)
    need = margin + 0.1 * reaction + math.log(0.1 / contact) / (params.c1 / max(params.m1, params.m2))
    for extra, expected in ((0.08, 0.2), (0.02, 0.8), (-0.01, 1.0), (0.15, 0.0)):
        _placed(env, need + extra, 0.1)
        assert env_band_shortfall(env) == pytest.approx(-extra, abs=1e-12)
        assert band_cost(env_band_shortfall(env)) == pytest.approx(expected)


def test_shortfall_agrees_with_the_rules_numpy_functions():
    # the compiled band_shortfall on the env's state against tank.stop_need and tank.clearance (numpy), per wall
    env = gym.make(LATEST_AVERAGED)
    rng = np.random.default_rng(3)
    rule = env.unwrapped.config.stop_rule
    for episode in range(4):
        env.reset(seed=episode)
        for _ in range(15):
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 8))
            x, y, psi, u, v, _ = env.unwrapped.fish_state
            vx, vy = math.cos(psi) * u - math.sin(psi) * v, math.sin(psi) * u + math.cos(psi) * v
            params = env.unwrapped.fish_params
            needs = stop_need(np.array([-vx, vx, -vy, vy]), coast_rate(params), rule)
            expected = float(np.max(needs - clearance(x, y, psi, Outline.from_params(params))))
            assert env_band_shortfall(env) == pytest.approx(expected, abs=1e-12)
            if terminated or truncated:
                break


def _random_steps(env, episodes, seed=0):
    rng = np.random.default_rng(seed)
    for episode in range(episodes):
        _, info = env.reset(seed=episode)
        yield None, info
        action, done = rng.uniform(-1, 1, 8), False
        while not done:
            if rng.random() < 0.2:  # hold an action for a few steps: the fish gets going and meets the band
                action = rng.uniform(-1, 1, 8)
            step = env.step(action)
            done = step[2] or step[3]
            yield step, step[4]


def test_band_cost_agrees_with_the_episode_end():
    env = BandCost(gym.make(LATEST_AVERAGED))
    graded = ended_in_band = 0
    for step, info in _random_steps(env, 12):
        assert 0.0 <= info["band_cost"] <= 1.0 and isinstance(info["band_cost"], np.float64)
        if step is None:
            continue
        if info["cost"] == 1.0:  # the env ended the episode in the band: the hard limit, cost 1 on both
            ended_in_band += 1
            assert step[2] and info["band_cost"] == 1.0
        else:
            assert info["band_cost"] < 1.0
            graded += 0.0 < info["band_cost"]
    assert ended_in_band >= 3 and graded >= 10  # random swimming meets the band; the cost rises before it


def test_safety_step_returns_the_cost_as_its_third_value():
    env = SafetyStep(gym.make(LATEST_AVERAGED))
    obs, info = env.reset(seed=1)
    assert "band_cost" in info
    for _ in range(5):
        step = env.step(env.action_space.sample())
        assert len(step) == 6
        _, reward, cost, terminated, truncated, info = step
        assert isinstance(cost, float) and cost == info["band_cost"] and isinstance(reward, float)
    assert isinstance(SafetyStep(BandCost(gym.make(LATEST_AVERAGED), width=0.2)).env, BandCost)
    assert SafetyStep(BandCost(gym.make(LATEST_AVERAGED), width=0.2)).env.width == 0.2  # not wrapped twice


def test_the_graded_cost_can_take_the_cost_key():
    # for a library that reads info["cost"] only: the graded cost there, 1 at the band's episode end as before
    env = BandCost(gym.make(LATEST_AVERAGED), key="cost")
    safety = SafetyStep(env)
    seen_graded = ended = 0
    for step, info in _random_steps(safety_as_gym(safety), 6):
        assert "band_cost" not in info and 0.0 <= info["cost"] <= 1.0
        if step is not None:
            seen_graded += 0.0 < info["cost"] < 1.0
            ended += bool(step[2]) and info["cost"] == 1.0
    assert seen_graded >= 5 and ended >= 1
    with pytest.raises(ValueError, match="key must be"):
        BandCost(gym.make(LATEST_AVERAGED), key="costs")


def safety_as_gym(safety):
    """A SafetyStep seen through Gymnasium's 5-tuple again (its cost is also in info)."""

    class Five:
        def reset(self, **kwargs):
            return safety.reset(**kwargs)

        def step(self, action):
            obs, reward, cost, terminated, truncated, info = safety.step(action)
            assert cost == info["cost"]
            return obs, reward, terminated, truncated, info

    return Five()


def test_band_cost_refuses_an_env_without_the_band():
    with pytest.raises(ValueError, match="stop_band=True"):
        BandCost(gym.make(SIMULATION_IDS["averaged"]))
    with pytest.raises(ValueError, match="width must be > 0"):
        BandCost(gym.make(LATEST_AVERAGED), width=0.0)
    assert BAND_COST_WIDTH == 0.10


def test_band_cost_in_a_sync_vector_env_reaches_final_info():
    venv = gym.make_vec(LATEST_AVERAGED, 2, vectorization_mode="sync", wrappers=[BandCost],
                        vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP})
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    action = rng.uniform(-1, 1, (2, 8))
    for _ in range(200):
        if rng.random() < 0.2:
            action = rng.uniform(-1, 1, (2, 8))
        _, _, terminated, _, info = venv.step(action)
        assert info["band_cost"].shape == (2,)
        final = info.get("final_info", {})
        if "cost" in final and (final["cost"] == 1.0).any():
            ended = final["cost"] == 1.0
            np.testing.assert_array_equal(final["band_cost"][ended], 1.0)
            break
    else:
        pytest.fail("no episode ended in the band in 200 steps")
    venv.close()
