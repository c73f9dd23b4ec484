"""The one-call env step (envs.fused) against the model API and the reward formulas, and its cache key."""

import ast
import importlib
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from pectoral_gym import AveragedModel, FinBeat, FullModel
from pectoral_gym.envs import fused
from pectoral_gym.envs.core import EnvConfig, EnvCore
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model.jit_cache import source_tree
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

REST = FinBeat.rest()


def reference_model(config: EnvConfig, core: EnvCore):
    """A model built through the public API alone, with the episode's parameters, at the core's start state."""
    if config.model == "full":
        model = FullModel(1, core.params[0])
    else:
        model = AveragedModel(1, core.params[0], scaling=config.scaling_functions() or "none",
                              transitions=config.transitions, ripple_offsets=config.ripple_offsets)
    model.reset(core.fish_state(0), right=REST, left=REST)
    return model


def expected_step(config, ref, action, target, d_prev, length, span, k_drag):
    """Command, advance and score one step as the env documents it; returns (obs, reward terms, distance)."""
    x = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    beats = config.decode(x.reshape(2, 4))
    before = ref.integral[0].copy()
    ref.command(right=beats[0], left=beats[1])
    ref.advance(config.control_period)
    dt = config.control_period
    px, py, psi = ref.state[0, :3]
    c, s = math.cos(psi), math.sin(psi)
    dx, dy = target[0] - px, target[1] - py
    d = math.hypot(dx, dy)
    velocity = (ref.integral[0] - before) / dt  # means over the control period
    obs = np.array([px, py, c, s, *velocity, c * dx + s * dy, -s * dx + c * dy, 0.0, 0.0, *x])
    # fin work: k S_p gA^3 (w1^2 + w2^2) / T_p per fin (averaging.mean_fin_power's docstring), times dt
    power = 0.0
    for _, amplitude, period, ratio in beats:
        w1 = math.pi * (ratio + 1.0) / period
        power += k_drag * span * amplitude**3 * (w1**2 + (w1 / ratio) ** 2) / period
    nose_tail = [(px + sign * 0.5 * length * c, py + sign * 0.5 * length * s) for sign in (1.0, -1.0)]
    wall = any(not (0 <= qx <= TANK_LENGTH and 0 <= qy <= TANK_WIDTH) for qx, qy in nose_tail)
    terms = {"reward_progress": config.progress_weight * (d_prev - d),
             "reward_goal": config.goal_bonus if d < config.goal_radius else 0.0,
             "reward_wall": -config.wall_penalty if wall else 0.0,
             "reward_energy": -config.energy_weight * power * dt,
             "reward_time": -config.time_penalty}
    return obs, terms, d


RANDOMIZE = {"fin_span": 0.2, "body_length": 0.2, "drag_coef": 0.2}


@pytest.mark.parametrize(("model", "randomize", "transitions"),
                         [("averaged", None, False), ("full", None, False), ("averaged", RANDOMIZE, False),
                          ("averaged", None, True)])
def test_core_step_is_model_advance_plus_the_reward_formula(model, randomize, transitions):
    config = EnvConfig(model=model, task="goal", randomize=randomize, transitions=transitions)
    core = EnvCore(1, config)
    core.step(np.zeros((1, 8)))  # binds the arrays; the reset below must not replace them
    core.reset(np.array([0]), (np.random.default_rng(4),))
    assert (core.params[0] != config.params) == bool(randomize)
    ref = reference_model(config, core)
    target = core.target(0)
    constants = core.fish_constants(0)
    d_prev = math.hypot(target[0] - core.fish_state(0)[0], target[1] - core.fish_state(0)[1])
    rng = np.random.default_rng(7)
    for step in range(40):
        action = rng.uniform(-1.3, 1.3, 8)  # some entries beyond [-1, 1]: clipped
        core.step(action.reshape(1, 8))
        obs, terms, d = expected_step(config, ref, action, target, d_prev, constants.body_length,
                                      constants.fin_span, constants.fin_drag_constant)
        # the same integrator on the same inputs: the same bits
        np.testing.assert_array_equal(core.model.state, ref.state, err_msg=f"step {step}")
        np.testing.assert_array_equal(core.model.integral, ref.integral)
        assert core.model.time == pytest.approx(ref.time, abs=1e-12)
        # formulas evaluated in another order: float32 obs to its resolution, the terms to float64's
        np.testing.assert_allclose(core.obs[0], obs.astype(np.float32), rtol=1e-6, atol=1e-6)
        info = {name: core.out[0, index] for name, index in core.terms}
        for name, value in terms.items():
            assert info[name] == pytest.approx(value, rel=1e-12, abs=1e-12), (step, name)
        assert core.out[0, tk.O_REWARD] == pytest.approx(sum(terms.values()), rel=1e-12, abs=1e-12)
        assert core.out[0, tk.O_DISTANCE] == pytest.approx(d, rel=1e-12)
        d_prev = d
        if core.out[0, tk.O_TERMINATED] > 0.5:
            break


