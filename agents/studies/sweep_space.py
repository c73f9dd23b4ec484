"""Parameter spaces of :mod:`~pectoral_gym.agents.studies.sweep`, and each trial's config (no Ray here).

Spaces come from YAML/JSON or ``--grid``.

A space maps a key to the values a trial takes for it. Keys are dotted paths into
the training config of :func:`pectoral_gym.agents.training.config.resolve_config`:

* ``seed``: the trial's seed;
* ``task``: ``goal`` or ``track``;
* any hyperparameter of the file's entry (``learning_rate``, ``ent_coef``,
  ``n_timesteps``, ``eval_freq``, ``policy_kwargs``, ``policy_kwargs.net_arch``, ...);
* environment arguments under ``env_kwargs.`` (``env_kwargs.time_penalty``,
  ``env_kwargs.randomize.drag_coef``: the relative half-width of one parameter);
* ``randomize_scale``: ``s`` sets ``env_kwargs.randomize`` to
  :data:`pectoral_gym.agents.training.evaluate.DEFAULT_RANDOMIZATION` with every width times ``s`` (``0``: none).

A value in the file is one of::

    seed: [0, 1, 2]                               # a list: grid search, one trial per value
    ent_coef: {grid: [0.0, 0.005]}                # the same, spelled out (for a list-valued key)
    learning_rate: {loguniform: [1.0e-4, 1.0e-3]} # sampled; also uniform [low, high], randint [low, high)
    n_steps: {choice: [128, 256]}                 # sampled from the values
    n_timesteps: 200000                           # anything else: the same for every trial
    policy_kwargs.net_arch: {value: [64, 64]}     # a list kept as one value

Grid keys multiply (every combination); each combination is repeated ``num_samples``
times with fresh draws of the sampled keys. ``--grid key=v1,v2`` on the command line
is a grid key (values read as YAML, split at commas outside brackets and quotes).
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from pectoral_gym.agents.training.config import parse_overrides, resolve_config

__all__ = ["SAMPLERS", "Dimension", "grid_points", "load_param_space", "parse_grid", "trial_config"]

SAMPLERS = ("uniform", "loguniform", "randint", "choice")
KINDS = ("grid", "value", *SAMPLERS)
SPECIAL_KEYS = ("seed", "task", "randomize_scale")

Dimension = tuple[str, Any]  # (kind, values): ("grid", [..]), ("value", v), ("uniform", [low, high]), ...


def _dimension(key: str, value: Any) -> Dimension:
    if isinstance(value, list):
        if not value:
            raise ValueError(f"param space: {key!r} has an empty list of values")
        return ("grid", value)
    if isinstance(value, dict) and len(value) == 1 and next(iter(value)) in KINDS:
        kind, values = next(iter(value.items()))
        if kind == "value":
            return (kind, values)
        if not isinstance(values, list) or not values:
            raise ValueError(f"param space: {key!r}: {kind} takes a non-empty list, got {values!r}")
        if kind in ("uniform", "loguniform", "randint"):
            if len(values) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
                raise ValueError(f"param space: {key!r}: {kind} takes [low, high] numbers, got {values!r}")
            if not values[0] < values[1] or (kind == "loguniform" and values[0] <= 0):
                raise ValueError(f"param space: {key!r}: {kind} needs 0 < low < high (low < high), got {values!r}")
        return (kind, values)
    if isinstance(value, dict) and len(value) == 1 and next(iter(value)) not in KINDS and not key.startswith(
            ("env_kwargs", "policy_kwargs", "normalize")):
        raise ValueError(f"param space: {key!r}: unknown kind {next(iter(value))!r}; kinds: {list(KINDS)}")
    return ("value", value)


def load_param_space(path: str | Path) -> dict[str, Dimension]:
    """Read a parameter space from a YAML or JSON file (see the module docstring).

    Raises:
        FileNotFoundError: If the file does not exist.
        ValueError: If it is not a mapping of keys to values, or a value is malformed.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no parameter-space file {path}")
    text = path.read_text()
    try:
        table = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as error:
        raise ValueError(f"{path}: not valid {'JSON' if path.suffix == '.json' else 'YAML'} ({error})") from None
    if not isinstance(table, dict) or not all(isinstance(k, str) for k in table):
        raise ValueError(f"{path} must map keys (seed, learning_rate, env_kwargs.randomize.drag_coef, ...) to values")
    return {key: _dimension(key, value) for key, value in table.items()}


