import math

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401  (registers the env ids)
from pectoral_gym.agents.baselines import FinMap, HandController, RandomController, make_baseline
from pectoral_gym.agents.nmpc.problem import to_z
from pectoral_gym.agents.training.policy import Controller
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.models import FullModel

CONFIG = EnvConfig(model="averaged", task="goal")


def _decode(config: EnvConfig, action: np.ndarray) -> np.ndarray:
    """Fin patterns (2, 4) of a normalised action: the env's linear map, written out independently."""
    r = config.ranges
    x = np.clip(np.asarray(action, dtype=float).reshape(2, 4), -1, 1)
    return r[:, 0] + 0.5 * (x + 1.0) * (r[:, 1] - r[:, 0])


def _obs_with_target(x_body: float, y_body: float) -> np.ndarray:
    """A fish at rest in mid-tank heading along X, the target at (x_body, y_body) in its body frame."""
    obs = np.zeros(19, dtype=np.float32)
    obs[0], obs[1], obs[2], obs[3] = 1.15, 0.575, 1.0, 0.0
    obs[7], obs[8] = x_body, y_body
    return obs


def test_make_baseline_builds_controllers_and_rejects_bad_input():
    for name in ("random", "hand"):
        controller = make_baseline(name, CONFIG)
        assert isinstance(controller, Controller)
        assert controller.name == name
    with pytest.raises(ValueError, match="unknown baseline"):
        make_baseline("pid", CONFIG)
    with pytest.raises(ValueError, match="EnvConfig"):
        make_baseline("hand", {"task": "goal"})


def test_random_is_seeded_and_in_bounds():
    a = RandomController(seed=3)
    b = RandomController(seed=3)
    first = np.array([a.act(np.zeros(19)) for _ in range(50)])
    second = np.array([b.act(np.zeros(19)) for _ in range(50)])
    np.testing.assert_array_equal(first, second)
    assert first.dtype == np.float32 and first.shape == (50, 8)
    assert np.all(first >= -1.0) and np.all(first <= 1.0)
    assert first.std() > 0.4  # uniform on [-1, 1] has std 0.577
    a.reset(seed=3)
    np.testing.assert_array_equal(a.act(np.zeros(19)), first[0])
    c = RandomController(seed=4)
    assert not np.array_equal(c.act(np.zeros(19)), first[0])


def test_fin_map_fixes_the_most_effective_period_and_ratio():
    fins = FinMap(CONFIG)
    action = fins.action(math.pi / 2, CONFIG.amplitude_range[1], math.pi / 2, 0.0)
    # bias 90 deg is the middle of (45, 135) deg -> 0; largest amplitude -> 1; zero amplitude -> -1;
    # shortest period -> -1; largest ratio -> 1
    np.testing.assert_allclose(action, [0, 1, -1, 1, 0, -1, -1, 1], atol=1e-6)
    assert fins.amplitude(0.0) == pytest.approx(CONFIG.amplitude_range[0])
    assert fins.amplitude(1.0) == pytest.approx(CONFIG.amplitude_range[1])
    # thrust ~ gA J1(gA) ~ gA^2 / 2 for small gA: a quarter of the thrust needs about half the amplitude
    assert fins.amplitude(0.25) / fins.amplitude(1.0) == pytest.approx(0.5, rel=0.05)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_hand_controller_turns_towards_the_target_by_physics(side):
    """Target to the left (side +1) or right: the commanded fins must turn the fish that way.

    Physics: the right fin alone pushes the right side forward and turns the fish left, so a
    target on the left needs the right fin stronger. Checked on the full model, independently of
    the controller: the commanded patterns, held 4 s from rest, turn the heading to the target's side.
    """
    hand = HandController(CONFIG)
    action = hand.act(_obs_with_target(0.2, side * 0.4))
    beats = _decode(CONFIG, action)
    right_amp, left_amp = beats[0, 1], beats[1, 1]
    assert (right_amp - left_amp) * side > 0
    model = FullModel(1)
    model.reset(np.array([1.15, 0.575, 0.0, 0.0, 0.0, 0.0]))
    model.command(right=beats[0], left=beats[1])
    model.advance(4.0)
    assert model.state[0, 2] * side > math.radians(10)


