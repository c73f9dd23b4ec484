"""One model definition: frozen specs of the full and the averaged model, their presets, the only factory.

A spec names every option of a model; ``spec.build(n, params)`` is the one way to build a batched
model from it, and the averaged spec loads its scaling-function (K) file (with
:func:`pectoral_gym.model.kloading.load_scaling`, the one K loader), with the check that the file was
identified for the same :class:`~pectoral_gym.model.params.FishParams`::

    from pectoral_gym.model.spec import AVERAGED_ENV, FULL_FAST
    model = AVERAGED_ENV.build(4)          # the averaged model as the registered envs use it
    fast = FULL_FAST.build(1, params)      # the full model's fast integration preset

Presets (module constants): :data:`FULL_REFERENCE` (= ``FullSpec()``), :data:`FULL_FAST`,
:data:`AVERAGED` (= ``AveragedSpec()``, the averaged model with both corrections, as the fidelity
benchmark measures it and the NMPC's spin turns plan on a full env), :data:`AVERAGED_ENV` (the
registered ``PectoralFish-Averaged-v0``), :data:`AVERAGED_PPO` (as ``agents/hyperparams/ppo.yml``
trains it) and :data:`AVERAGED_PAPER` (the paper's plain model). Specs round-trip through plain
dicts (:meth:`FullSpec.to_dict`, :func:`spec_from_dict`), which run folders record.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.kloading import (
    YAW_DAMPINGS,
    check_yaw_damping,
    held_yaw_damping,
    load_scaling,
    select_yaw_damping,
)
from pectoral_gym.model.models import FULL_INTEGRATION, AveragedModel, FullModel
from pectoral_gym.model.params import FishParams

__all__ = [
    "AVERAGED", "AVERAGED_ENV", "AVERAGED_PAPER", "AVERAGED_PPO", "ENV_DEFAULTS", "ENV_OPTIONS", "FORCINGS",
    "FULL_FAST", "FULL_REFERENCE", "MODELS", "PRESETS", "SCALINGS", "AveragedSpec", "FullSpec", "ModelSpec",
    "env_options", "env_spec", "make_model", "spec_from_dict",
]

MODELS = ("full", "averaged")
SCALINGS = ("identified", "none")  # besides the path of a coefficients file
FORCINGS = ("exact", "taylor")
#: The env settings (:class:`pectoral_gym.envs.core.EnvConfig` field names) of each model's spec.
ENV_OPTIONS = {"full": ("integration",),
               "averaged": ("scaling", "check_scaling_params", "transitions", "ripple_offsets", "fast_step")}
# The averaged model's configuration is written once, as AveragedModel's keyword defaults; AveragedSpec's
# defaults are read from there, and every preset below (and each env version) is AveragedSpec() with changes.
_AVERAGED_MODEL = {name: p.default for name, p in inspect.signature(AveragedModel).parameters.items()
                   if p.default is not inspect.Parameter.empty}


def _check_bool(name: str, value: Any) -> bool:
    if not isinstance(value, bool) and type(value).__name__ != "bool_":
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _check_dt(value: Any) -> float:
    try:
        dt = float(value)
    except (TypeError, ValueError):
        dt = math.nan
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt_max must be a finite number > 0 s, got {value!r}")
    return dt


class ModelSpec:
    """What both specs share: the model name, ``build``, ``to_dict``."""

    model: ClassVar[str]

    def build(self, n: int = 1, params: FishParams | Sequence[FishParams] | None = None):
        """The batched model of ``n`` fish (one :class:`FishParams`, one per fish, or ``None``: Table 1)."""
        raise NotImplementedError

    def scaling_functions(self, params: FishParams | None = None) -> ScalingFunctions | None:
        """The K the model uses (``None``: K = 1 or the full model); ``params`` for the parameter check."""
        return None

    def to_dict(self) -> dict[str, Any]:
        """Plain values (JSON/YAML): ``{"model": name, **fields}``; :func:`spec_from_dict` inverts it."""
        return {"model": self.model, **dataclasses.asdict(self)}

    def replace(self, **changes: Any):
        """A copy with ``changes`` (validated as a new spec)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class FullSpec(ModelSpec):
    """The blade-element model, eqs. (1)-(20), integrated through every fin beat.

    Attributes:
        integration: ``"reference"`` (converged steps) or ``"fast"`` (8 RK4 substeps per half-stroke,
            at most 0.05 s; :data:`pectoral_gym.model.models.FULL_INTEGRATION`; its speed and accuracy against
            the reference: docs/model.md section 6).
        dt_max: Largest RK4 substep [s]; ``None``: the integration preset's.
        min_substeps: Least substeps per half-stroke; ``None``: the integration preset's.
    """

    model: ClassVar[str] = "full"
    integration: str = "reference"
    dt_max: float | None = None
    min_substeps: int | None = None

    def __post_init__(self) -> None:
        if self.integration not in FULL_INTEGRATION:
            raise ValueError(f"integration must be one of {tuple(FULL_INTEGRATION)}, got {self.integration!r}")
        if self.dt_max is not None:
            object.__setattr__(self, "dt_max", _check_dt(self.dt_max))
        if self.min_substeps is not None:
            if isinstance(self.min_substeps, bool) or int(self.min_substeps) != self.min_substeps \
                    or self.min_substeps < 1:
                raise ValueError(f"min_substeps must be an integer >= 1, got {self.min_substeps!r}")
            object.__setattr__(self, "min_substeps", int(self.min_substeps))

    def build(self, n: int = 1, params: FishParams | Sequence[FishParams] | None = None) -> FullModel:
        """A :class:`~pectoral_gym.model.models.FullModel` of ``n`` fish."""
        return FullModel(n, params, dt_max=self.dt_max, min_substeps=self.min_substeps,
                         integration=self.integration)