def _pair(n_small: int, model: str, task: str):
    """A core of ``n_small`` envs (the step's serial build) and a 64-env core (its parallel build), same first envs."""
    config = EnvConfig(model=model, task=task)
    small, big = EnvCore(n_small, config), EnvCore(64, config)
    assert not small._step.parallel and big._step.parallel
    small.reset(np.arange(n_small), [np.random.default_rng(i) for i in range(n_small)])
    big.reset(np.arange(64), [np.random.default_rng(i) for i in range(64)])
    return small, big


@pytest.mark.parametrize(("model", "task"), [("averaged", "track"), ("full", "goal")])
def test_fused_step_matches_the_separate_kernels_with_a_skip_mask(model, task):
    small, big = _pair(3, model, task)
    rng = np.random.default_rng(1)
    skip = np.array([False, True, False])
    for step in range(12):
        actions = rng.uniform(-1, 1, (64, 8)).astype(np.float32)
        mask = skip if step % 3 == 1 else None
        if mask is not None:
            actions[1, 2] = np.nan  # env 1 is skipped: its action is not checked
        small.step(actions[:3], mask)
        big.step(actions, None if mask is None else np.concatenate([mask, np.zeros(61, dtype=bool)]))
        for name in ("obs", "out", "ep", "beats"):
            np.testing.assert_array_equal(getattr(small, name), getattr(big, name)[:3], err_msg=f"{name}, step {step}")
        np.testing.assert_array_equal(small.model.state, big.model.state[:3])


def test_non_finite_action_raises_before_anything_is_written():
    core = EnvCore(3, EnvConfig(model="averaged"))
    core.reset(np.arange(3), [np.random.default_rng(i) for i in range(3)])
    core.step(np.zeros((3, 8)))
    snapshot = [a.copy() for a in (core.obs, core.out, core.ep, core.beats, core.model.state, core.model.fins)]
    time = core.model.time
    actions = np.zeros((3, 8))
    actions[2, 5] = np.inf
    with pytest.raises(ValueError, match=r"action must be finite, got \[0.0, 0.0, 0.0, 0.0, 0.0, inf, 0.0, 0.0\] "
                                         r"for env 2"):
        core.step(actions)
    for before, after in zip(snapshot, (core.obs, core.out, core.ep, core.beats, core.model.state, core.model.fins),
                             strict=True):
        np.testing.assert_array_equal(before, after)
    assert core.model.time == time
    with pytest.raises(ValueError, match=r"actions must have shape \(3, 8\), got \(8,\)"):
        core.step(np.zeros(8))


def test_model_settings_changed_after_the_first_step_are_used():
    """The step reads the model's settings and K tables at every call, as model.advance does."""
    config = EnvConfig(model="averaged")
    core = EnvCore(1, config)
    core.reset(np.array([0]), (np.random.default_rng(2),))
    core.step(np.zeros((1, 8)))  # binds the model's arrays
    core.model.tables = ScalingFunctions.unit().kernel_arrays()  # K = 1
    core.model.transitions = True
    core.model.dt_max = 0.05
    start = core.fish_state(0)
    core.model.reset(start, right=REST, left=REST)
    ref = AveragedModel(1, config.params, scaling="none", transitions=True, ripple_offsets=False, dt_max=0.05)
    ref.reset(start, right=REST, left=REST)
    rng = np.random.default_rng(3)
    for _ in range(10):
        action = rng.uniform(-1, 1, (1, 8))
        core.step(action)
        beats = config.decode(action.reshape(2, 4))
        ref.command(right=beats[0], left=beats[1])
        ref.advance(config.control_period)
        np.testing.assert_array_equal(core.model.state, ref.state)


