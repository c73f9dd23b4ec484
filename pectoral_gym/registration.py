"""Registration of the Gymnasium ids (entry points by string, so importing stays cheap)."""

from __future__ import annotations

__all__ = ["ENV_IDS", "register_envs"]

ENV_IDS = {"PectoralFish-Full-v0": "full", "PectoralFish-Averaged-v0": "averaged"}
MAX_EPISODE_STEPS = 240  # 2 min at the default control period of 0.5 s


def register_envs() -> None:
    """Register ``PectoralFish-Full-v0`` and ``PectoralFish-Averaged-v0`` (idempotent)."""
    from gymnasium.envs.registration import register, registry

    for env_id, model in ENV_IDS.items():
        if env_id in registry:
            continue
        register(
            id=env_id,
            entry_point="pectoral_gym.envs.fish_env:PectoralFishEnv",
            vector_entry_point="pectoral_gym.envs.vector:PectoralFishVectorEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={"model": model},
        )
