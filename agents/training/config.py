"""Training configuration: hyperparameter YAML files keyed by env id, command-line overrides, the resolved config.

``agents/hyperparams/<algo>.yml`` is in rl-baselines3-zoo's format, so one file
serves ``python -m pectoral_gym.agents.training.train`` and ``python -m rl_zoo3.train --conf-file``.
An env id maps to a dict of SB3 algorithm arguments plus zoo's own keys:

* ``n_envs``: environments in the batched vector env;
* ``n_timesteps``: total environment steps;
* ``normalize``: ``false``, ``true``, ``VecNormalize`` keyword arguments, or their Python text;
* ``policy``: SB3 policy name (``MlpPolicy``);
* ``env_kwargs``: environment arguments (``task``, ``randomize``, reward weights, ...).

Everything else is passed to the algorithm's constructor. ``policy_kwargs`` (and
``replay_buffer_kwargs``) may be Python text as zoo evaluates it,
``"dict(net_arch=[64, 64], activation_fn=nn.Tanh)"``; this module parses that text
without evaluating it (literals, ``dict(...)``, classes named ``nn.<Name>``,
``th.nn.<Name>``, ``th.optim.<Name>``). ``learning_rate`` may be ``"lin_<x>"``
(linear decay from ``x`` to 0).

The project's extras, which zoo would pass to the algorithm and which it takes from
its command line instead, live in the file's top-level ``pectoral_gym.agents.training.train`` section,
keyed by env id (zoo reads only the entry of ``--env``):

* ``eval_freq``: environment steps in all between periodic evaluations (0: none);
* ``eval_episodes``: episodes per periodic evaluation;
* ``eval_env``: env id of the periodic evaluation, which selects ``best_model.zip`` (default: the training
  env). ``PectoralFish-Full-v0`` validates a policy trained on the averaged model on the full model, which
  stands in for the robot (its episodes are disjoint from the reported ones);
* ``eval_env_kwargs``: env arguments of the periodic evaluation, over the training ``env_kwargs`` (a ``null``
  value drops a training argument: ``{randomize: null}`` validates on the nominal parameters). Arguments of
  the averaged model only (``scaling``, ``check_scaling_params``) are dropped on the full model;
* ``action_change_penalty``: training-only penalty per unit of mean absolute action change between steps
  (:mod:`pectoral_gym.agents.training.smoothing`; 0: off).
"""

from __future__ import annotations

import ast
import copy
import inspect
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "HYPERPARAMS_DIR",
    "evaluation_env",
    "OWN_KEYS",
    "PROJECT_SECTION",
    "algo_class",
    "algo_kwargs",
    "load_hyperparams",
    "load_project_settings",
    "parse_overrides",
    "parse_python_kwargs",
    "resolve_config",
    "zoo_problems",
]

HYPERPARAMS_DIR = Path(__file__).resolve().parents[1] / "hyperparams"
PROJECT_SECTION = "agents.train"  # the section of the hyperparameter files read by train only
OWN_KEYS = ("n_envs", "n_timesteps", "normalize", "policy", "env_kwargs", "eval_freq", "eval_episodes", "eval_env",
            "eval_env_kwargs", "action_change_penalty")
PROJECT_KEYS = ("eval_freq", "eval_episodes", "eval_env", "eval_env_kwargs", "action_change_penalty")
ZOO_KEYS = ("n_envs", "n_timesteps", "normalize", "policy", "env_kwargs", "frame_stack", "env_wrapper",
            "vec_env_wrapper", "callback", "monitor_kwargs")
_UNSUPPORTED = ("frame_stack", "env_wrapper", "vec_env_wrapper", "callback", "monitor_kwargs", "replay_buffer_class")
_DEFAULTS = {"n_envs": 8, "normalize": False, "policy": "MlpPolicy", "env_kwargs": {}, "eval_freq": 0,
             "eval_episodes": 20, "eval_env": None, "eval_env_kwargs": {},
             "action_change_penalty": 0.0}
_ACTIVATIONS = {"tanh": "nn.Tanh", "relu": "nn.ReLU", "elu": "nn.ELU", "leaky_relu": "nn.LeakyReLU"}
_CLASS_KEYS = ("activation_fn", "optimizer_class")
_SCHEDULES = ("learning_rate", "clip_range", "clip_range_vf")