def _pectoral_imports(module: str) -> set[str]:
    """``pectoral_gym`` modules that ``module`` imports (from its source)."""
    path = Path(importlib.import_module(module).__file__)
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pectoral_gym"):
            package = hasattr(importlib.import_module(node.module), "__path__")
            for alias in node.names:  # "from pectoral_gym import stepping" names a module
                sub = f"{node.module}.{alias.name}"
                found.add(sub if package and importlib.util.find_spec(sub) is not None else node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("pectoral_gym"))
    return found - {"pectoral_gym", "pectoral_gym.envs"}


def test_cache_key_covers_every_module_the_kernel_inlines():
    seen, todo = set(), ["pectoral_gym.model.stepping", "pectoral_gym.envs.tasks.kernels", "pectoral_gym.model.strokes"]
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo.extend(_pectoral_imports(name))
    keyed = set(source_tree(fused.__name__, fused.__file__))  # what the kernel's disk cache is keyed on
    assert seen <= keyed, sorted(seen - keyed)


def test_both_step_builds_can_be_kept_in_the_disk_cache():
    # numba writes no kernel that links a pointer into its own runtime ("dynamic globals": nb.parallel_chunksize
    # inside the body did) to its disk cache: every process would compile the step afresh at its first step.
    small, big = _pair(2, "averaged", "goal")
    actions = np.zeros((64, 8), dtype=np.float32)
    small.step(actions[:2], None)
    big.step(actions, None)
    # the averaged model's step with a mask and its one-argument step (the step and the fin block)
    for build in (fused.STEP[True].serial, fused.STEP[True].parallel, *fused.own_builds(tk.reward_one, True)):
        assert build.overloads, build
        for result in build.overloads.values():
            assert not result.library.has_dynamic_globals, build


def test_the_parallel_step_leaves_the_callers_chunk_size_as_it_found_it():
    import numba as nb

    _, big = _pair(2, "full", "goal")
    previous = nb.set_parallel_chunksize(7)
    try:
        big.step(np.zeros((64, 8), dtype=np.float32), None)
        assert nb.get_parallel_chunksize() == 7
    finally:
        nb.set_parallel_chunksize(previous)


@pytest.mark.parametrize(("model", "task", "observe_fins"), [("averaged", "goal", True), ("full", "track", False)])
def test_one_env_reset_in_one_call_is_the_general_reset(model, task, observe_fins):
    config = EnvConfig(model=model, task=task, observe_fins=observe_fins, stop_band=True,
                       transitions=model == "averaged")
    fast, general = EnvCore(1, config), EnvCore(1, config)
    assert fast._reset_one is not None
    general._reset_one = None  # the batched reset every other core runs
    rngs = {fast: np.random.default_rng(7), general: np.random.default_rng(7)}
    pinned = np.full((1, 8), np.nan)
    pinned[0, :3] = (1.0, 0.5, 0.3)
    actions = np.random.default_rng(2).uniform(-1, 1, (40, 8))
    for episode in range(4):
        for core in (fast, general):  # each episode after steps: a reset rewrites a used state
            core.reset(np.zeros(1, dtype=np.int64), (rngs[core],), pinned if task == "goal" and episode == 2 else None)
        for step in range(1 + 9 * episode):
            if step:
                fast.step(actions[step:step + 1])
                general.step(actions[step:step + 1])
            for name in ("obs", "out", "ep", "beats"):
                np.testing.assert_array_equal(getattr(fast, name), getattr(general, name), err_msg=f"{name}, {episode}")
            for name in ("state", "fins", "pending", "integral", "forcing_cache"):
                np.testing.assert_array_equal(getattr(fast.model, name), getattr(general.model, name), err_msg=name)
            assert fast.model.time == general.model.time
    assert rngs[fast].bit_generator.state == rngs[general].bit_generator.state
    if task == "goal":
        assert fast.fish_state(0)[:3].tolist() != [1.0, 0.5, 0.3]  # the last episode's start was drawn, not pinned
