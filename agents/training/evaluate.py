"""Seeded evaluation of a controller (trained policy or baseline) on a fish environment.

Episode ``k`` of an evaluation with ``seed`` is reset with ``seed + k``, so the
same seed gives the same starts and targets for every controller and every
model (averaged, full). Episodes run batched on the native vector env: a
:class:`~pectoral_gym.agents.training.policy.BatchController` acts on all of them in one call; other
controllers come from a factory, one per env slot.

CLI (``pectoral-evaluate``, also ``python -m pectoral_gym.agents.training.evaluate``)::

    pectoral-evaluate --policy runs/PectoralFish-Averaged-v2/ppo_goal_seed0_...
    pectoral-evaluate --policy RUN --env PectoralFish-Full-v2 --episodes 100 --seed 0 [--randomize]
    pectoral-evaluate --controller hand --env PectoralFish-Full-v2 --task goal

A run folder's environment arguments (``config.yaml``) are reused, ``--env-kwargs`` on top, except
``randomize`` (``--randomize`` sets it) and, on the full model, the averaged model's own settings
``scaling`` and ``check_scaling_params`` (a policy trained on a robot's averaged model with its K is
evaluated on the full model of the same robot, ``params`` kept). ``--quick``: at most 2 episodes.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.training.metrics import METRICS, Trajectory, episode_metrics, summarize
from pectoral_gym.agents.training.policy import BatchController, Controller
from pectoral_gym.agents.training.results import EvaluationResult, format_table, jsonable, plot_trajectories, write_json
from pectoral_gym.envs.layout import ACTION_SIZE
from pectoral_gym.envs.observation import OBS_POSITION, OBS_SIZE, decode
from pectoral_gym.model.jit import PARALLEL_MIN_ITEMS
from pectoral_gym.model.spec import ENV_OPTIONS
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name
from pectoral_gym.versions import LATEST_FULL

__all__ = [
    "DEFAULT_RANDOMIZATION",
    "EvaluationResult",
    "build_parser",
    "evaluate",
    "format_table",
    "main",
    "make_vector_env",
    "plot_trajectories",
    "write_json",
]

# Relative half-widths of the per-episode parameter randomisation used by ``--randomize``.
DEFAULT_RANDOMIZATION = {"body_mass": 0.1, "body_inertia": 0.2, "drag_coef": 0.2, "lift_coef": 0.2,
                         "moment_coef": 0.2, "fin_force_coef": 0.2}
# Vector-env slots of one evaluation: the largest batch the vector env steps without threads. An evaluation is a
# few thousand steps, too short for the threads to pay for their wake-ups, which a busy machine delays most
# (measured: docs/notes/2026-12-07-time-to-policy.md); the results do not depend on the slot count.
MAX_BATCH = PARALLEL_MIN_ITEMS - 1
QUICK_EPISODES = 2  # --quick: episodes of a smoke run
# Settings of one model only (pectoral_gym.model.spec.ENV_OPTIONS, the one table): a policy trained on one
# model keeps its other env arguments on the other.
AVERAGED_ONLY = ENV_OPTIONS["averaged"]
FULL_ONLY = ENV_OPTIONS["full"]
# Settings of how a policy was trained, not of what it is evaluated on: evaluations leave them out (a policy
# trained on the fast full model is evaluated at the reference steps, one trained through the simulated camera
# on the true state, and one trained with the robot's command delays commanding at once, unless the evaluation
# asks otherwise, e.g. --env-kwargs '{"sensing": {}, "timing": {}}').
TRAINING_ONLY = ("randomize", "integration", "sensing", "timing")


def model_kwargs(env_id: str, kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` without the other model's own arguments (:data:`AVERAGED_ONLY`, :data:`FULL_ONLY`)."""
    from pectoral_gym.registration import ENV_IDS

    dropped = ENV_OPTIONS["averaged"] if ENV_IDS.get(env_id) == "full" else ENV_OPTIONS["full"]
    return {k: v for k, v in kwargs.items() if k not in dropped}


def trained_env_kwargs(path: str | Path, env_id: str) -> dict[str, Any]:
    """The env arguments a run folder trained with, for an evaluation on ``env_id``.

    Left out: :data:`TRAINING_ONLY` (the randomisation, the full model's ``integration``, the simulated camera
    ``sensing``, the control loop's ``timing``).
    ``{}`` for a ``.zip`` (no run config next to it).
    """
    from pectoral_gym.agents.training.policy import read_config

    run = read_config(path).get("env_kwargs", {}) if Path(path).is_dir() else {}
    return model_kwargs(env_id, {k: v for k, v in (run or {}).items() if k not in TRAINING_ONLY})

