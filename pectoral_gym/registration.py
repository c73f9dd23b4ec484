"""Registration of the Gymnasium ids (entry points by string, so importing stays cheap).

Each id names one configuration (:data:`ENV_SETTINGS`), used by ``gym.make``, ``gym.make_vec`` and every
tool that takes an env id (training, evaluation, the baselines' and the NMPC's model, the benchmark, the
robot env): :func:`registered_settings` is the one way from an id to its settings.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pectoral_gym.model.servo import ROBOT_MAX_FIN_RATE
from pectoral_gym.model.tank import ROBOT_STOP_RULE

#: Clearance [m] the v1 envs' band keeps on top of the robot's rule: the robot's supervisor judges the band on a
#: least-squares speed from camera poses plus 2 standard errors (>= 2 x 5 mm / 1.58 s = 6.3 mm/s over its 1 s
#: window), which widens the band by up to 2 sigma (t_r + 1 / (k v_c)) = 3.3 cm at the camera's noise floor (near
#: the contact speed v_c, where the need grows fastest with speed), and more with the in-beat swing of the pose;
#: and the envs check the band after each control period, the robot every frame (``docs/guide/envs.md``,
#: "Versions").
MEASUREMENT_MARGIN = 0.05

__all__ = ["ENV_IDS", "ENV_SETTINGS", "MAX_EPISODE_STEPS", "MEASUREMENT_MARGIN", "ROBOT_READY", "register_envs",
           "registered_settings"]

#: What the v1 envs add to prepare a policy for the robot stack (``PectoralFishEnv``'s Version History): the
#: fins' stroke phase observed, the robot's stopping band as an episode end with a cost, the servos' rate
#: limit, goals the band leaves reachable (``docs/guide/envs.md``, "Versions").
ROBOT_READY: dict[str, Any] = {
    "observe_fins": True, "stop_band": True, "servo_limit": ROBOT_MAX_FIN_RATE, "goal_inset": 0.3,
    "stop_rule": ROBOT_STOP_RULE._replace(margin=ROBOT_STOP_RULE.margin + MEASUREMENT_MARGIN),
}

_FULL_V1 = {"model": "full", "integration": "fast", **ROBOT_READY}
_AVERAGED_V1 = {"model": "averaged", "transitions": True, **ROBOT_READY}

#: id -> the EnvConfig arguments it stands for (the others keep EnvConfig's defaults).
ENV_SETTINGS: dict[str, dict[str, Any]] = {
    "PectoralFish-Full-v0": {"model": "full"},
    "PectoralFish-Averaged-v0": {"model": "averaged"},
    "PectoralFish-Full-v1": dict(_FULL_V1),
    "PectoralFish-Averaged-v1": dict(_AVERAGED_V1),
    # v2: the averaged model with both of its corrections (the model's own defaults, docs/model.md 3.7-3.8); the
    # full id moves with it unchanged, so the two ids of a version go together (train on one, evaluate on the other).
    "PectoralFish-Full-v2": dict(_FULL_V1),
    "PectoralFish-Averaged-v2": {**_AVERAGED_V1, "ripple_offsets": True},
}
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
