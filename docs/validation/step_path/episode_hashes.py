"""SHA-256 of recorded 60-step episodes of the registered envs, single and vector, in several settings.

Run with the checkout to hash first on ``PYTHONPATH`` (e.g. a worktree of an older commit, then this
one) and compare the printed lines; ``--check`` also asserts that the single env and the vector envs
at 4 and 80 envs agree among themselves (the same seeds give the same episodes)::

    PYTHONPATH=/tmp/stepbase python docs/validation/step_path/episode_hashes.py > old.txt
    PYTHONPATH=. python docs/validation/step_path/episode_hashes.py > new.txt && diff old.txt new.txt

Hashed per step: observations, rewards, terminated and truncated flags and every ``info`` entry
(key, value bytes and dtype), actions drawn from a fixed generator; episodes end by their own
flags (autoreset in the vector env) and run on for 60 steps.
"""

from __future__ import annotations

import hashlib
import sys

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the envs

STEPS = 60
SETTINGS = {
    "averaged-defaults": ("PectoralFish-Averaged-v0", {}),
    "averaged-transitions-fins": ("PectoralFish-Averaged-v0", {"transitions": True, "observe_fins": True}),
    "averaged-track": ("PectoralFish-Averaged-v0", {"task": "track"}),
    "averaged-scaling-none": ("PectoralFish-Averaged-v0", {"scaling": "none"}),
    "full-fast": ("PectoralFish-Full-v0", {"integration": "fast"}),
    "full-fast-track": ("PectoralFish-Full-v0", {"integration": "fast", "task": "track"}),
}


def _feed(h, value) -> None:
    if isinstance(value, dict):
        for key in value:
            if key.startswith("_") or key in ("final_obs", "final_info", "episode"):
                continue
            h.update(key.encode())
            _feed(h, value[key])
        return
    array = np.asarray(value)
    h.update(str(array.dtype).encode())
    h.update(np.ascontiguousarray(array).tobytes())


def single(env_id: str, kwargs: dict, seed: int = 0) -> str:
    """SHA-256 of a 60-step episode (observations, rewards, flags, infos) of one env."""
    env = gym.make(env_id, **kwargs)
    rng = np.random.default_rng(seed)
    h = hashlib.sha256()
    obs, info = env.reset(seed=seed)
    _feed(h, obs), _feed(h, info)
    for _ in range(STEPS):
        obs, reward, term, trunc, info = env.step(rng.uniform(-1, 1, 8))
        for v in (obs, np.float64(reward), term, trunc, info):
            _feed(h, v)
        if term or trunc:
            obs, info = env.reset()
            _feed(h, obs), _feed(h, info)
    env.close()
    return h.hexdigest()[:16]


def vector(env_id: str, kwargs: dict, n: int, seed: int = 0) -> tuple[str, str]:
    """Hash of the whole batch, and of env 0 alone."""
    envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    rng = np.random.default_rng(seed)
    h, h0 = hashlib.sha256(), hashlib.sha256()
    obs, info = envs.reset(seed=seed)
    _feed(h, obs), _feed(h, info)
    for _ in range(STEPS):
        obs, reward, term, trunc, info = envs.step(rng.uniform(-1, 1, (n, 8)))
        for v in (obs, reward, term, trunc, info):
            _feed(h, v)
        _feed(h0, obs[0]), _feed(h0, reward[0])
    envs.close()
    return h.hexdigest()[:16], h0.hexdigest()[:16]


def main() -> None:
    """Print the hash of every setting, single and vector."""
    for name, (env_id, kwargs) in SETTINGS.items():
        print(f"{name:28s} single {single(env_id, kwargs)}", flush=True)
        for n in (4, 80):
            whole, first = vector(env_id, kwargs, n)
            print(f"{name:28s} vector@{n:<3d} {whole} env0 {first}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