def test_hand_controller_swims_straight_at_a_target_ahead():
    action = HandController(CONFIG).act(_obs_with_target(0.6, 0.0))
    beats = _decode(CONFIG, action)
    assert beats[0, 1] == pytest.approx(beats[1, 1])  # equal amplitudes
    assert beats[0, 1] > math.radians(10)  # and a real stroke


def test_hand_controller_never_stalls_on_a_target_inside_its_turning_circle():
    """A target beside the fish closer than its turning diameter cannot be reached by turning; the old law then
    commanded no turn and (facing away) no speed, and the fish stayed put for the whole episode. It must swim."""
    hand = HandController(CONFIG)
    beats = _decode(CONFIG, hand.act(_obs_with_target(-0.05, 0.3)))  # 0.3 m to the left, slightly behind
    assert beats[0, 1] > 0 and beats[1, 1] > 0  # both fins beat: the fish swims on
    model = FullModel(1)
    model.reset(np.array([1.15, 0.575, 0.0, 0.0, 0.0, 0.0]))
    model.command(right=beats[0], left=beats[1])
    model.advance(10.0)
    assert model.state[0, 0] - 1.15 > 0.05  # and it moves (forward)


def _obs_at(x, y, psi, x_body, y_body):
    obs = _obs_with_target(x_body, y_body)
    obs[0], obs[1], obs[2], obs[3] = x, y, math.cos(psi), math.sin(psi)
    return obs


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_hand_controller_turns_away_from_a_wall_when_the_target_is_behind(side):
    """Near the top wall (Y = 1.15 m) heading along X, a target behind: the short way round (towards the wall
    side) would run into the wall, so the fish turns the other way; in mid-tank it turns towards the target."""
    from pectoral_gym.model.params import TANK_WIDTH

    hand = HandController(CONFIG)
    target = (-0.4, side * 0.05)  # behind, slightly to the left (side +1) or right
    wall_side = 1.0  # the wall is on the fish's left (heading +X near Y = TANK_WIDTH)
    near = _decode(CONFIG, hand.act(_obs_at(1.15, TANK_WIDTH - 0.2, 0.0, *target)))
    hand.reset()
    free = _decode(CONFIG, hand.act(_obs_at(1.15, 0.575, 0.0, *target)))
    turns_left = lambda beats: beats[0, 1] > beats[1, 1]  # noqa: E731 - right fin stronger turns left
    assert turns_left(free) == (side > 0)  # mid-tank: towards the target
    assert turns_left(near) == (wall_side < 0)  # by the wall: away from it, whatever side the target is on


def test_hand_controller_rejects_bad_observations():
    with pytest.raises(ValueError, match="shape"):
        HandController(CONFIG).act(np.zeros(5))


# ---------------------------------------------------------------------- NMPC
@pytest.fixture(scope="module")
def nmpc():
    # no wall-clock budget: a loaded test machine must not turn slow solves into fallbacks (the
    # budget's fallback has its own test below); solve times are measured by the benchmark
    return make_baseline("nmpc", CONFIG, step_budget=1e6, max_cpu_time=1e6)


def _episode_with_goal_ahead(env, distance: float = 0.35, bearing: float = 0.2):
    """The first seeded episode whose goal lies within ``distance`` m, at most ``bearing`` rad off the heading."""
    for seed in range(5000):
        obs, _ = env.reset(seed=seed)
        if math.hypot(obs[7], obs[8]) < distance and abs(math.atan2(obs[8], obs[7])) < bearing:
            return obs
    raise AssertionError("no such episode")  # pragma: no cover


def test_nmpc_reaches_a_near_goal_on_the_averaged_env(nmpc):
    env = gym.make("PectoralFish-Averaged-v0")
    obs = _episode_with_goal_ahead(env)
    nmpc.reset()
    # 0.35 m at the fish's top speed (~0.2 m/s) takes a few seconds; 30 steps = 15 s is generous
    for _ in range(30):
        action = nmpc.act(obs)
        assert action.shape == (8,) and action.dtype == np.float32
        assert np.all(np.abs(action) <= 1.0)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert info["is_success"]
    assert len(nmpc.solve_times) > 0
    assert nmpc.failures <= len(nmpc.solve_times) // 10  # nearly every step comes from a fresh solve