ControllerLike = Controller | Callable[[], Controller]


def make_vector_env(env_id: str, num_envs: int, env_kwargs: dict[str, Any] | None = None):
    """The native :class:`~pectoral_gym.envs.PectoralFishVectorEnv` of a registered fish env id."""
    from pectoral_gym.agents.training.vec_adapter import env_arguments
    from pectoral_gym.envs import PectoralFishVectorEnv
    from pectoral_gym.registration import registered_settings

    return PectoralFishVectorEnv(num_envs=num_envs, **registered_settings(env_id, env_arguments(env_kwargs)))


def _is_factory(controller: Any) -> bool:
    return isinstance(controller, type) or (callable(controller) and not hasattr(controller, "act"))


def evaluate(controller: ControllerLike, env_id: str, n_episodes: int = 100, seed: int = 0,
             env_kwargs: dict[str, Any] | None = None, n_envs: int | None = None, confidence: float = 0.95,
             progress: bool = False) -> EvaluationResult:
    """Run ``n_episodes`` seeded episodes of a controller and compute the metrics.

    Args:
        controller: A :class:`Controller`, a :class:`BatchController` (all slots share it), or a
            zero-argument factory of controllers (one per slot). A plain controller without
            ``act_batch`` runs one episode at a time.
        env_id: A fish env id (:data:`pectoral_gym.registration.ENV_SETTINGS`).
        n_episodes: Number of episodes (>= 1).
        seed: Episode ``k`` is reset with ``seed + k``.
        env_kwargs: Environment arguments (``task``, ``randomize``, reward weights, ...). A policy trained
            with the fin block (an ``obs_size`` of 27, :class:`pectoral_gym.agents.training.policy.SB3Controller`) gets
            ``observe_fins=True`` unless ``env_kwargs`` sets it.
        n_envs: Vector-env slots (default: ``min(n_episodes, MAX_BATCH)``, 63, 1 for a plain controller).
        confidence: Confidence level of the bootstrap intervals.
        progress: Show a tqdm progress bar over episodes.

    Returns:
        The :class:`EvaluationResult`.
    """
    if int(n_episodes) < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    n_episodes = int(n_episodes)
    env_kwargs = dict(env_kwargs or {})
    batch = isinstance(controller, BatchController) and not _is_factory(controller)
    if _is_factory(controller):
        default_envs = min(n_episodes, MAX_BATCH)
    elif batch:
        default_envs = min(n_episodes, MAX_BATCH)
    elif isinstance(controller, Controller):
        default_envs = 1
    else:
        raise TypeError(f"expected a Controller or a factory of controllers, got {type(controller).__name__}")
    n_envs = min(int(n_envs or default_envs), n_episodes)
    if not batch and not _is_factory(controller) and n_envs != 1:
        raise ValueError("a single controller with per-episode state runs one env; pass a factory for more")
    if getattr(controller, "obs_size", OBS_SIZE) > OBS_SIZE:  # the policy observes the fins: so must its env
        env_kwargs.setdefault("observe_fins", True)
    env = make_vector_env(env_id, n_envs, env_kwargs)
    config = env.config
    slots = [controller() for _ in range(n_envs)] if _is_factory(controller) else [controller] * n_envs
    name = str(getattr(slots[0], "name", type(slots[0]).__name__))
    dt = config.control_period
    energy_weight = config.energy_weight
    start = time.perf_counter()

    episode_of = np.full(n_envs, -1)
    swept = np.zeros(n_envs)  # each env's swept fin work at its last step [J]
    records: list[dict[str, list] | None] = [None] * n_envs
    trajectories: list[Trajectory | None] = [None] * n_episodes
    next_episode = 0

    def assign(mask: np.ndarray) -> np.ndarray:
        nonlocal next_episode
        seeds: list[int | None] = [None] * n_envs
        for i in np.flatnonzero(mask):
            if next_episode < n_episodes:
                episode_of[i] = next_episode
                seeds[i] = seed + next_episode
                slots[i].reset(seed + next_episode)
                next_episode += 1
            else:
                episode_of[i] = -1
        started = mask & (episode_of >= 0)
        if started.any():
            obs, _ = env.reset(seed=[s if started[i] else None for i, s in enumerate(seeds)],
                               options={"reset_mask": started})
            swept[started] = _swept(env)[started]
            for i in np.flatnonzero(started):
                records[i] = {"obs": [obs[i].copy()], "reward": [], "work": [], "distance": [_distance(obs[i])],
                              "swept": []}
        return started

    from tqdm.auto import tqdm

    bar = tqdm(total=n_episodes, desc=f"eval {name} on {env_id}", disable=not progress, leave=False)
    assign(np.ones(n_envs, dtype=bool))
    obs = env.last_observations
    actions = np.zeros((n_envs, ACTION_SIZE), dtype=np.float32)
    while (episode_of >= 0).any():
        active = episode_of >= 0
        if batch:
            actions[active] = controller.act_batch(obs[active])
        else:
            for i in np.flatnonzero(active):
                actions[i] = slots[i].act(obs[i])
        actions[~active] = 0.0
        obs, reward, terminated, truncated, info = env.step(actions)
        done = (terminated | truncated) & active
        now = _swept(env)
        for i in np.flatnonzero(active):
            rec = records[i]
            rec["obs"].append(obs[i].copy())
            rec["reward"].append(float(reward[i]))
            rec["distance"].append(float(info["distance"][i]))
            rec["work"].append(_fin_work(info, i, obs[i], config, energy_weight))
            rec["swept"].append(float(now[i] - swept[i]))
        swept = now
        for i in np.flatnonzero(done):
            wall = bool(info["reward_wall"][i] < 0)
            success = bool(info.get("is_success", np.zeros(n_envs, bool))[i])
            trajectories[episode_of[i]] = _trajectory(records[i], dt, success, wall,
                                                      bool(truncated[i] and not terminated[i]),
                                                      seed + int(episode_of[i]))
            bar.update(1)
        if done.any():
            assign(done)
            obs = env.last_observations
    bar.close()
    env.close()
    task = config.task
    episodes = [episode_metrics(t, task) for t in trajectories]
    metrics = {m: summarize([e[m] for e in episodes], confidence=confidence, seed=seed) for m in METRICS[task]}
    return EvaluationResult(name, env_id, task, int(seed), jsonable(env_kwargs), metrics, episodes,
                            trajectories, time.perf_counter() - start)