def algo_class(algo: str) -> type:
    """The SB3 algorithm class of ``algo`` (``"ppo"``, ``"sac"``, ``"td3"``, ``"a2c"``, ``"ddpg"``)."""
    from pectoral_gym.agents.training.policy import _algos

    classes = _algos()
    if algo.lower() not in classes:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(classes)}")
    return classes[algo.lower()]


def _read_table(algo: str, path: str | Path | None) -> tuple[Path, dict[str, Any]]:
    path = Path(path) if path is not None else HYPERPARAMS_DIR / f"{algo.lower()}.yml"
    if not path.is_file():
        raise FileNotFoundError(f"no hyperparameter file {path}; write one keyed by env id (see {HYPERPARAMS_DIR})")
    with open(path) as f:
        table = yaml.safe_load(f) or {}
    if not isinstance(table, dict):
        raise ValueError(f"{path} must map env ids to hyperparameters, got {type(table).__name__}")
    return path, table


def load_hyperparams(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The zoo entry of ``env_id`` from ``path`` (default ``agents/hyperparams/<algo>.yml``).

    Raises:
        FileNotFoundError: If the file does not exist.
        ValueError: If the file has no entry for ``env_id``.
    """
    path, table = _read_table(algo, path)
    entries = sorted(key for key in table if key != PROJECT_SECTION)
    if env_id == PROJECT_SECTION or env_id not in table:
        raise ValueError(f"{path} has no entry for {env_id!r}; entries: {entries}")
    return copy.deepcopy(dict(table[env_id]))


def load_project_settings(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The training settings of ``env_id`` (:data:`PROJECT_KEYS`); ``{}`` if there are none.

    They are the file's ``agents.train`` section, read by ``pectoral_gym.agents.training.train``.

    Raises:
        FileNotFoundError: If the file does not exist.
        ValueError: If the section holds other keys.
    """
    path, table = _read_table(algo, path)
    settings = dict((table.get(PROJECT_SECTION) or {}).get(env_id) or {})
    unknown = sorted(set(settings) - set(PROJECT_KEYS))
    if unknown:
        raise ValueError(f"{path}: {PROJECT_SECTION}.{env_id} has unknown keys {unknown}; accepted: {PROJECT_KEYS}")
    return copy.deepcopy(settings)


_NAMESPACES = {"nn": ("torch", "nn"), "th": ("torch",), "torch": ("torch",)}


def _literal(node: ast.AST, text: str) -> Any:
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool, type(None))):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        value = _literal(node.operand, text)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, (ast.List, ast.Tuple)):
        return [_literal(item, text) for item in node.elts]
    if isinstance(node, ast.Dict) and None not in node.keys:
        return {_literal(k, text): _literal(v, text) for k, v in zip(node.keys, node.values, strict=True)}
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args
            and all(kw.arg is not None for kw in node.keywords)):
        return {kw.arg: _literal(kw.value, text) for kw in node.keywords}
    name = _dotted(node)
    if name is not None and name.split(".")[0] in _NAMESPACES and "." in name:
        return name
    raise ValueError(f"{text!r}: cannot read {ast.unparse(node)!r} (literals, dict(...) and nn./th. class names only)")


