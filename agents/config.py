"""Training configuration: hyperparameter YAML files keyed by env id, command-line overrides, the resolved config.

``agents/hyperparams/<algo>.yml`` maps each env id to a dict of SB3 algorithm
arguments plus a few keys of our own (as rl-baselines3-zoo):

* ``n_envs``: environments in the batched vector env;
* ``n_timesteps``: total environment steps;
* ``normalize``: ``false``, ``true`` or ``VecNormalize`` keyword arguments;
* ``policy``: SB3 policy name (``MlpPolicy``);
* ``env_kwargs``: environment arguments (``task``, ``randomize``, reward weights, ...);
* ``eval_freq``: environment steps between periodic evaluations (0: none);
* ``eval_episodes``: episodes per periodic evaluation.

Everything else is passed to the algorithm's constructor. ``learning_rate``
may be ``"lin_<x>"`` (linear decay from ``x`` to 0); ``policy_kwargs.activation_fn``
is a name (``tanh``, ``relu``, ``elu``, ``leaky_relu``).
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "HYPERPARAMS_DIR",
    "OWN_KEYS",
    "algo_class",
    "algo_kwargs",
    "load_hyperparams",
    "parse_overrides",
    "resolve_config",
]

HYPERPARAMS_DIR = Path(__file__).parent / "hyperparams"
OWN_KEYS = ("n_envs", "n_timesteps", "normalize", "policy", "env_kwargs", "eval_freq", "eval_episodes")
_DEFAULTS = {"n_envs": 8, "normalize": False, "policy": "MlpPolicy", "env_kwargs": {}, "eval_freq": 0,
             "eval_episodes": 20}
_ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")


def algo_class(algo: str) -> type:
    """The SB3 algorithm class of ``algo`` (``"ppo"``, ``"sac"``, ``"td3"``, ``"a2c"``, ``"ddpg"``)."""
    from agents.policy import _algos

    classes = _algos()
    if algo.lower() not in classes:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(classes)}")
    return classes[algo.lower()]


def load_hyperparams(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The hyperparameters of ``env_id`` from ``path`` (default ``agents/hyperparams/<algo>.yml``).

    Raises:
        FileNotFoundError: If the file does not exist.
        ValueError: If the file has no entry for ``env_id``.
    """
    path = Path(path) if path is not None else HYPERPARAMS_DIR / f"{algo.lower()}.yml"
    if not path.is_file():
        raise FileNotFoundError(f"no hyperparameter file {path}; write one keyed by env id (see {HYPERPARAMS_DIR})")
    with open(path) as f:
        table = yaml.safe_load(f) or {}
    if env_id not in table:
        raise ValueError(f"{path} has no entry for {env_id!r}; entries: {sorted(table)}")
    return copy.deepcopy(dict(table[env_id]))


def parse_overrides(items: Sequence[str] | None) -> dict[str, Any]:
    """``["a=1", "policy_kwargs.net_arch=[32, 32]"]`` -> nested dict; values parsed as YAML.

    Raises:
        ValueError: If an item is not ``key=value``.
    """
    result: dict[str, Any] = {}
    for item in items or ():
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"override {item!r} must look like key=value (nested: a.b=value)")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f"override {item!r}: value is not valid YAML ({error})") from None
        if isinstance(value, str):
            value = _number(value)
        node = result
        parts = key.strip().split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return result


def _number(text: str) -> Any:
    """YAML reads ``1e5`` as a string; take it as a number."""
    try:
        number = float(text)
    except ValueError:
        return text
    return int(number) if number.is_integer() and "." not in text and "e" not in text.lower() else number


def _deep_update(base: dict[str, Any], update: dict[str, Any]) -> dict[str, Any]:
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict) and key != "normalize":
            _deep_update(base[key], value)
        else:
            base[key] = value
    return base


def resolve_config(algo: str, env_id: str, seed: int, task: str | None = None,
                   hyperparams: dict[str, Any] | None = None, env_kwargs: dict[str, Any] | None = None,
                   hyperparams_file: str | Path | None = None) -> dict[str, Any]:
    """The full, YAML-ready training config: file entry, then ``hyperparams`` overrides, then ``env_kwargs``, ``task``.

    Returns:
        A dict with ``algo``, ``env_id``, ``seed``, the keys of :data:`OWN_KEYS` (``env_kwargs`` always
        holding ``task``) and ``algo_kwargs`` (everything passed to the algorithm's constructor).

    Raises:
        ValueError: On an unknown algorithm or algorithm argument, or invalid ``n_envs``/``n_timesteps``.
    """
    cls = algo_class(algo)
    params = _deep_update(load_hyperparams(algo, env_id, hyperparams_file), copy.deepcopy(hyperparams or {}))
    own = {key: params.pop(key, copy.deepcopy(_DEFAULTS.get(key))) for key in OWN_KEYS}
    own["env_kwargs"] = dict(own["env_kwargs"] or {})
    own["env_kwargs"].update(env_kwargs or {})
    if task is not None:
        own["env_kwargs"]["task"] = task
    own["env_kwargs"].setdefault("task", "goal")
    for key in ("n_envs", "n_timesteps", "eval_freq", "eval_episodes"):
        try:
            own[key] = int(float(own[key]))
        except (TypeError, ValueError):
            raise ValueError(f"{key} must be an integer, got {own[key]!r}") from None
    if own["n_envs"] < 1 or own["n_timesteps"] < 1:
        raise ValueError(f"n_envs and n_timesteps must be >= 1, got {own['n_envs']} and {own['n_timesteps']}")
    accepted = set(inspect.signature(cls.__init__).parameters) - {"self", "policy", "env", "seed", "device"}
    unknown = sorted(set(params) - accepted)
    if unknown:
        raise ValueError(f"unknown {algo.upper()} arguments {unknown}; accepted: {sorted(accepted)}")
    return {"algo": algo.lower(), "env_id": env_id, "seed": int(seed), **own, "algo_kwargs": params}


def _schedule(value: Any) -> float | Callable[[float], float]:
    if isinstance(value, str) and value.startswith("lin_"):
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    return float(value)


def algo_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments of the algorithm from a resolved config (schedules and activation names converted)."""
    import torch

    kwargs = copy.deepcopy(config["algo_kwargs"])
    for key in ("learning_rate", "clip_range"):
        if key in kwargs:
            kwargs[key] = _schedule(kwargs[key])
    policy_kwargs = kwargs.get("policy_kwargs")
    if policy_kwargs and "activation_fn" in policy_kwargs:
        name = str(policy_kwargs["activation_fn"]).lower()
        if name not in _ACTIVATIONS:
            raise ValueError(f"activation_fn must be one of {_ACTIVATIONS}, got {name!r}")
        policy_kwargs["activation_fn"] = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU,
                                          "leaky_relu": torch.nn.LeakyReLU}[name]
    return kwargs