@dataclass(frozen=True)
class AveragedSpec(ModelSpec):
    """The cycle-averaged model with scaled forcing, eq. (25) (:class:`~pectoral_gym.model.models.AveragedModel`).

    Attributes:
        scaling: The scaling functions K: ``"identified"`` (the shipped coefficients file), ``"none"``
            (K = 1) or the path of a coefficients file (``python -m pectoral_gym.scaling identify``).
        check_params: Refuse a coefficients file that records other model parameters than the
            ``params`` it is built for (K identified for another robot); ``False`` is the explicit opt-out.
        yaw_damping: ``"sinusoid"`` (the other presets') or ``"none"`` (eq. 20 alone: :data:`AVERAGED_PAPER`, K = 1)
            (:data:`~pectoral_gym.model.kloading.YAW_DAMPINGS`): the spec picks it, never the file: the
            file must hold the section it needs, and sections it does not use are dropped. K = 1 has
            none: ``scaling="none"`` needs ``"none"``.
        forcing: ``"exact"`` (closed-form Bessel averages) or ``"taylor"`` (the paper's eqs. 26-28, to
            reproduce the paper: :data:`AVERAGED_PAPER`).
        transitions: The forcing of transitional half-strokes (docs/model.md 3.7).
        ripple_offsets: The beat-mean ripple offset of a fin that starts, changes or parks a pattern
            (docs/model.md 3.8).
        dt_max: Largest RK4 step [s] (it also shrinks to stay inside RK4's stability limit).
        fast_step: The fast step (:mod:`pectoral_gym.model.fast_step`): numerically different, default off.
            Left out of :meth:`to_dict` when off, so the dicts of every spec without it are as before.
    """

    model: ClassVar[str] = "averaged"
    scaling: str = _AVERAGED_MODEL["scaling"]
    check_params: bool = True
    yaw_damping: str = "sinusoid"
    forcing: str = _AVERAGED_MODEL["forcing"]
    transitions: bool = _AVERAGED_MODEL["transitions"]
    ripple_offsets: bool = _AVERAGED_MODEL["ripple_offsets"]
    dt_max: float = _AVERAGED_MODEL["dt_max"]
    fast_step: bool = _AVERAGED_MODEL["fast_step"]

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if isinstance(self.scaling, os.PathLike):
            set_(self, "scaling", os.fspath(self.scaling))
        if not isinstance(self.scaling, str) or not self.scaling:
            raise ValueError(f"scaling must be 'identified', 'none' or a coefficients file path, got {self.scaling!r}")
        if self.scaling not in SCALINGS and not os.path.isfile(self.scaling):
            raise ValueError(f"scaling: no coefficients file at {self.scaling!r} (or use 'identified' or 'none')")
        if self.forcing not in FORCINGS:
            raise ValueError(f"forcing must be one of {FORCINGS}, got {self.forcing!r}")
        check_yaw_damping(self.yaw_damping)
        if self.scaling == "none" and self.yaw_damping != "none":
            raise ValueError(f"yaw_damping={self.yaw_damping!r} needs a coefficients file's "
                             f"{YAW_DAMPINGS[self.yaw_damping]} section; K = 1 (scaling='none') has none: "
                             "use yaw_damping='none'")
        for name in ("check_params", "transitions", "ripple_offsets", "fast_step"):
            set_(self, name, _check_bool(name, getattr(self, name)))
        set_(self, "dt_max", _check_dt(self.dt_max))

    def to_dict(self) -> dict[str, Any]:
        """As :meth:`ModelSpec.to_dict`, without ``fast_step`` when it is off (its default)."""
        data = super().to_dict()
        if not self.fast_step:
            del data["fast_step"]
        return data

    def scaling_functions(self, params: FishParams | None = None) -> ScalingFunctions | None:
        """The K of :attr:`scaling` with :attr:`yaw_damping`'s section only (``None`` for K = 1).

        Raises:
            ValueError: If ``check_params`` and the file records other parameters than ``params``
                (default: Table 1), or the file lacks the section :attr:`yaw_damping` needs.
        """
        if self.scaling == "none":
            return None
        return load_scaling(self.scaling, params if params is not None else FishParams(), self.check_params,
                            self.yaw_damping)

    def build(self, n: int = 1, params: FishParams | Sequence[FishParams] | None = None,
              k: ScalingFunctions | None = None) -> AveragedModel:
        """An :class:`~pectoral_gym.model.models.AveragedModel` of ``n`` fish; K checked against the first ``params``.

        ``k``: scaling functions already in memory (e.g. just identified by ``scaling/``), used instead of
        loading :attr:`scaling`, with :attr:`yaw_damping`'s section only.
        """
        if k is not None:
            k = select_yaw_damping(k, self.yaw_damping, "the given scaling functions")
        else:
            first = params[0] if isinstance(params, Sequence) and params else params
            k = self.scaling_functions(first)
        return AveragedModel(n, params, scaling=k, forcing=self.forcing,
                             dt_max=self.dt_max, transitions=self.transitions, ripple_offsets=self.ripple_offsets,
                             fast_step=self.fast_step)


