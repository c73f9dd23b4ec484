"""rl-baselines3-zoo's hyperparameter files: their entries, the project's section, zoo's Python text and rules.

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
``th.nn.<Name>``, ``th.optim.<Name>``; :func:`parse_python_kwargs`, then :func:`torch_class`).
``learning_rate`` may be ``"lin_<x>"`` (linear decay from ``x`` to 0).
:func:`zoo_problems` lists what zoo itself would refuse in a file.

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

How an entry becomes a run's config (file, overrides, defaults): :mod:`pectoral_gym.agents.training.config`.
"""

from __future__ import annotations

import ast
import copy
import inspect
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "CLASS_KEYS",
    "HYPERPARAMS_DIR",
    "PROJECT_KEYS",
    "PROJECT_SECTION",
    "SCHEDULES",
    "ZOO_KEYS",
    "algo_class",
    "load_hyperparams",
    "load_project_settings",
    "parse_python_kwargs",
    "torch_class",
    "zoo_problems",
]

HYPERPARAMS_DIR = Path(__file__).resolve().parents[1] / "hyperparams"
PROJECT_SECTION = "agents.train"  # the section of the hyperparameter files read by train only
PROJECT_KEYS = ("eval_freq", "eval_episodes", "eval_env", "eval_env_kwargs", "action_change_penalty")
ZOO_KEYS = ("n_envs", "n_timesteps", "normalize", "policy", "env_kwargs", "frame_stack", "env_wrapper",
            "vec_env_wrapper", "callback", "monitor_kwargs")
CLASS_KEYS = ("activation_fn", "optimizer_class")  # policy_kwargs that name a torch class
SCHEDULES = ("learning_rate", "clip_range", "clip_range_vf")  # arguments that may be a schedule text
_ACTIVATIONS = {"tanh": "nn.Tanh", "relu": "nn.ReLU", "elu": "nn.ELU", "leaky_relu": "nn.LeakyReLU"}


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
    are read; a class name is kept as its dotted text (``"nn.Tanh"``), resolved by :func:`torch_class`.

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


def torch_class(name: Any, key: str) -> type:
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
                                for name in CLASS_KEYS if isinstance(value.get(name), str))
        for key in SCHEDULES:
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
