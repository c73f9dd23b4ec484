"""The env versions: one frozen configuration per registered id, in one table, and the latest id of each model.

An id's configuration is an :class:`EnvVersion`: a model spec (:mod:`pectoral_gym.model.spec`, whose presets
derive from the averaged model's own defaults) and a :class:`RobotReadiness` (what prepares a policy for the
robot stack: the fins' stroke phase observed, the robot's stopping band as an episode end with its rule, the
servos' rate limit, goals the band leaves reachable). Every other setting is
:class:`~pectoral_gym.envs.config.EnvConfig`'s default, the same for every id. :data:`ENV_VERSIONS` is the one
table; :mod:`pectoral_gym.registration` registers it, and :data:`LATEST` names the id every tool, recipe and
example uses by default::

    import gymnasium as gym
    from pectoral_gym.versions import LATEST_AVERAGED
    env = gym.make(LATEST_AVERAGED)

Nothing here imports Gymnasium or the envs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from pectoral_gym.model.servo import ROBOT_MAX_FIN_RATE
from pectoral_gym.model.spec import (
    AVERAGED,
    AVERAGED_ENV,
    AVERAGED_PPO,
    ENV_DEFAULTS,
    FULL_FAST,
    FULL_REFERENCE,
    AveragedSpec,
    FullSpec,
    env_options,
)
from pectoral_gym.model.tank import ROBOT_STOP_RULE, StopRule

__all__ = ["ENV_VERSIONS", "LATEST", "LATEST_AVERAGED", "LATEST_FULL", "MEASUREMENT_MARGIN", "ROBOT", "SIMULATION",
           "SIMULATION_IDS", "EnvVersion", "RobotReadiness", "latest_settings", "with_measurement_margin"]

#: Clearance [m] the robot-ready envs' band keeps on top of the robot's rule: the robot's supervisor judges the band
#: on a least-squares speed from camera poses plus 2 standard errors (>= 2 x 5 mm / 1.58 s = 6.3 mm/s over its 1 s
#: window), which widens the band by up to 2 sigma (t_r + 1 / (k v_c)) = 3.3 cm at the camera's noise floor (near
#: the contact speed v_c, where the need grows fastest with speed), and more with the in-beat swing of the pose;
#: and the envs check the band after each control period, the robot every frame (``docs/guide/envs.md``,
#: "Versions").
MEASUREMENT_MARGIN = 0.05


def with_measurement_margin(rule: StopRule) -> StopRule:
    """``rule`` with :data:`MEASUREMENT_MARGIN` added to its margin.

    The band the robot-ready envs keep for a robot whose supervisor judges ``rule``: the one place the margin is
    added (:data:`ROBOT`'s band, and the robot stack's controllers' band around the deploy's geofence).
    """
    return dataclasses.replace(rule, margin=rule.margin + MEASUREMENT_MARGIN)


@dataclass(frozen=True)
class RobotReadiness:
    """The settings that prepare a policy for the robot stack (``docs/guide/envs.md``, "Versions").

    Attributes:
        observe_fins: Observe each fin's half-stroke in progress (the stroke phase a new command's effect depends on).
        stop_band: End the episode, with a cost, inside the robot's stopping band.
        stop_rule: The band's :class:`~pectoral_gym.model.tank.StopRule`.
        servo_limit: Fastest fin rate [rad/s] (``None``: no limit).
        goal_inset: Least distance of a goal from the walls [m].
    """

    observe_fins: bool
    stop_band: bool
    stop_rule: StopRule
    servo_limit: float | None
    goal_inset: float

    def settings(self) -> dict[str, Any]:
        """The :class:`~pectoral_gym.envs.config.EnvConfig` arguments these stand for (same names)."""
        return {"observe_fins": self.observe_fins, "stop_band": self.stop_band, "stop_rule": self.stop_rule,
                "servo_limit": self.servo_limit, "goal_inset": self.goal_inset}


#: A simulation-only env (the v0 ids, and :class:`~pectoral_gym.envs.config.EnvConfig`'s defaults): the 19-entry
#: observation, no stopping band (its rule the robot's, unused), no servo limit, goals 0.2 m from the walls.
SIMULATION = RobotReadiness(observe_fins=False, stop_band=False, stop_rule=ROBOT_STOP_RULE, servo_limit=None,
                            goal_inset=0.2)
#: The robot-ready envs (v1 on): the fins observed, the robot's band with :data:`MEASUREMENT_MARGIN` more margin,
#: the robot's servo rate, goals 0.3 m from the walls (ones the band leaves reachable).
ROBOT = RobotReadiness(observe_fins=True, stop_band=True,
                       stop_rule=with_measurement_margin(ROBOT_STOP_RULE),
                       servo_limit=ROBOT_MAX_FIN_RATE, goal_inset=0.3)


# The spec fields an env sets (EnvConfig's model options, by their spec names).
_OPTION_FIELDS = {"integration", "scaling", "check_params", "transitions", "ripple_offsets", "fast_step"}


@dataclass(frozen=True)
class EnvVersion:
    """One registered id's configuration: its model spec and its robot readiness.

    Attributes:
        model: The model spec, one an env can run (:func:`~pectoral_gym.model.spec.env_spec` of its options
            gives it back).
        robot: The robot-readiness settings.
        same_as: The id this one is identical to, when a version moved on without changing this model (the two
            ids of a version go together: train on one, evaluate on the other); ``None`` otherwise.
    """

    model: FullSpec | AveragedSpec
    robot: RobotReadiness
    same_as: str | None = None

    def __post_init__(self) -> None:
        # Cheap (no K file read at import): the fields an env does not set must be its default preset's, as
        # env_spec resolves them (the test of the table checks the whole spec through env_spec).
        base = FULL_REFERENCE if isinstance(self.model, FullSpec) else AVERAGED_ENV
        fixed = {f.name for f in dataclasses.fields(base)} - _OPTION_FIELDS
        if any(getattr(self.model, name) != getattr(base, name) for name in fixed):
            raise ValueError(f"{self.model!r} is not a model an env runs: only {sorted(_OPTION_FIELDS)} may differ "
                             f"from {base!r}")

    def settings(self) -> dict[str, Any]:
        """Every :class:`~pectoral_gym.envs.config.EnvConfig` argument a version sets (the rest are its defaults).

        Both models' options (the other model's at their defaults), so that the arguments alone name the version,
        whatever defaults they are applied on (:meth:`~pectoral_gym.envs.config.EnvConfig.recommended`).
        """
        return {"model": self.model.model, **ENV_DEFAULTS, **env_options(self.model), **self.robot.settings()}


_FULL_V1 = EnvVersion(FULL_FAST, ROBOT)

#: id -> its configuration: the one table of the registered ids (read-only).
ENV_VERSIONS: MappingProxyType[str, EnvVersion] = MappingProxyType({
    "PectoralFish-Full-v0": EnvVersion(FULL_REFERENCE, SIMULATION),
    "PectoralFish-Averaged-v0": EnvVersion(AVERAGED_ENV, SIMULATION),
    # v1: robot-ready; the full model's fast integration, the averaged model with its transitional strokes.
    "PectoralFish-Full-v1": _FULL_V1,
    "PectoralFish-Averaged-v1": EnvVersion(AVERAGED_PPO, ROBOT),
    # v2: the averaged model with both of its corrections (the model's own defaults, docs/model.md 3.7-3.8). The
    # full model did not change: its v2 is its v1, registered so that the two ids of a version go together.
    "PectoralFish-Full-v2": EnvVersion(_FULL_V1.model, _FULL_V1.robot, same_as="PectoralFish-Full-v1"),
    "PectoralFish-Averaged-v2": EnvVersion(AVERAGED, ROBOT),
})
for _env_id, _version in ENV_VERSIONS.items():  # the relations the names state hold
    if _version.same_as is not None and ENV_VERSIONS[_version.same_as].settings() != _version.settings():
        raise AssertionError(f"{_env_id} is declared the same as {_version.same_as} but its settings differ")

#: model -> its recommended id: the default of every tool, recipe and example.
LATEST: MappingProxyType[str, str] = MappingProxyType({"full": "PectoralFish-Full-v2",
                                                       "averaged": "PectoralFish-Averaged-v2"})
LATEST_FULL = LATEST["full"]
LATEST_AVERAGED = LATEST["averaged"]
#: model -> its simulation-only id (:data:`SIMULATION`: no stopping band ends an episode, no servo limit): for the
#: studies that check the band themselves and for the measurements recorded on it (the env throughput, the NMPC's
#: development rounds), never a tool's default for training or evaluation.
SIMULATION_IDS: MappingProxyType[str, str] = MappingProxyType({"full": "PectoralFish-Full-v0",
                                                               "averaged": "PectoralFish-Averaged-v0"})


def latest_settings(model: str) -> dict[str, Any]:
    """The settings of :data:`LATEST`'s id of ``model`` (``"full"`` or ``"averaged"``).

    Raises:
        ValueError: For another model name.
    """
    if model not in LATEST:
        raise ValueError(f"model must be one of {tuple(LATEST)}, got {model!r}")
    return ENV_VERSIONS[LATEST[model]].settings()
for _model, _env_id in {**LATEST, **SIMULATION_IDS}.items():
    if ENV_VERSIONS[_env_id].model.model != _model:
        raise AssertionError(f"{_env_id} is not a {_model} model id")
if any(ENV_VERSIONS[_env_id].robot != SIMULATION for _env_id in SIMULATION_IDS.values()):
    raise AssertionError("a simulation-only id is robot-ready")