#: The full model at converged steps (the spec class's defaults).
FULL_REFERENCE = FullSpec()
#: The full model's fast integration preset (8 substeps per half-stroke, at most 0.05 s).
FULL_FAST = FullSpec(integration="fast")
#: The averaged model with both corrections and the shipped K (the spec class's defaults; the
#: fidelity benchmark's candidate, the model of ``pectoral-fish simulate|steady``).
AVERAGED = AveragedSpec()
#: The averaged model as the registered ``PectoralFish-Averaged-v0`` runs it (the envs' default): the cycle
#: averages alone, without either correction.
AVERAGED_ENV = AVERAGED.replace(transitions=False, ripple_offsets=False)
#: The averaged model of ``PectoralFish-Averaged-v1``: with transitional strokes, without the ripple offsets.
#: ``PectoralFish-Averaged-v2``, which the PPO recipe trains on, runs :data:`AVERAGED` (both corrections).
AVERAGED_PPO = AVERAGED.replace(ripple_offsets=False)
#: The paper's plain model: eq. (25) with the Taylor forcing of eqs. 26-28, the shipped K and eq. (20)'s
#: yaw damping, without the corrections of docs/model.md 3.6-3.8.
AVERAGED_PAPER = AVERAGED_ENV.replace(yaw_damping="none", forcing="taylor")
PRESETS = {"full-reference": FULL_REFERENCE, "full-fast": FULL_FAST, "averaged": AVERAGED,
           "averaged-env": AVERAGED_ENV, "averaged-ppo": AVERAGED_PPO, "averaged-paper": AVERAGED_PAPER}
_CLASSES = {"full": FullSpec, "averaged": AveragedSpec}


def spec_from_dict(data: Mapping[str, Any] | str) -> FullSpec | AveragedSpec:
    """The spec of :meth:`ModelSpec.to_dict`'s dict, or of a preset name (:data:`PRESETS`).

    Raises:
        ValueError: For an unknown model, preset or field.
    """
    if isinstance(data, str):
        if data not in PRESETS:
            raise ValueError(f"unknown model preset {data!r}; presets: {sorted(PRESETS)}")
        return PRESETS[data]
    fields = dict(data)
    model = fields.pop("model", None)
    if model not in _CLASSES:
        raise ValueError(f"a model spec needs model = one of {MODELS}, got {model!r}")
    cls = _CLASSES[model]
    unknown = sorted(set(fields) - {f.name for f in dataclasses.fields(cls)})
    if unknown:
        raise ValueError(f"unknown {model} model options {unknown}; valid: {[f.name for f in dataclasses.fields(cls)]}")
    return cls(**fields)


# Another model's env options refused away from their defaults. A full env ignores the averaged model's
# transitions and ripple_offsets, as it always has (evaluations of averaged-trained policies on the full model
# pass them on), and check_scaling_params checks the K its model-based controllers plan with.
_STRICT = ("integration", "scaling")