def _dotted(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


def parse_python_kwargs(text: str) -> dict[str, Any]:
    """Zoo's Python text for keyword arguments (``"dict(net_arch=[64], activation_fn=nn.Tanh)"``) as a dict.

    Nothing is evaluated: literals, ``dict(...)``, ``{...}`` and class names rooted at ``nn``, ``th`` or ``torch``
    are read; a class name is kept as its dotted text (``"nn.Tanh"``), resolved by :func:`algo_kwargs`.

    Raises:
        ValueError: On anything else, or if the text is not a dict.
    """
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as error:
        raise ValueError(f"{text!r} is not Python text ({error.msg})") from None
    value = _literal(tree.body, text)
    if not isinstance(value, dict):
        raise ValueError(f"{text!r} must give a dict, got {type(value).__name__}")
    return value


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
    from pectoral_gym.registration import ENV_IDS

    if config.get("model_spec"):
        return spec_from_dict(config["model_spec"])
    env_id = config.get("env_id")
    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; fish envs: {sorted(ENV_IDS)}")
    kwargs = config.get("env_kwargs") or {}
    names = {*ENV_OPTIONS["full"], *ENV_OPTIONS["averaged"]}
    return env_spec(kwargs.get("model", ENV_IDS[env_id]), **{k: v for k, v in kwargs.items() if k in names})


def _schedule(value: Any) -> float | Callable[[float], float] | None:
    if value is None:
        return None
    if isinstance(value, str) and value.startswith("lin_"):
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    return float(value)


def _class(name: Any, key: str) -> type:
    """``"nn.Tanh"``, ``"th.optim.Adam"`` (or a legacy activation name, ``"tanh"``) -> the torch class."""
    import torch

    text = _ACTIVATIONS.get(str(name).lower(), str(name)) if key == "activation_fn" else str(name)
    root, *attrs = text.split(".")
    if root not in _NAMESPACES or not attrs:
        raise ValueError(f"{key} must name a torch class (nn.Tanh, th.optim.Adam, ...), got {name!r}")
    obj: Any = torch
    for attr in (*_NAMESPACES[root][1:], *attrs):
        obj = getattr(obj, attr, None)
    if not isinstance(obj, type):
        raise ValueError(f"{key}: {name!r} is not a torch class")
    return obj


def algo_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments of the algorithm from a resolved config (schedules and class names converted)."""
    kwargs = copy.deepcopy(config["algo_kwargs"])
    for key in _SCHEDULES:
        if key in kwargs:
            kwargs[key] = _schedule(kwargs[key])
    if isinstance(kwargs.get("train_freq"), list):
        kwargs["train_freq"] = tuple(kwargs["train_freq"])  # as zoo
    policy_kwargs = kwargs.get("policy_kwargs")
    for key in _CLASS_KEYS:
        if policy_kwargs and key in policy_kwargs and not isinstance(policy_kwargs[key], type):
            policy_kwargs[key] = _class(policy_kwargs[key], key)
    return kwargs


def zoo_problems(algo: str, path: str | Path | None = None) -> list[str]:
    """What rl-baselines3-zoo 2.9.2 would refuse in a hyperparameter file (``[]``: nothing).

    Zoo's rules (``rl_zoo3/exp_manager.py``, ``_preprocess_hyperparams``): an entry needs ``n_timesteps``; it
    removes its own keys (:data:`ZOO_KEYS`), evaluates ``policy_kwargs``/``normalize`` given as text, turns a
    schedule text ``"<name>_<x>"`` into a linear schedule, and passes every other key, unchanged, to the
    algorithm's constructor (with ``env``, ``seed``, ``verbose``, ``device``, ``tensorboard_log`` of its own).
    """
    path, table = _read_table(algo, path)
    accepted = set(inspect.signature(algo_class(algo).__init__).parameters) - {
        "self", "env", "seed", "device", "verbose", "tensorboard_log"}
    problems = []
    for env_id, entry in table.items():
        if env_id == PROJECT_SECTION:
            continue
        where = f"{path.name}: {env_id}"
        if not isinstance(entry, dict):
            problems.append(f"{where}: not a mapping")
            continue
        if "n_timesteps" not in entry:
            problems.append(f"{where}: no n_timesteps")
        for key in sorted(set(entry) - set(ZOO_KEYS) - accepted):
            problems.append(f"{where}: {key!r} is not a {algo.upper()} argument (zoo passes it to the constructor)")
        for key in ("policy_kwargs", "replay_buffer_kwargs", "normalize"):
            value = entry.get(key)
            if isinstance(value, str):
                try:
                    parse_python_kwargs(value)
                except ValueError as error:
                    problems.append(f"{where}: {key}: {error}")
            elif isinstance(value, dict) and key == "policy_kwargs":
                problems.extend(f"{where}: policy_kwargs.{name} is text in a dict (SB3 gets the text); write "
                                "policy_kwargs as Python text, activation_fn=nn.Tanh"
                                for name in _CLASS_KEYS if isinstance(value.get(name), str))
        for key in _SCHEDULES:
            value = entry.get(key)
            if isinstance(value, str) and (value.count("_") != 1 or not _is_float(value.split("_")[1])):
                problems.append(f"{where}: {key} {value!r} is not a zoo schedule (lin_<x>)")
    return problems


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
