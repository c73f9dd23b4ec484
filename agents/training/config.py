"""The resolved training config: a hyperparameter file's entry, command-line overrides and the defaults.

The files are rl-baselines3-zoo's (:mod:`pectoral_gym.agents.training.zoo_format`: their keys, the
project's ``agents.train`` section, zoo's Python text). :func:`resolve_config` layers, for one algorithm
and env id, the entry's project settings, the entry, ``hyperparams`` overrides (:func:`parse_overrides`
reads them from ``key=value`` text), ``env_kwargs`` and the task into one YAML-ready dict, the
``config.yaml`` of a run folder; :func:`algo_kwargs` turns it into the algorithm's constructor arguments
(schedules and torch classes), :func:`evaluation_env` into the env of the periodic evaluation and
:func:`run_model_spec` into the model spec the run trained on.
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml

from pectoral_gym.agents.training.zoo_format import (
    CLASS_KEYS,
    SCHEDULES,
    algo_class,
    load_hyperparams,
    load_project_settings,
    parse_python_kwargs,
    torch_class,
)

__all__ = ["OWN_KEYS", "algo_kwargs", "evaluation_env", "parse_overrides", "resolve_config"]

OWN_KEYS = ("n_envs", "n_timesteps", "normalize", "policy", "env_kwargs", "eval_freq", "eval_episodes", "eval_env",
            "eval_env_kwargs", "action_change_penalty", "keep_checkpoints")
_UNSUPPORTED = ("frame_stack", "env_wrapper", "vec_env_wrapper", "callback", "monitor_kwargs", "replay_buffer_class")
_DEFAULTS = {"n_envs": 8, "normalize": False, "policy": "MlpPolicy", "env_kwargs": {}, "eval_freq": 0,
             "eval_episodes": 20, "eval_env": None, "eval_env_kwargs": {},
             "action_change_penalty": 0.0, "keep_checkpoints": False}


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


def _as_dicts(params: dict[str, Any]) -> dict[str, Any]:
    """Zoo's Python-text values (``policy_kwargs``, ``replay_buffer_kwargs``, ``normalize``) as dicts."""
    for key in ("policy_kwargs", "replay_buffer_kwargs", "normalize"):
        if isinstance(params.get(key), str):
            params[key] = parse_python_kwargs(params[key])
    return params


def resolve_config(algo: str, env_id: str, seed: int, task: str | None = None,
                   hyperparams: dict[str, Any] | None = None, env_kwargs: dict[str, Any] | None = None,
                   hyperparams_file: str | Path | None = None) -> dict[str, Any]:
    """The full, YAML-ready training config: file entry, then ``hyperparams``, ``env_kwargs``, ``task``.

    The entry's ``pectoral_gym.agents.training.train`` settings (``eval_freq``, ``eval_episodes``) come first, the entry
    over them.

    Returns:
        A dict with ``algo``, ``env_id``, ``seed``, the keys of :data:`OWN_KEYS` (``env_kwargs`` always
        holding ``task``) and ``algo_kwargs`` (everything passed to the algorithm's constructor, Python text
        read into dicts, class names as text).

    Raises:
        ValueError: On an unknown algorithm or algorithm argument, a zoo key pectoral_gym.agents.training.train does not
            support, or invalid ``n_envs``/``n_timesteps``.
    """
    cls = algo_class(algo)
    params = load_project_settings(algo, env_id, hyperparams_file)
    params.update(_as_dicts(load_hyperparams(algo, env_id, hyperparams_file)))
    params = _as_dicts(_deep_update(params, copy.deepcopy(hyperparams or {})))
    unsupported = sorted(set(params) & set(_UNSUPPORTED))
    if unsupported:
        raise ValueError(f"rl-baselines3-zoo keys {unsupported} are not supported by "
                         "pectoral_gym.agents.training.train (train with python -m rl_zoo3.train instead)")
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
    own["eval_env"] = env_id if own["eval_env"] is None else str(own["eval_env"])
    try:
        own["action_change_penalty"] = float(own["action_change_penalty"])
    except (TypeError, ValueError):
        raise ValueError(f"action_change_penalty must be a number, got {own['action_change_penalty']!r}") from None
    if not (own["action_change_penalty"] >= 0 and own["action_change_penalty"] < float("inf")):
        raise ValueError(f"action_change_penalty must be a finite number >= 0, got {own['action_change_penalty']}")
    if not isinstance(own["eval_env_kwargs"], dict):
        raise ValueError(f"eval_env_kwargs must be a mapping, got {own['eval_env_kwargs']!r}")
    accepted = set(inspect.signature(cls.__init__).parameters) - {"self", "policy", "env", "seed", "device"}
    unknown = sorted(set(params) - accepted)
    if unknown:
        raise ValueError(f"unknown {algo.upper()} arguments {unknown}; accepted: {sorted(accepted)}")
    return {"algo": algo.lower(), "env_id": env_id, "seed": int(seed), **own, "algo_kwargs": params}


def evaluation_env(config: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """Env id and arguments of the periodic evaluation of a resolved config (see the module docstring).

    Raises:
        ValueError: If ``eval_env`` is not a registered fish env id.
    """
    from pectoral_gym.agents.training.evaluate import model_kwargs
    from pectoral_gym.registration import ENV_IDS

    env_id = config.get("eval_env") or config["env_id"]
    if env_id not in ENV_IDS:
        raise ValueError(f"eval_env must be one of {sorted(ENV_IDS)}, got {env_id!r}")
    kwargs = {**config["env_kwargs"], **dict(config.get("eval_env_kwargs") or {})}
    return env_id, model_kwargs(env_id, {k: v for k, v in kwargs.items() if v is not None})


def run_model_spec(config: dict[str, Any]):
    """The model spec a run trained on (:mod:`pectoral_gym.model.spec`), from a resolved or a run folder's config.

    A run folder records it as ``model_spec`` (``spec.to_dict()``); for an older folder without it, the
    spec is derived from ``env_id`` and the model settings in ``env_kwargs``, as the env resolved them.

    Raises:
        ValueError: For an unknown env id or invalid model settings.
    """
    from pectoral_gym.model.spec import ENV_OPTIONS, env_spec, spec_from_dict
    from pectoral_gym.registration import registered_settings

    if config.get("model_spec"):
        return spec_from_dict(config["model_spec"])
    kwargs = registered_settings(config.get("env_id"), config.get("env_kwargs") or {})
    names = {*ENV_OPTIONS["full"], *ENV_OPTIONS["averaged"]}
    return env_spec(kwargs["model"], **{k: v for k, v in kwargs.items() if k in names})


def _schedule(value: Any) -> float | Callable[[float], float] | None:
    if value is None:
        return None
    if isinstance(value, str) and value.startswith("lin_"):
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    return float(value)


def algo_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments of the algorithm from a resolved config (schedules and class names converted)."""
    kwargs = copy.deepcopy(config["algo_kwargs"])
    for key in SCHEDULES:
        if key in kwargs:
            kwargs[key] = _schedule(kwargs[key])
    if isinstance(kwargs.get("train_freq"), list):
        kwargs["train_freq"] = tuple(kwargs["train_freq"])  # as zoo
    policy_kwargs = kwargs.get("policy_kwargs")
    for key in CLASS_KEYS:
        if policy_kwargs and key in policy_kwargs and not isinstance(policy_kwargs[key], type):
            policy_kwargs[key] = torch_class(policy_kwargs[key], key)
    return kwargs