def test_nmpc_falls_back_to_the_last_plan_then_to_rest_when_the_solver_fails(nmpc, monkeypatch):
    env = gym.make("PectoralFish-Averaged-v0")
    obs = _episode_with_goal_ahead(env)
    nmpc.reset()
    nmpc.act(obs)
    plan = nmpc.plan.copy()
    failures = nmpc.failures

    def broken(*args, **kwargs):
        raise RuntimeError("solver crashed")

    monkeypatch.setattr(nmpc, "_solver", broken)
    obs, *_ = env.step(nmpc.fins.action(plan[0, 2], plan[0, 0], plan[0, 3], plan[0, 1]))
    action = nmpc.act(obs)
    np.testing.assert_allclose(action, nmpc.fins.action(plan[1, 2], plan[1, 0], plan[1, 3], plan[1, 1]))
    assert nmpc.failures == failures + 1
    for _ in range(plan.shape[0]):  # use up the plan: then both fins rest (zero amplitude)
        action = nmpc.act(obs)
    beats = _decode(CONFIG, action)
    np.testing.assert_allclose(beats[:, 1], CONFIG.amplitude_range[0])
    # a broken observation never reaches the solver and gives a safe action too
    action = nmpc.act(np.full(19, np.nan, dtype=np.float32))
    assert np.all(np.isfinite(action)) and np.all(np.abs(action) <= 1.0)


def test_nmpc_rejects_bad_settings():
    with pytest.raises(ValueError, match="velocity"):
        make_baseline("nmpc", CONFIG, velocity="guess")
    with pytest.raises(ValueError, match="horizon"):
        make_baseline("nmpc", CONFIG, horizon=0)
    with pytest.raises(ValueError, match="blocks"):
        make_baseline("nmpc", CONFIG, horizon=10, blocks=(1, 2, 3))
    with pytest.raises(ValueError, match="solver"):
        make_baseline("nmpc", CONFIG, solver="simplex")
    with pytest.raises(ValueError, match="step_budget"):
        make_baseline("nmpc", CONFIG, step_budget=0.0)
    for bad in ({"togo_steps": -1}, {"deep_candidates": 0}, {"togo_wall_margin": -0.1}):
        with pytest.raises(ValueError, match="togo_steps"):
            make_baseline("nmpc", CONFIG, **bad)


def test_nmpc_plan_holds_each_block_and_obeys_the_model(monkeypatch):
    """A converged solve's plan is constant within each move block, and its states are the model's rollout of it."""
    # to convergence; the biases free (bias_span=None): with them fixed by equal bounds (the goal default)
    # IPOPT stops at 300 iterations without converging here (the SQP default is not affected;
    # docs/notes/2026-12-01-nmpc-rounds.md)
    nmpc = make_baseline("nmpc", CONFIG, solver="ipopt", max_iter=300, max_cpu_time=30.0, bias_span=None)
    env = gym.make("PectoralFish-Averaged-v0")
    obs = _episode_with_goal_ahead(env)
    nmpc.reset()
    recorded, solver = [], nmpc._solver

    def recording(**kwargs):
        recorded.append(solver(**kwargs))
        return recorded[-1]

    recording.stats = solver.stats
    monkeypatch.setattr(nmpc, "_solver", recording)
    state, ref, vref = nmpc._estimate(np.asarray(obs, dtype=np.float64))
    p = nmpc.problem.parameters(state, ref, vref, to_z(nmpc._u_prev), nmpc.gains)
    result = nmpc._solve(state, p, nmpc._fresh_guesses()[0])
    assert result is not None
    problem = nmpc.problem
    plan = result[1]
    assert plan.shape == (problem.horizon, 4) and problem.n_blocks < problem.horizon
    for b in range(problem.n_blocks):
        rows = plan[problem.block_of == b]
        np.testing.assert_allclose(rows, np.repeat(rows[:1], len(rows), 0))
    cost, plan, duals = result
    guess_cost, _ = nmpc._rollout_cost(state, p, nmpc._fresh_guesses()[0])
    assert cost <= guess_cost  # the solve improved on (or kept) the guess it started from
    assert duals is not None and nmpc._solver.stats()["success"]  # converged: its states must obey the model
    x_plan = np.asarray(recorded[-1]["x"]).ravel()[4 * problem.n_blocks:].reshape((6, problem.horizon + 1), order="F")
    x_roll = np.asarray(problem.rollout(state, to_z(plan.T), to_z(nmpc._u_prev), nmpc.gains))
    np.testing.assert_allclose(x_plan, x_roll, atol=1e-4)  # multiple-shooting gaps closed
    assert np.hypot(*(x_roll[:2, -1] - state[:2])) > 0.05  # the plan swims towards the goal ahead


