"""Registration of the Gymnasium ids (entry points by string, so importing stays cheap).

Each id names one configuration (:data:`pectoral_gym.versions.ENV_VERSIONS`, as EnvConfig arguments:
:data:`ENV_SETTINGS`), used by ``gym.make``, ``gym.make_vec`` and every
tool that takes an env id (training, evaluation, the baselines' and the NMPC's model, the benchmark, the
robot env): :func:`registered_settings` is the one way from an id to its settings.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pectoral_gym.versions import (
    ENV_VERSIONS,
    LATEST,
    LATEST_AVERAGED,
    LATEST_FULL,
    MEASUREMENT_MARGIN,
    ROBOT,
)

__all__ = ["ENV_IDS", "ENV_SETTINGS", "LATEST", "LATEST_AVERAGED", "LATEST_FULL", "MAX_EPISODE_STEPS",
           "MEASUREMENT_MARGIN", "ROBOT_READY", "register_envs", "registered_settings"]

#: What the robot-ready envs (v1 on) set, as EnvConfig arguments (:data:`pectoral_gym.versions.ROBOT`'s settings).
ROBOT_READY: dict[str, Any] = ROBOT.settings()

#: id -> every EnvConfig argument its version sets (:data:`pectoral_gym.versions.ENV_VERSIONS`; the others keep
#: EnvConfig's defaults).
ENV_SETTINGS: dict[str, dict[str, Any]] = {env_id: version.settings() for env_id, version in ENV_VERSIONS.items()}
#: id -> its model, ``"full"`` or ``"averaged"``.
ENV_IDS = {env_id: settings["model"] for env_id, settings in ENV_SETTINGS.items()}
MAX_EPISODE_STEPS = 240  # 2 min at the default control period of 0.5 s


def registered_settings(env_id: str, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The EnvConfig arguments of ``env_id`` with ``overrides`` on top (``model`` is the id's).

    Raises:
        ValueError: If ``env_id`` is not a fish env id, or ``overrides`` names another model.
    """
    if env_id not in ENV_SETTINGS:
        raise ValueError(f"unknown env id {env_id!r}; fish envs: {sorted(ENV_SETTINGS)}")
    overrides = dict(overrides or {})
    model = overrides.pop("model", ENV_IDS[env_id])
    if model != ENV_IDS[env_id]:
        raise ValueError(f"{env_id} is the {ENV_IDS[env_id]} model; model={model!r} contradicts it")
    return {**ENV_SETTINGS[env_id], **overrides}


def register_envs() -> None:
    """Register the ids of :data:`ENV_SETTINGS` (idempotent)."""
    from gymnasium.envs.registration import register, registry

    for env_id, settings in ENV_SETTINGS.items():
        if env_id in registry:
            continue
        register(
            id=env_id,
            entry_point="pectoral_gym.envs.fish_env:PectoralFishEnv",
            vector_entry_point="pectoral_gym.envs.vector:PectoralFishVectorEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs=dict(settings),
        )
