"""Seeded episodes of every registered id, recorded as arrays: the configuration's fingerprint.

``python tests/config_fingerprint.py`` writes :data:`GOLDEN` (only when the configurations are meant to
change; the test ``tests/test_config_fingerprint.py`` compares the current code against it).
"""

from __future__ import annotations

import dataclasses
import os
import sys

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.model.params import PER_FIN_DEFAULTS

GOLDEN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "config_fingerprint.npz")
STEPS = 30
SEED = 2026


def record(env_id: str) -> dict[str, np.ndarray]:
    """Observations, rewards, flags and info values of ``STEPS`` seeded random steps of ``env_id``.

    A reset with the next seed follows every episode end, so a terminating id keeps being exercised.
    """
    env = gym.make(env_id)
    actions = np.random.default_rng(SEED).uniform(-1.0, 1.0, (STEPS, 8)).astype(np.float32)
    seed = SEED
    obs, info = env.reset(seed=seed)
    rows: dict[str, list] = {"obs": [obs], "reward": [], "terminated": [], "truncated": []}
    infos: list[dict] = [info]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        rows["obs"].append(obs)
        rows["reward"].append(reward)
        rows["terminated"].append(terminated)
        rows["truncated"].append(truncated)
        infos.append(info)
        if terminated or truncated:
            seed += 1
            obs, info = env.reset(seed=seed)
            rows["obs"].append(obs)
            infos.append(info)
    env.close()
    out = {key: np.asarray(value) for key, value in rows.items()}
    keys = sorted({key for info in infos for key in info})
    for key in keys:
        out[f"info.{key}"] = np.array([float(info.get(key, np.nan)) for info in infos])
    return out


def settings_view(config) -> dict[str, np.ndarray]:
    """What an env's settings resolve to, in terms that do not depend on how the settings are organised.

    The kernels' packed settings (task, ranges, rewards, insets, stopping band and rule, servo limit), the
    model spec as a plain dict, the observation of the fins and the nominal parameters (the per-fin fields only
    where they differ from the symmetric fish, which every id recorded before they existed was).
    """
    spec = config.model_spec().to_dict()
    return {
        "cfg_array": config.cfg_array(),
        "model_spec": np.array(sorted(f"{key}={value!r}" for key, value in spec.items())),
        "observe_fins": np.array(bool(config.observe_fins)),
        "params": np.array(sorted(f"{key}={value!r}" for key, value in dataclasses.asdict(config.params).items()
                                  if PER_FIN_DEFAULTS.get(key) != value)),
        "extras": np.array([repr(config.randomize), repr(config.sensing), repr(config.timing)]),
    }


def make_views(env_id: str) -> dict[str, np.ndarray]:
    """:func:`settings_view` of ``env_id`` through ``gym.make`` and through ``gym.make_vec`` (which must agree)."""
    env = gym.make(env_id)
    single = settings_view(env.unwrapped.config)
    env.close()
    vec = gym.make_vec(env_id, num_envs=1)
    vector = settings_view(vec.unwrapped.config if hasattr(vec.unwrapped, "config") else vec.config)
    vec.close()
    for key, value in single.items():
        if not np.array_equal(value, vector[key]):
            raise AssertionError(f"{env_id}: gym.make and gym.make_vec disagree on {key}")
    return {f"settings.{key}": value for key, value in single.items()}


def fingerprint(episodes: bool = True) -> dict[str, np.ndarray]:
    """:func:`record` (with ``episodes``) and :func:`make_views` of every registered fish id, as ``"<id>/<name>"``."""
    from pectoral_gym.registration import ENV_IDS

    out = {}
    for env_id in sorted(ENV_IDS):
        arrays = {**make_views(env_id), **(record(env_id) if episodes else {})}
        out.update({f"{env_id}/{name}": value for name, value in arrays.items()})
    return out


if __name__ == "__main__":
    arrays = fingerprint()
    np.savez_compressed(GOLDEN, **arrays)
    print(f"wrote {len(arrays)} arrays to {GOLDEN}", file=sys.stderr)