def _distance(obs: np.ndarray) -> float:
    o = decode(obs)
    return float(math.hypot(o.target_x, o.target_y))


def _swept(env) -> np.ndarray:
    """Each env's fin work since its reset over the strokes actually swept [J] (``FishModel.fin_work``)."""
    return env.core.model.fin_work().sum(axis=1)


def _fin_work(info: dict, i: int, obs: np.ndarray, config, energy_weight: float) -> float:
    """Fin work of one step [J]: from the energy term, or from the applied action if the term is switched off."""
    if energy_weight > 0:
        return float(-info["reward_energy"][i] / energy_weight)
    from pectoral_gym.model.averaging import mean_fin_power

    params = config.params
    work = 0.0
    for beat in config.decode(np.asarray(decode(obs).last_action, dtype=float).reshape(2, 4)):
        work += mean_fin_power(beat[1], beat[2], beat[3], params.fin_span, params.fin_drag_constant)
    return work * config.control_period


def _trajectory(rec: dict[str, list], dt: float, success: bool, wall: bool, truncated: bool, seed: int) -> Trajectory:
    obs = np.asarray(rec["obs"], dtype=float)
    o = decode(obs)
    target = np.column_stack(o.target_in_tank())
    return Trajectory(xy=obs[:, OBS_POSITION].copy(), psi=o.psi, target=target,
                      distance=np.asarray(rec["distance"]), reward=np.asarray(rec["reward"]),
                      fin_work=np.asarray(rec["work"]), control_period=dt, success=success, wall=wall,
                      truncated=truncated, seed=seed, swept_work=np.asarray(rec["swept"]))


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-evaluate``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-evaluate", "pectoral_gym.agents.training.evaluate"),
        description=__doc__.split("\n\n")[0] + " Episode k is reset with --seed + k: the same starts and "
        "targets for every controller. Writes metrics.json and trajectories.png into --out.",
        formatter_class=HelpFormatter,
        epilog=examples(f"pectoral-evaluate --policy demo_out/run --env {LATEST_FULL} --episodes 100 --seed 0",
                        f"pectoral-evaluate --policy demo_out/run --env {LATEST_FULL} --randomize",
                        f"pectoral-evaluate --controller hand --env {LATEST_FULL} --task goal --episodes 100",
                        "pectoral-evaluate --controller nmpc --quick"))
    who = parser.add_mutually_exclusive_group(required=True)
    who.add_argument("--policy", metavar="RUN|ZIP",
                     help="run folder of pectoral-train or an SB3 .zip")
    who.add_argument("--controller", metavar="NAME",
                     help="baseline controller: random, hand, nmpc or excite (identification runs)")
    parser.add_argument("--env", default=LATEST_FULL, help="environment id")
    parser.add_argument("--task", choices=("goal", "track"), help="task (default: the run's task, else goal)")
    parser.add_argument("--randomize", nargs="?", const="default", metavar="JSON",
                        help="per-episode parameter randomisation: alone for the default preset "
                             f"{DEFAULT_RANDOMIZATION}, or a JSON dict {{field: relative half-width}}")
    parser.add_argument("--env-kwargs", default="{}", metavar="JSON", help="more environment arguments")
    parser.add_argument("--scaling", metavar="JSON",
                        help="--controller hand|nmpc: the K file they plan with, identified for the env's params "
                             "(pectoral-scaling identify --params robot.json writes it; default: the env's K, on the "
                             "full model the shipped K, identified for Table 1's fish)")
    parser.add_argument("--episodes", type=int, default=100, help="number of episodes")
    parser.add_argument("--seed", type=int, default=0, help="episode k is reset with seed + k")
    parser.add_argument("--n-envs", type=int, help="vector-env slots (default: up to 63, the most the vector env steps "
                        "without threads)")
    parser.add_argument("--algo", help="algorithm of a bare .zip if it cannot be read from it")
    parser.add_argument("--out", metavar="DIR", help="output folder (default: runs/eval/<controller>_<env>_<task>...)")
    parser.add_argument("--plot-episodes", type=int, default=12, help="episodes drawn in the trajectory plot")
    parser.add_argument("--quick", action="store_true",
                        help=f"smoke run in seconds: at most {QUICK_EPISODES} episodes whatever --episodes says")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from pectoral_gym.agents.baselines import scaling_flag_problem

    if (problem := scaling_flag_problem(args.controller if not args.policy else "policy", args.scaling)) is not None:
        parser.error(problem)
    if args.quick:
        args.episodes = min(args.episodes, QUICK_EPISODES)
    try:
        env_kwargs = json.loads(args.env_kwargs)
        if not isinstance(env_kwargs, dict):
            raise ValueError("--env-kwargs must be a JSON object")
        if args.policy:
            from pectoral_gym.agents.training.policy import load_policy

            env_kwargs = {**trained_env_kwargs(args.policy, args.env), **env_kwargs}
            controller: ControllerLike = load_policy(args.policy, algo=args.algo)
            name = Path(args.policy).name.removesuffix(".zip")
        else:
            from pectoral_gym.agents.baselines import make_baseline
            from pectoral_gym.envs.core import EnvConfig
            from pectoral_gym.registration import registered_settings

            baseline_kwargs = {**env_kwargs, **({"task": args.task} if args.task else {})}
            from pectoral_gym.agents.training.vec_adapter import env_arguments

            config = EnvConfig(**registered_settings(args.env, env_arguments(baseline_kwargs)))
            planning = {} if args.scaling is None else {"scaling": args.scaling}
            make_baseline(args.controller, config, **planning)  # a wrong K file fails here, before the episodes
            controller = lambda: make_baseline(args.controller, config, **planning)  # noqa: E731 - one per slot
            name = args.controller
        if args.task:
            env_kwargs["task"] = args.task
        if args.randomize:
            env_kwargs["randomize"] = DEFAULT_RANDOMIZATION if args.randomize == "default" else json.loads(
                args.randomize)
        result = evaluate(controller, args.env, n_episodes=args.episodes, seed=args.seed, env_kwargs=env_kwargs,
                          n_envs=args.n_envs, progress=not args.no_progress)
    except (ValueError, TypeError, FileNotFoundError, json.JSONDecodeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    tag = f"{name}_{args.env}_{result.task}" + ("_rand" if env_kwargs.get("randomize") else "") + f"_seed{args.seed}"
    out = Path(args.out) if args.out else Path("runs") / "eval" / tag
    json_path = write_json(result, out / "metrics.json")
    plot_path = plot_trajectories(result, out / "trajectories.png", max_episodes=args.plot_episodes)
    print(format_table([result]))
    print(f"wrote {json_path} and {plot_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