def env_spec(model: str, **options: Any) -> FullSpec | AveragedSpec:
    """The spec of an env's model settings (:data:`ENV_OPTIONS`, named as :class:`~pectoral_gym.envs.core.EnvConfig`'s).

    The env's own defaults: :data:`FULL_REFERENCE` and :data:`AVERAGED_ENV`. An env's yaw damping is the
    richest the coefficients file holds (``"none"`` for K = 1; the returned spec names it): it is no env
    option (docs/model.md 3.6). ``integration`` and ``scaling`` are refused on the other model away from
    their env defaults; the full model ignores the averaged model's other options.

    Raises:
        ValueError: For an unknown model or option, or another model's option set away from its default.
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    defaults = ENV_DEFAULTS
    unknown = sorted(set(options) - set(defaults))
    if unknown:
        raise ValueError(f"unknown model options {unknown}; valid: {sorted(defaults)}")
    for name, value in options.items():
        if name not in ENV_OPTIONS[model] and name in _STRICT and value != defaults[name]:
            raise ValueError(f"{name} applies to the {'full' if model == 'averaged' else 'averaged'} model only; "
                             f"leave it at {defaults[name]!r} for model={model!r}")
    values = {**defaults, **options}
    if model == "full":
        return FullSpec(integration=values["integration"])
    scaling = os.fspath(values["scaling"]) if isinstance(values["scaling"], os.PathLike) else values["scaling"]
    return AVERAGED_ENV.replace(scaling=scaling, check_params=values["check_scaling_params"],
                                yaw_damping=_held_damping(scaling),
                                transitions=values["transitions"], ripple_offsets=values["ripple_offsets"],
                                fast_step=values["fast_step"])


def env_options(spec: FullSpec | AveragedSpec) -> dict[str, Any]:
    """The env settings (:data:`ENV_OPTIONS` of the spec's model) that name ``spec``: :func:`env_spec`'s inverse.

    Only for a spec an env can run (:func:`env_spec` of the result gives ``spec`` back); the averaged model's
    other fields (yaw damping, forcing, step) follow from these.
    """
    options = {"integration": spec.integration} if isinstance(spec, FullSpec) else {
        "scaling": spec.scaling, "check_scaling_params": spec.check_params, "transitions": spec.transitions,
        "ripple_offsets": spec.ripple_offsets, "fast_step": spec.fast_step}
    return options


#: The env settings' defaults (:class:`~pectoral_gym.envs.config.EnvConfig`'s): those of :data:`FULL_REFERENCE` and
#: :data:`AVERAGED_ENV`, the v0 ids' models.
ENV_DEFAULTS: dict[str, Any] = {**env_options(FULL_REFERENCE), **env_options(AVERAGED_ENV)}


def _held_damping(scaling: str) -> str:
    """The richest yaw damping a coefficients file holds (``"none"`` for K = 1 or a file with neither section)."""
    if scaling == "none" or (scaling != "identified" and not os.path.isfile(scaling)):
        return "none"  # a missing file is reported by AveragedSpec
    return held_yaw_damping(ScalingFunctions.load(None if scaling == "identified" else scaling))


def make_model(model: str | ModelSpec = "averaged", n: int = 1, params: FishParams | None = None,
               scaling: ScalingFunctions | str | os.PathLike | None = "spec", forcing: str | None = None):
    """Thin alias over the specs: ``spec.build(n, params)`` of a spec or a name, with the K or forcing replaced.

    Args:
        model: A spec, a preset name (:data:`PRESETS`), ``"full"`` (:data:`FULL_REFERENCE`) or
            ``"averaged"`` (:data:`AVERAGED`).
        n: Number of fish.
        params: Model parameters (default: Table 1).
        scaling: Averaged model only, replacing the spec's K: ``"identified"``, ``"none"`` (K = 1), a
            coefficients file, :class:`ScalingFunctions` in memory (its richest yaw damping), ``None``
            (K = 1, as in :class:`~pectoral_gym.model.models.AveragedModel`) or ``"spec"`` (default: the spec's).
            Ignored by the full model, as ``forcing`` is.
        forcing: Averaged model only: ``"exact"`` or ``"taylor"``; ``None`` keeps the spec's.

    Raises:
        ValueError: For an unknown model name or option.
    """
    if isinstance(model, ModelSpec):
        spec = model
    elif model in MODELS:
        spec = FULL_REFERENCE if model == "full" else AVERAGED
    else:
        spec = spec_from_dict(model)
    if not isinstance(spec, AveragedSpec):
        return spec.build(n, params)
    if forcing is not None:
        spec = spec.replace(forcing=forcing)
    if isinstance(scaling, ScalingFunctions):
        return spec.replace(yaw_damping=held_yaw_damping(scaling)).build(n, params, k=scaling)
    if scaling is None:
        spec = spec.replace(scaling="none", yaw_damping="none")
    elif scaling != "spec":
        path = os.fspath(scaling)
        spec = spec.replace(scaling=path, yaw_damping=_held_damping(path))
    return spec.build(n, params)
