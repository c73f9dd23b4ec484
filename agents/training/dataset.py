r"""Record a controller's seeded episodes as a Minari dataset, with the dataset's metadata.

The controller is a trained policy (``--policy``: a ``pectoral-train`` run folder, a zoo run folder or an SB3
``.zip``, as ``pectoral-evaluate`` takes it, with the env arguments the run trained with) or a baseline
(``--controller random|hand|nmpc|excite``). Episode ``k`` is reset with ``--seed + k``, as in ``pectoral-evaluate``:
the same starts and goals for every controller. Minari's ``DataCollector`` records observations, actions, rewards,
flags and infos (the reset's too), and the env's spec, arguments included, so ``dataset.recover_environment()``
makes the env back. The metadata: the controller's name as ``algorithm_name``, a description (env id and
arguments, seeds, controller, success rate and mean return of the recorded episodes), ``eval_env`` (the env's spec),
``requirements`` (this package at its version) and, when given, the author and their contact::

    python -m pectoral_gym.agents.training.dataset --policy runs/PectoralFish-Averaged-v2/ppo_seed0 \
        --env PectoralFish-Full-v2 --episodes 100 --dataset-id pectoral/full-ppo-v0
    python -m pectoral_gym.agents.training.dataset --controller hand --dataset-id pectoral/full-hand-v0

Datasets go to ``~/.minari/datasets`` unless ``--datasets-path`` (or ``MINARI_DATASETS_PATH``) says otherwise.
Needs Minari with its writers (``minari[create,hdf5]``, the ``clients`` extra).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.versions import LATEST_FULL

__all__ = ["Recorded", "build_parser", "main", "record_dataset"]


@dataclass(frozen=True)
class Recorded:
    """What :func:`record_dataset` wrote.

    Attributes:
        dataset_id: The Minari dataset id.
        path: The dataset's folder.
        episodes: Episodes recorded.
        steps: Steps recorded.
        success: Fraction of episodes that reached the goal (``info["is_success"]`` on the last step).
        mean_return: Mean undiscounted return.
    """

    dataset_id: str
    path: Path
    episodes: int
    steps: int
    success: float
    mean_return: float


def _package_requirement() -> list[str]:
    try:
        return [f"pectoral-gym=={version('pectoral-gym')}"]
    except PackageNotFoundError:  # a source tree without an install
        return []


def record_dataset(controller: Any, name: str, env_id: str, dataset_id: str, episodes: int = 100, seed: int = 0,
                   env_kwargs: dict[str, Any] | None = None, description: str | None = None,
                   author: str | None = None, author_email: str | None = None) -> Recorded:
    """Run ``episodes`` seeded episodes of ``controller`` on ``gym.make(env_id, **env_kwargs)`` into a dataset.

    Args:
        controller: A :class:`~pectoral_gym.agents.training.policy.Controller` (``reset(seed)``, ``act(obs)``).
        name: Its name, the dataset's ``algorithm_name``.
        env_id: A registered id.
        dataset_id: Minari's id, ``namespace/name-v<N>`` (no dataset of that id may exist).
        episodes: Number of episodes (>= 1); episode ``k`` is reset with ``seed + k``.
        env_kwargs: More env arguments.
        description: Text put before the generated description.
        author, author_email: The dataset's author and their contact (Minari's metadata).

    Raises:
        ValueError: If ``episodes`` < 1, or Minari refuses the id (it exists, or is malformed).
    """
    import gymnasium as gym
    import minari

    import pectoral_gym  # noqa: F401  (registers the ids)

    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    env_kwargs = dict(env_kwargs or {})
    env = minari.DataCollector(gym.make(env_id, **env_kwargs), record_infos=True)
    returns, successes, steps = [], 0, 0
    for k in range(episodes):
        controller.reset(seed + k)
        obs, _ = env.reset(seed=seed + k)
        total, done, info = 0.0, False, {}
        while not done:
            obs, reward, terminated, truncated, info = env.step(controller.act(obs))
            total += float(reward)
            steps += 1
            done = terminated or truncated
        returns.append(total)
        successes += bool(info.get("is_success", False))
    success, mean_return = successes / episodes, float(np.mean(returns))
    text = (f"{name} on {env_id} (env arguments {json.dumps(env_kwargs, default=str, sort_keys=True)}), "
            f"{episodes} episodes reset with seeds {seed}..{seed + episodes - 1}: success {success:.2f}, "
            f"mean return {mean_return:.3f}. Recorded with pectoral-gym's dataset command.")
    try:
        dataset = env.create_dataset(dataset_id=dataset_id, algorithm_name=name, eval_env=env.spec,
                                     description=f"{description} {text}" if description else text,
                                     requirements=_package_requirement(), author=author, author_email=author_email)
    except (ValueError, FileExistsError) as error:
        raise ValueError(f"Minari refuses dataset id {dataset_id!r}: {error}") from None
    finally:
        env.close()
    path = Path(minari.storage.get_dataset_path(dataset_id))
    return Recorded(dataset_id, path, dataset.total_episodes, dataset.total_steps, success, mean_return)


def _controller(args: argparse.Namespace, env_kwargs: dict[str, Any]) -> tuple[Any, str, dict[str, Any]]:
    """The controller, its name and the env arguments (a run's own first) of the command line."""
    if args.policy:
        from pectoral_gym.agents.training.evaluate import trained_env_kwargs
        from pectoral_gym.agents.training.policy import load_policy

        policy = load_policy(args.policy)
        return policy, policy.name, {**trained_env_kwargs(args.policy, args.env), **env_kwargs}
    from pectoral_gym.agents.baselines import make_baseline
    from pectoral_gym.agents.training.vec_adapter import env_arguments
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.registration import registered_settings

    config = EnvConfig(**registered_settings(args.env, env_arguments(env_kwargs)))
    return make_baseline(args.controller, config), args.controller, env_kwargs


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m pectoral_gym.agents.training.dataset`` (module docstring)."""
    from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name

    prog = prog_name(None, "pectoral_gym.agents.training.dataset")
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter,
        epilog=examples(f"{prog} --policy runs/PectoralFish-Averaged-v2/ppo_seed0 --env {LATEST_FULL} --episodes 100 "
                        "--dataset-id pectoral/full-ppo-v0",
                        f"{prog} --controller hand --dataset-id pectoral/full-hand-v0 --datasets-path datasets"))
    who = parser.add_mutually_exclusive_group(required=True)
    who.add_argument("--policy", metavar="RUN|ZIP", help="run folder of pectoral-train or zoo, or an SB3 .zip")
    who.add_argument("--controller", metavar="NAME", help="baseline controller: random, hand, nmpc or excite")
    parser.add_argument("--dataset-id", required=True, help="Minari dataset id, namespace/name-v<N>")
    parser.add_argument("--env", default=LATEST_FULL, help="environment id")
    parser.add_argument("--env-kwargs", default="{}", metavar="JSON", help="more environment arguments")
    parser.add_argument("--episodes", type=int, default=100, help="number of episodes")
    parser.add_argument("--seed", type=int, default=0, help="episode k is reset with seed + k")
    parser.add_argument("--description", help="text put before the generated description")
    parser.add_argument("--author", help="the dataset's author (Minari's metadata)")
    parser.add_argument("--author-email", help="the author's contact (Minari's metadata)")
    parser.add_argument("--datasets-path", metavar="DIR", help="Minari's datasets folder (default: "
                        "$MINARI_DATASETS_PATH, else ~/.minari/datasets)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; prints what was written as JSON. Exit status 2 on bad input."""
    args = build_parser().parse_args(argv)
    if args.datasets_path:
        os.environ["MINARI_DATASETS_PATH"] = str(Path(args.datasets_path).resolve())
    try:
        env_kwargs = json.loads(args.env_kwargs)
        if not isinstance(env_kwargs, dict):
            raise ValueError("--env-kwargs must be a JSON object")
        controller, name, env_kwargs = _controller(args, env_kwargs)
        done = record_dataset(controller, name, args.env, args.dataset_id, args.episodes, args.seed, env_kwargs,
                              args.description, args.author, args.author_email)
    except (ValueError, TypeError, FileNotFoundError, json.JSONDecodeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(json.dumps({"dataset_id": done.dataset_id, "path": str(done.path), "episodes": done.episodes,
                      "steps": done.steps, "success": done.success, "mean_return": done.mean_return}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