def test_nmpc_uses_the_fallback_when_the_step_runs_late():
    """A step whose solves end after the step budget is not applied: the safe fallback is."""
    late = make_baseline("nmpc", CONFIG, step_budget=1e-9)  # every solve takes longer than 1 ns
    env = gym.make("PectoralFish-Averaged-v0")
    obs = _episode_with_goal_ahead(env)
    late.reset()
    action = late.act(obs)
    assert late.late == 1 and late.failures == 1 and late.plan is None
    beats = _decode(CONFIG, action)
    np.testing.assert_allclose(beats[:, 1], CONFIG.amplitude_range[0])  # no plan yet: both fins at rest


@pytest.mark.slow  # IPOPT solves to convergence: ~0.3 s per step
def test_nmpc_with_ipopt_reaches_a_near_goal_on_the_averaged_env():
    controller = make_baseline("nmpc", CONFIG, solver="ipopt", max_iter=60, blocks=None, step_budget=5.0)
    env = gym.make("PectoralFish-Averaged-v0")
    obs = _episode_with_goal_ahead(env)
    controller.reset()
    for _ in range(30):
        obs, _, terminated, truncated, info = env.step(controller.act(obs))
        if terminated or truncated:
            break
    assert info["is_success"]


def test_nmpc_compare_runs_variants_on_the_same_episodes():
    from pectoral_gym.agents.nmpc.compare import compare
    results = compare({"short": {"horizon": 2, "blocks": None}, "blocked": {"horizon": 3, "blocks": (1, 2)}},
                      [0], env="averaged", max_steps=2)
    assert set(results) == {"short", "blocked"}
    for r in results.values():
        assert r["episodes"] == 1 and 0.0 <= r["success"] <= 1.0 and r["p50_ms"] <= r["p95_ms"] <= r["max_ms"]
        assert 0.0 < r["mean_distance_cm"] < 300.0  # a distance inside the 2.3 m tank
        assert r["failed"] == [] if r["success"] == 1.0 else r["failed"] == [(0, 2, "time-out")]  # 2 steps: 1 s
    with pytest.raises(ValueError, match="env"):
        compare({"a": {}}, [0], env="moon")


def test_nmpc_with_transitions_adds_the_expected_impulse_of_a_change_only():
    """NMPCSettings(transitions=True): a rollout whose input changes from the latched command differs from the
    cycle-average model by the expected transitional impulse (docs/model.md 3.7); an unchanged input does not."""
    plain = make_baseline("nmpc", CONFIG, step_budget=1e6)
    with_t = make_baseline("nmpc", CONFIG, step_budget=1e6, transitions=True)
    state = np.zeros(6)
    u_prev = np.array([math.radians(10), math.radians(10), math.radians(80), math.radians(80)])
    u_new = np.array([math.radians(25), math.radians(25), math.radians(100), math.radians(100)])
    gains = np.ones(2)
    n = plain.problem.horizon
    for u, changed in ((u_prev, False), (u_new, True)):
        z = np.tile(to_z(u)[:, None], (1, n))
        a = np.asarray(plain.problem.rollout(state, z, to_z(u_prev), gains))
        b = np.asarray(with_t.problem.rollout(state, z, to_z(u_prev), gains))
        if changed:
            assert abs(b[0, -1] - a[0, -1]) > 1e-4  # the switch's impulse moves the fish
            np.testing.assert_allclose(b[1:3], a[1:3], atol=1e-9)  # symmetric fins: no sway, no yaw from it
        else:
            np.testing.assert_array_equal(b, a)
    env = gym.make("PectoralFish-Averaged-v0")
    obs = _episode_with_goal_ahead(env)
    with_t.reset()
    action = with_t.act(obs)
    assert action.shape == (8,) and np.all(np.isfinite(action)) and np.all(np.abs(action) <= 1.0)
