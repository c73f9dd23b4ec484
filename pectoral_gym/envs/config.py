"""Settings of the fish environments: :class:`EnvConfig`, validated once, and the envs' signature.

One dataclass holds every setting of the single, the vector and the robot environment (its
defaults are written once: :func:`env_signature` shows them in the envs' ``help()``). It checks
its values when built, resolves the model settings to one spec (:meth:`EnvConfig.model_spec`) and
packs the task settings for the kernels (:meth:`EnvConfig.cfg_array`; the layout:
:mod:`pectoral_gym.envs.layout`). :class:`~pectoral_gym.envs.core.EnvCore` runs the envs on it.
Nothing here imports Gymnasium.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.envs.tasks.table import TASK_IDS
from pectoral_gym.envs.timing import TimingConfig
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams, as_params
from pectoral_gym.model.servo import servo_period
from pectoral_gym.model.spec import ENV_DEFAULTS, ENV_OPTIONS, MODELS, AveragedSpec, FullSpec, env_spec
from pectoral_gym.model.tank import TANK_WIDTH, StopRule
from pectoral_gym.sensing.camera import SensingConfig
from pectoral_gym.versions import SIMULATION, RobotReadiness, latest_settings

__all__ = ["EnvConfig", "MODELS", "TASKS", "env_signature"]

# name -> cfg[C_TASK] id of every task in the task table (a live view: registered tasks appear here).
TASKS = TASK_IDS
_FIELD_NAMES = tuple(f.name for f in dataclasses.fields(FishParams))
_OTHER = {"full": "averaged", "averaged": "full"}


def _check_range(name: str, value: Sequence[float], positive: bool = False, nonnegative: bool = False):
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low, high) of numbers, got {value!r}") from None
    if not (math.isfinite(low) and math.isfinite(high)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if low > high:
        raise ValueError(f"{name} needs low <= high, got {value!r}")
    if positive and low <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if nonnegative and low < 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return low, high


@dataclass(frozen=True)
class EnvConfig:
    """Validated settings of a fish environment (see :class:`~pectoral_gym.envs.fish_env.PectoralFishEnv`).

    Attributes:
        model: ``"full"`` (blade-element) or ``"averaged"`` (cycle-averaged, scaled).
        task: ``"goal"`` (reach a point), ``"track"`` (follow a point moving on an ellipse), or a task
            added to the task table (:func:`pectoral_gym.envs.tasks.table.register_task`).
        control_period: Time between actions [s].
        bias_range: ``(low, high)`` of the fin bias ``gamma_0`` [rad].
        amplitude_range: ``(low, high)`` of the fin amplitude ``gamma_A`` [rad].
        period_range: ``(low, high)`` of the fin-beat period ``T_p`` [s].
        ratio_range: ``(low, high)`` of the speed ratio ``zeta`` [-].
        params: Nominal model parameters: a :class:`FishParams`, a dict of its fields, the path of a
            parameters file (:func:`pectoral_gym.model.params.load_params`), or ``None`` (Table 1); stored
            as a ``FishParams``.
        randomize: FishParams field name -> relative half-width ``w``; each
            reset multiplies the field by a factor drawn from ``U(1-w, 1+w)``.
        scaling: Averaged model only: ``"identified"`` (the shipped coefficients file), ``"none"``
            (K = 1), or the path of a coefficients file (``python -m pectoral_gym.scaling identify``).
        check_scaling_params: Averaged model only: raise ``ValueError`` when the coefficients file
            records other model parameters than ``params`` (K identified for another robot).
            ``False`` is the explicit opt-out. ``randomize`` draws around ``params`` and is not checked.
            On the full model: the check of the K its model-based controllers plan with
            (:func:`pectoral_gym.agents.controllers.fin_map.planning_spec`).
        transitions: Averaged model only: add the forcing of transitional half-strokes (after every
            pattern change; :class:`~pectoral_gym.model.models.AveragedModel`, ``docs/model.md`` 3.7). Off by
            default in the envs, unlike the model: it depends on the fins' stroke phase, which the default
            observation does not show; use it with ``observe_fins=True``, as the shipped PPO file does
            (alone it did far worse: full-model success 0.36-0.68; with both 0.98-1.00;
            docs/notes/2026-12-02-ppo-v0-tuning.md).
        ripple_offsets: Averaged model only: the beat-mean ripple offset of a fin that starts,
            changes or parks a pattern (:class:`~pectoral_gym.model.models.AveragedModel`, ``docs/model.md``
            3.8; on by default in the model). Off by default in the envs (``-v0``, ``-v1``); on in
            ``PectoralFish-Averaged-v2``, which the PPO recipe trains on.
        fast_step: Averaged model only: its fast step (:mod:`pectoral_gym.model.fast_step`: the yaw damping's
            stiffness integrated exactly, bounded-range function approximations), numerically different from the
            default step and about 1.6x faster (``docs/model.md`` section 6). Off by default and in every registered
            id: ``gym.make("PectoralFish-Averaged-v2", fast_step=True)``.
        integration: Full model only: ``"reference"`` (converged steps) or ``"fast"`` (8 RK4 substeps
            per half-stroke, at most 0.05 s; :data:`~pectoral_gym.model.models.FULL_INTEGRATION`; its speed
            and accuracy against the reference: ``docs/model.md`` section 6).

    The model settings (``model`` and the ``ENV_OPTIONS`` above) resolve to one spec,
    :meth:`model_spec` (:func:`pectoral_gym.model.spec.env_spec`, which also refuses another model's
    option set away from its default); the env builds its model from it and nothing else. Its yaw
    damping is the richest the coefficients file holds (``"none"`` for ``scaling="none"``; ``docs/model.md`` 3.6).
        observe_fins: Append each fin's half-stroke in progress to the observation (angle now, the next
            turning point, power or recovery, time left; :mod:`pectoral_gym.envs.observation`): the
            stroke phase on which a new command's effect depends. Off by default (the 19-entry
            observation); the robot env replays the fins on the PC (``pectoral_gym.model.finreplay``).
        progress_weight: Goal task: reward per metre of approach [1/m].
        goal_bonus: Goal task: reward for reaching the goal.
        wall_penalty: Penalty when the nose or tail leaves the tank.
        energy_weight: Penalty per joule of fin work [1/J].
        time_penalty: Goal task: penalty per step.
        tracking_weight: Track task: penalty per metre of distance, per step [1/m].
        goal_radius: Goal task: success radius [m].
        ref_speed: Track task: speed of the reference point [m/s].
        start_inset: Goal task: least distance of a start position from the walls [m].
        goal_inset: Goal task: least distance of a goal from the walls [m].
        stop_band: End the episode, with the ``wall_penalty`` and a per-step ``info["cost"]`` of 1 (the
            Safety-Gymnasium convention; 0 otherwise), when any part of the fish (body and fin tips) is
            closer to a wall than it needs to stop: the robot's geofence, whose safety supervisor stops the
            fish there (:data:`pectoral_gym.model.tank.ROBOT_STOP_RULE`, ``docs/guide/safety.md``). Checked on the
            state after each control period.
        stop_rule: The band's :class:`~pectoral_gym.model.tank.StopRule` (margin [m], reaction time [s], contact
            speed [m/s]); also given as ``(margin, reaction_time, contact_speed)`` or a mapping of them.
        servo_limit: Fastest fin rate [rad/s] (``None``: no limit): a commanded pattern whose faster
            half-stroke peaks above it runs with its period lengthened, as the robot's firmware runs it
            (:func:`pectoral_gym.model.servo.servo_period`; the robot's value:
            :data:`~pectoral_gym.model.servo.ROBOT_MAX_FIN_RATE`).
        sensing: Observe through a simulated camera and the robot's high-gain observer
            (:mod:`pectoral_gym.envs.sensed`): ``None`` (off: the observation is the true state, its velocities
            the exact means over the period), ``True`` or ``{}`` (the defaults), or a mapping of
            :class:`~pectoral_gym.sensing.camera.SensingConfig` fields (frame rate, per-episode ranges of pose
            noise, frame drops and latency, the observer's ``epsilon``); stored as a ``SensingConfig``. The
            reward, the termination and ``info`` stay on the true state. Latencies must stay below
            ``control_period``.
        timing: The robot's control-loop timing (:mod:`pectoral_gym.envs.timing`): ``None`` (off: each command
            acts at once, every period lasts ``control_period``), ``True`` or ``{}`` (the defaults), or a mapping
            of :class:`~pectoral_gym.envs.timing.TimingConfig` fields: each command reaches the fins after a
            delay (an episode level plus a per-step jitter) and each observation comes a little after its tick;
            stored as a ``TimingConfig``. The longest delay must stay below the shortest period.
    """

    model: str = "full"
    task: str = "goal"
    control_period: float = 0.5
    bias_range: tuple[float, float] = (math.radians(45.0), math.radians(135.0))
    amplitude_range: tuple[float, float] = (0.0, math.radians(30.0))
    period_range: tuple[float, float] = (0.5, 2.0)
    ratio_range: tuple[float, float] = (1.0, 5.0)
    params: FishParams | Mapping[str, float] | str | os.PathLike | None = None
    randomize: Mapping[str, float] | None = field(default=None, hash=False)
    # The model's and the robot readiness's defaults are written in their own homes (the v0 ids' settings).
    scaling: str | os.PathLike = ENV_DEFAULTS["scaling"]
    check_scaling_params: bool = ENV_DEFAULTS["check_scaling_params"]
    transitions: bool = ENV_DEFAULTS["transitions"]
    ripple_offsets: bool = ENV_DEFAULTS["ripple_offsets"]
    integration: str = ENV_DEFAULTS["integration"]
    fast_step: bool = ENV_DEFAULTS["fast_step"]
    observe_fins: bool = SIMULATION.observe_fins
    progress_weight: float = 10.0
    goal_bonus: float = 10.0
    wall_penalty: float = 10.0
    energy_weight: float = 1.0
    time_penalty: float = 0.01
    tracking_weight: float = 1.0
    goal_radius: float = 0.08
    ref_speed: float = 0.03
    start_inset: float = tk.START_INSET
    goal_inset: float = SIMULATION.goal_inset
    stop_band: bool = SIMULATION.stop_band
    stop_rule: StopRule = SIMULATION.stop_rule
    servo_limit: float | None = SIMULATION.servo_limit
    sensing: SensingConfig | Mapping[str, Any] | bool | None = None
    timing: TimingConfig | Mapping[str, Any] | bool | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {tuple(TASKS)}, got {self.task!r}")
        if isinstance(self.scaling, os.PathLike):
            set_(self, "scaling", os.fspath(self.scaling))
        for name in ("check_scaling_params", "transitions", "ripple_offsets", "fast_step", "observe_fins", "stop_band"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        # The one check of the model options (applicability included): the spec's.
        set_(self, "_spec", env_spec(self.model, **{name: getattr(self, name) for name in ENV_OPTIONS[self.model]},
                                     **{name: getattr(self, name) for name in ENV_OPTIONS[_OTHER[self.model]]}))
        try:
            period = float(self.control_period)
        except (TypeError, ValueError):
            period = math.nan
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"control_period must be a finite number > 0 s, got {self.control_period!r}")
        set_(self, "control_period", period)
        set_(self, "bias_range", _check_range("bias_range", self.bias_range))
        set_(self, "amplitude_range", _check_range("amplitude_range", self.amplitude_range, nonnegative=True))
        set_(self, "period_range", _check_range("period_range", self.period_range, positive=True))
        set_(self, "ratio_range", _check_range("ratio_range", self.ratio_range, positive=True))
        amp_max = self.amplitude_range[1]
        if self.bias_range[0] - amp_max < 0 or self.bias_range[1] + amp_max > math.pi:
            raise ValueError(
                f"bias_range {self.bias_range} with amplitudes up to {amp_max:.4g} rad lets the stroke leave "
                "[0, pi] rad (the fin would pass through the body); narrow bias_range or amplitude_range"
            )
        for name in ("progress_weight", "goal_bonus", "wall_penalty", "energy_weight", "time_penalty",
                     "tracking_weight", "ref_speed", "goal_radius"):
            value = getattr(self, name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if not (math.isfinite(number) and number >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
            set_(self, name, number)
        for name in ("start_inset", "goal_inset"):
            inset = getattr(self, name)
            if not (isinstance(inset, (int, float)) and 0 <= inset < 0.5 * TANK_WIDTH - 0.01):
                raise ValueError(f"{name} must be a number in [0, {0.5 * TANK_WIDTH - 0.01:.3f}) m, got {inset!r}")
            set_(self, name, float(inset))
        try:
            set_(self, "stop_rule", StopRule.coerce(self.stop_rule))  # the rule checks itself
        except ValueError as err:
            raise ValueError(f"stop_rule: {err}") from None
        if self.servo_limit is not None:
            limit = self.servo_limit
            if not (isinstance(limit, (int, float)) and math.isfinite(limit) and limit > 0):
                raise ValueError(f"servo_limit must be None or a finite fin rate > 0 rad/s, got {limit!r}")
            set_(self, "servo_limit", float(limit))
        set_(self, "params", as_params(self.params))
        set_(self, "sensing", SensingConfig.coerce(self.sensing))
        if self.sensing is not None and self.sensing.latency[1] >= self.control_period:
            raise ValueError(f"sensing['latency'] must stay below the control period {self.control_period} s, got "
                             f"{self.sensing.latency}")
        set_(self, "timing", TimingConfig.coerce(self.timing))
        if self.timing is not None:
            self.timing.check_period(self.control_period)
        if self.randomize is not None:
            randomize = dict(self.randomize)
            unknown = sorted(set(randomize) - set(_FIELD_NAMES))
            if unknown:
                raise ValueError(f"randomize: unknown FishParams fields {unknown}; valid names: {list(_FIELD_NAMES)}")
            for name, width in randomize.items():
                if not (isinstance(width, (int, float)) and math.isfinite(width) and 0 <= width < 1):
                    raise ValueError(f"randomize[{name!r}] must be a relative half-width in [0, 1), got {width!r}")
            set_(self, "randomize", randomize or None)

    def model_spec(self) -> FullSpec | AveragedSpec:
        """The model these settings name (:mod:`pectoral_gym.model.spec`).

        :class:`~pectoral_gym.envs.core.EnvCore` builds its model from this and nothing else.
        """
        return self._spec

    @classmethod
    def recommended(cls, **settings: Any) -> EnvConfig:
        """The settings of the latest id of ``settings["model"]`` (default ``"full"``) with ``settings`` on top.

        What the env classes build when constructed directly (not through an id): a version's settings
        (:data:`pectoral_gym.versions.LATEST`), not this class's own defaults, which are the v0 ids'.

        Raises:
            ValueError: For an unknown model or an invalid setting.
        """
        model = settings.get("model", cls.model)
        if model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {model!r}")
        return cls(**{**latest_settings(model), **settings})

    def robot_readiness(self) -> RobotReadiness:
        """The settings that prepare a policy for the robot stack (:class:`pectoral_gym.versions.RobotReadiness`)."""
        return RobotReadiness(self.observe_fins, self.stop_band, self.stop_rule, self.servo_limit, self.goal_inset)

    def scaling_functions(self) -> ScalingFunctions | None:
        """The averaged model's scaling functions (``None`` for K = 1 or the full model), checked against ``params``.

        Raises:
            ValueError: If ``check_scaling_params`` and the file records other parameters than ``params``.
        """
        return self._spec.scaling_functions(self.params)

    @property
    def task_id(self) -> int:
        """``cfg[C_TASK]``: ``tasks.GOAL``, ``tasks.TRACK`` or a registered task's id."""
        return TASKS[self.task]

    @property
    def ranges(self) -> np.ndarray:
        """``(4, 2)``: (low, high) of bias [rad], amplitude [rad], period [s], ratio [-]."""
        return np.array([self.bias_range, self.amplitude_range, self.period_range, self.ratio_range])

    def cfg_array(self) -> np.ndarray:
        """Pack the settings for the kernels of :mod:`~pectoral_gym.envs.tasks.kernels`."""
        cfg = np.zeros(tk.N_CFG)
        cfg[tk.C_DT] = self.control_period
        cfg[tk.C_TASK] = self.task_id
        cfg[tk.C_RANGES:tk.C_RANGES + 8] = self.ranges.ravel()
        cfg[tk.C_W_PROGRESS] = self.progress_weight
        cfg[tk.C_GOAL_BONUS] = self.goal_bonus
        cfg[tk.C_WALL] = self.wall_penalty
        cfg[tk.C_W_ENERGY] = self.energy_weight
        cfg[tk.C_TIME] = self.time_penalty
        cfg[tk.C_W_TRACKING] = self.tracking_weight
        cfg[tk.C_GOAL_RADIUS] = self.goal_radius
        cfg[tk.C_REF_SPEED] = self.ref_speed
        cfg[tk.C_START_INSET] = self.start_inset
        cfg[tk.C_GOAL_INSET] = self.goal_inset
        cfg[tk.C_BAND] = 1.0 if self.stop_band else 0.0
        cfg[tk.C_BAND_MARGIN:tk.C_BAND_CONTACT + 1] = self.stop_rule.as_tuple()
        cfg[tk.C_FIN_RATE] = 0.0 if self.servo_limit is None else self.servo_limit
        return cfg

    def encode(self, beat: np.ndarray) -> np.ndarray:
        """Normalised action entries of one fin pattern ``(bias, amplitude, period, ratio)``, clipped to [-1, 1]."""
        r = self.ranges
        width = r[:, 1] - r[:, 0]
        code = np.where(width > 0, 2.0 * (np.asarray(beat) - r[:, 0]) / np.where(width > 0, width, 1.0) - 1.0, 0.0)
        return np.clip(code, -1.0, 1.0)

    def decode(self, code: np.ndarray) -> np.ndarray:
        """Fin pattern(s) ``(..., 4)`` of normalised action entries ``(..., 4)``: the env's own action mapping.

        Entries are clipped to [-1, 1] and mapped linearly onto the ranges, as
        :func:`pectoral_gym.envs.tasks.kernels.apply_actions` does, then, with ``servo_limit``, the period
        lengthened as the servos run the pattern (:func:`pectoral_gym.model.servo.servo_period`);
        ``decode(encode(beat))`` returns ``beat`` for a pattern inside the ranges (and the servo limit).
        """
        r = self.ranges
        x = np.clip(np.asarray(code, dtype=np.float64), -1.0, 1.0)
        beat = np.minimum(r[:, 0] + 0.5 * (x + 1.0) * (r[:, 1] - r[:, 0]), r[:, 1])
        if self.servo_limit is not None:
            beat[..., 2] = servo_period(beat[..., 1], beat[..., 2], beat[..., 3], self.servo_limit)
        return beat


def env_signature(*parameters: inspect.Parameter) -> inspect.Signature:
    """``(self, *parameters, *EnvConfig's fields)``: an env's signature, the settings keyword-only with their defaults.

    The envs take the settings as ``**kwargs`` and forward them to :class:`EnvConfig`, so
    its defaults are written once; this signature shows them in ``help()`` and ``inspect``.
    """
    settings = [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default, annotation=f.type)
                for f in dataclasses.fields(EnvConfig)]
    return inspect.Signature([inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD), *parameters,
                              *settings])