def _split_top_level(text: str) -> list[str]:
    """Split at commas that are outside brackets, braces and quotes."""
    parts, depth, quote, current = [], 0, "", []
    for char in text:
        if quote:
            quote = "" if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char in "[{(":
            depth += 1
        elif char in "]})":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append("".join(current))
            current = []
            continue
        current.append(char)
    parts.append("".join(current))
    return [p.strip() for p in parts]


def parse_grid(items: Sequence[str] | None) -> dict[str, Dimension]:
    """``["seed=0,1", "ent_coef=0,0.005", "policy_kwargs.net_arch=[64],[64,64]"]`` -> grid dimensions.

    Raises:
        ValueError: If an item is not ``key=v1[,v2...]`` or a value is not valid YAML.
    """
    space: dict[str, Dimension] = {}
    for item in items or ():
        key, sep, text = item.partition("=")
        if not sep or not key.strip() or not text.strip():
            raise ValueError(f"--grid {item!r} must look like key=value1,value2")
        values = [next(iter(parse_overrides([f"v={part}"]).values())) for part in _split_top_level(text)]
        space[key.strip()] = ("grid", values)
    return space


def grid_points(space: dict[str, Dimension]) -> list[dict[str, Any]]:
    """Every combination of the grid keys, with fixed keys and, for sampled keys, their lower bound/first value.

    The sampled stand-ins let :func:`trial_config` check every combination before a sweep starts.
    """
    fixed = {}
    for key, (kind, values) in space.items():
        if kind == "value":
            fixed[key] = values
        elif kind in SAMPLERS:
            fixed[key] = values[0]
    grid = [(key, values) for key, (kind, values) in space.items() if kind == "grid"]
    return [{**fixed, **dict(zip([k for k, _ in grid], combo, strict=True))}
            for combo in itertools.product(*(v for _, v in grid))]


def trial_config(algo: str, env_id: str, params: dict[str, Any], seed: int = 0,
                 hyperparams: dict[str, Any] | None = None, hyperparams_file: str | Path | None = None
                 ) -> dict[str, Any]:
    """The resolved training config of one trial: the file's entry, ``hyperparams``, then the trial's ``params``.

    Args:
        algo: Algorithm (``ppo``, ``sac``, ...).
        env_id: Environment id.
        params: The trial's values, keyed by dotted path (see the module docstring).
        seed: Seed when ``params`` has none.
        hyperparams: Overrides for every trial (nested dict), under ``params``.
        hyperparams_file: Hyperparameter file (default: ``agents/hyperparams/<algo>.yml``).

    Raises:
        ValueError: On unknown keys or values that :func:`pectoral_gym.agents.training.config.resolve_config` refuses.
    """
    from pectoral_gym.agents.training.evaluate import DEFAULT_RANDOMIZATION

    params = dict(params)
    seed = params.pop("seed", seed)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    task = params.pop("task", None)
    overrides: dict[str, Any] = {}
    for key, value in params.items():
        if key == "randomize_scale":
            continue
        node = overrides
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"param space: {key!r} goes inside {part!r}, which another key sets to a value")
        node[leaf] = value
    merged = _merge(hyperparams or {}, overrides)
    if "randomize_scale" in params:
        scale = params["randomize_scale"]
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 <= scale * max(
                DEFAULT_RANDOMIZATION.values()) < 1:
            raise ValueError(f"randomize_scale must be a number in [0, {1 / max(DEFAULT_RANDOMIZATION.values()):g}), "
                             f"got {scale!r}")
        randomize = {name: width * scale for name, width in DEFAULT_RANDOMIZATION.items()} if scale else None
        merged.setdefault("env_kwargs", {})["randomize"] = randomize
    return resolve_config(algo, env_id, int(seed), task=task, hyperparams=merged, hyperparams_file=hyperparams_file)


def _merge(base: dict[str, Any], update: dict[str, Any]) -> dict[str, Any]:
    out = {key: (_merge(value, {}) if isinstance(value, dict) else value) for key, value in base.items()}
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out
