"""Model parameters and fin-beat patterns.

One frozen :class:`FishParams` feeds every model in the project (full, averaged,
the NMPC in ``scaling/``, the emulator in ``hardware/``). Defaults are Table 1
of the reference paper with the errata of ``docs/model.md`` applied.

All quantities are SI: metres, kilograms, seconds, radians.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pectoral_gym.inputfile import SMALL_FILE_BYTES, load_json, read_text
from pectoral_gym.model.tank import (  # re-exported: the tank's one home is pectoral_gym.model.tank
    TANK_LENGTH,
    TANK_WIDTH,
)

__all__ = [
    "FishParams", "FinBeat", "COEF_NAMES", "Coef", "BodyCoefficients", "TANK_LENGTH", "TANK_WIDTH",
    "coefficient_vector", "body_coefficients", "params_from_dict", "load_params", "save_params", "as_params",
    "params_dict", "PARAMS_FIELDS", "PER_FIN_DEFAULTS", "FIN_FORCE_SCALE", "FIN_ANGLE_OFFSET", "FIN_ANGLE_SCALE",
]


@dataclass(frozen=True)
class FishParams:
    """Physical parameters of the robotic fish (Table 1 of the paper).

    The added masses and inertia are stored with the paper's sign convention:
    Table 1 lists ``-m_ax = 0.095 kg``, so ``added_mass_x = -0.095`` and
    ``m1 = body_mass - added_mass_x = 0.89 kg`` (eq. 20).

    Attributes:
        body_mass: Body mass ``m_b`` [kg].
        body_inertia: Body yaw inertia ``J_bz`` [kg m^2]. Table value; the
            ellipsoid formula of Sec. 4.2 does not reproduce it (erratum 5).
        added_mass_x: Hydrodynamic derivative ``m_ax`` along x [kg], negative.
        added_mass_y: Hydrodynamic derivative ``m_ay`` along y [kg], negative.
        added_inertia: Added yaw inertia ``J_az`` [kg m^2], negative (Table 1
            prints the unit as kg/m^2, a typo).
        wetted_area: Wetted surface area ``S_A`` [m^2]. Table 1 prints 0.325;
            the paper's own speeds need 0.0325 (erratum 1).
        drag_coef: Body drag coefficient ``C_D`` [-].
        lift_coef: Body lift coefficient ``C_L`` [1/rad].
        moment_coef: Body drag-moment coefficient ``C_M`` [kg m^2].
        fin_offset: Lateral distance ``C_p`` of each fin pivot from the
            centre of mass [m] (Table 1, "Body Width (C_p)").
        fin_span: Fin span ``S_p`` [m].
        fin_chord: Fin chord ``D_p`` [m].
        fin_mass: Fin mass ``m_pf`` [kg] (documentation only; the dynamics use
            the effective mass).
        fin_effective_mass: Effective fin mass ``m_p`` incl. added mass [kg].
        water_density: ``rho`` [kg/m^3].
        fin_force_coef: Normal-force coefficient ``lambda`` of eq. (11) [-].
        body_length: Body length [m] (used for walls and rendering).
        body_height: Body height [m] (documentation only).
        fin_force_scale_right, fin_force_scale_left: Per-fin factor [-] on that fin's normal force of
            eq. (11), i.e. on its drag constant ``k`` (a bent or smaller fin, a servo that cannot reach
            the commanded speed); 1 is the paper's fin, 0 a fin without a blade. >= 0.
        fin_angle_offset_right, fin_angle_offset_left: Per-fin servo offset ``a_0`` [rad] (an offset horn).
        fin_angle_scale_right, fin_angle_scale_left: Per-fin servo scale ``a_1`` [-], > 0: the fin's actual
            angle is ``a_0 + a_1 g`` for the commanded angle ``g``. The firmware's rules and the servo limits
            act on the commanded angle; only the fin's motion in the water (the forces) sees the actual one.

    The per-fin fields default to today's symmetric fish (factor 1, offset 0, scale 1); a parameters file
    without them loads as that fish (``docs/model.md`` section 2, "Fins that differ").
    """

    body_mass: float = 0.795  # kg
    body_inertia: float = 4.26e-4  # kg m^2
    added_mass_x: float = -0.095  # kg
    added_mass_y: float = -0.1794  # kg
    added_inertia: float = -2.7e-5  # kg m^2
    wetted_area: float = 0.0325  # m^2  (erratum: Table 1 prints 0.325)
    drag_coef: float = 0.3870  # -
    lift_coef: float = 0.0808  # 1/rad
    moment_coef: float = 8.5e-3  # kg m^2
    fin_offset: float = 0.03  # m
    fin_span: float = 0.061  # m
    fin_chord: float = 0.041  # m
    fin_mass: float = 0.008  # kg
    fin_effective_mass: float = 0.008  # kg
    water_density: float = 1000.0  # kg/m^3
    fin_force_coef: float = 4.1464  # -
    body_length: float = 0.198  # m
    body_height: float = 0.1  # m
    fin_force_scale_right: float = 1.0  # -
    fin_force_scale_left: float = 1.0  # -
    fin_angle_offset_right: float = 0.0  # rad
    fin_angle_offset_left: float = 0.0  # rad
    fin_angle_scale_right: float = 1.0  # -
    fin_angle_scale_left: float = 1.0  # -

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"FishParams.{field.name} must be a finite number, got {value!r}")
        positive = (
            "body_mass", "body_inertia", "wetted_area", "fin_offset", "fin_span",
            "fin_chord", "water_density", "fin_force_coef", "body_length", "body_height",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"FishParams.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("drag_coef", "lift_coef", "moment_coef", "fin_mass", "fin_effective_mass",
                     "fin_force_scale_right", "fin_force_scale_left"):
            if getattr(self, name) < 0:
                raise ValueError(f"FishParams.{name} must be >= 0, got {getattr(self, name)!r}")
        for name in ("fin_angle_scale_right", "fin_angle_scale_left"):
            if getattr(self, name) <= 0:
                raise ValueError(f"FishParams.{name} must be > 0 (a servo that turns the fin the commanded way), "
                                 f"got {getattr(self, name)!r}")
        for name in ("fin_angle_offset_right", "fin_angle_offset_left"):
            if abs(getattr(self, name)) >= math.pi / 2:
                raise ValueError(f"FishParams.{name} must be within +-pi/2 rad (a horn offset, not another fin "
                                 f"position), got {getattr(self, name)!r}")
        for name, value in (("m1", self.m1), ("m2", self.m2), ("J3", self.J3)):
            if value <= 0:
                raise ValueError(
                    f"FishParams: effective {name} = {value:.4g} must be > 0; added masses and "
                    "inertia follow the paper's sign (negative numbers add to the body's)."
                )

    # Derived coefficients, eq. (20).
    @property
    def m1(self) -> float:
        """Surge mass ``m_1 = m_b - m_ax`` [kg] (eq. 20)."""
        return self.body_mass - self.added_mass_x

    @property
    def m2(self) -> float:
        """Sway mass ``m_2 = m_b - m_ay`` [kg] (eq. 20)."""
        return self.body_mass - self.added_mass_y

    @property
    def J3(self) -> float:  # noqa: N802 - the paper's name
        """Yaw inertia ``J_3 = J_bz - J_az`` [kg m^2] (eq. 20)."""
        return self.body_inertia - self.added_inertia

    @property
    def c1(self) -> float:
        """Drag constant ``c_1 = rho S_A C_D / 2`` [kg/m] (eq. 20)."""
        return 0.5 * self.water_density * self.wetted_area * self.drag_coef

    @property
    def c2(self) -> float:
        """Lift constant ``c_2 = rho S_A C_L / 2`` [kg/m/rad] (eq. 20)."""
        return 0.5 * self.water_density * self.wetted_area * self.lift_coef

    @property
    def c4(self) -> float:
        """Yaw damping ``c_4 = C_M / J_3`` [-] (eq. 20)."""
        return self.moment_coef / self.J3

    @property
    def fin_drag_constant(self) -> float:
        """``k = lambda rho D_p S_p^3 / 6`` [kg m^2... N s^2]: ``F_n = -k g'|g'|`` (eqs. 11, 13)."""
        return self.fin_force_coef * self.water_density * self.fin_chord * self.fin_span**3 / 6.0

    @property
    def fin_inertia_constant(self) -> float:
        """``m_p S_p / 2`` [kg m]: the fin's inertial reaction of eq. (15)."""
        return self.fin_effective_mass * self.fin_span / 2.0

    @property
    def symmetric_fins(self) -> bool:
        """True when both fins are the paper's fin (every per-fin field at its default)."""
        return all(getattr(self, name) == default for name, default in PER_FIN_DEFAULTS.items())

    def fin_actual_beat(self, beat: FinBeat, side: str) -> FinBeat:
        """The pattern fin ``side`` (``"right"``/``"left"``) actually beats for the commanded ``beat``.

        ``bias -> a_0 + a_1 bias``, ``amplitude -> a_1 amplitude``; period and ratio are unchanged.

        Raises:
            ValueError: If ``side`` is not ``"right"`` or ``"left"``, or the actual stroke leaves [0, pi].
        """
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        offset = getattr(self, f"fin_angle_offset_{side}")
        scale = getattr(self, f"fin_angle_scale_{side}")
        return FinBeat(offset + scale * beat.bias, scale * beat.amplitude, beat.period, beat.ratio)

    def replace(self, **changes: float) -> FishParams:
        """Return a copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


#: The per-fin fields and the values that make both fins the paper's fin (``FishParams.symmetric_fins``).
PER_FIN_DEFAULTS = {
    "fin_force_scale_right": 1.0, "fin_force_scale_left": 1.0,
    "fin_angle_offset_right": 0.0, "fin_angle_offset_left": 0.0,
    "fin_angle_scale_right": 1.0, "fin_angle_scale_left": 1.0,
}

# Packed per-fish coefficients the compiled kernels read (one row per fish), in this order. The per-fin
# fields follow the symmetric ones, right fin then left, so a kernel reads fin f's at ``index[f]``
# (FIN_FORCE_SCALE, FIN_ANGLE_OFFSET, FIN_ANGLE_SCALE).
COEF_NAMES = ("m1", "m2", "J3", "c1", "c2", "c4", "fin_drag_constant", "fin_inertia_constant", "fin_offset",
              "fin_force_scale_right", "fin_force_scale_left", "fin_angle_offset_right", "fin_angle_offset_left",
              "fin_angle_scale_right", "fin_angle_scale_left")

#: Index of each packed coefficient, generated from :data:`COEF_NAMES` (``coef[Coef.C4]``);
#: numba reads the members as compile-time constants.
Coef = enum.IntEnum("Coef", {name.upper(): i for i, name in enumerate(COEF_NAMES)})
#: Packed index of each fin's force factor, servo offset and servo scale, ``(right, left)`` (numba constants).
FIN_FORCE_SCALE = (int(Coef.FIN_FORCE_SCALE_RIGHT), int(Coef.FIN_FORCE_SCALE_LEFT))
FIN_ANGLE_OFFSET = (int(Coef.FIN_ANGLE_OFFSET_RIGHT), int(Coef.FIN_ANGLE_OFFSET_LEFT))
FIN_ANGLE_SCALE = (int(Coef.FIN_ANGLE_SCALE_RIGHT), int(Coef.FIN_ANGLE_SCALE_LEFT))


class BodyCoefficients(NamedTuple):
    """The rigid-body coefficients of eqs. (19)-(20), the first six packed coefficients."""

    m1: float  # kg, surge mass m_b - m_ax (eq. 20)
    m2: float  # kg, sway mass m_b - m_ay
    J3: float  # kg m^2, yaw inertia J_bz - J_az
    c1: float  # kg/m, drag constant rho S_A C_D / 2
    c2: float  # kg/m/rad, lift constant rho S_A C_L / 2
    c4: float  # -, yaw damping C_M / J_3


def coefficient_vector(params: FishParams) -> np.ndarray:
    """Pack the derived coefficients of ``params`` in the order of :data:`COEF_NAMES`."""
    return np.array([float(getattr(params, name)) for name in COEF_NAMES], dtype=np.float64)


def body_coefficients(coef: FishParams | np.ndarray) -> BodyCoefficients:
    """The body coefficients ``(m1, m2, J3, c1, c2, c4)`` of a :class:`FishParams` or of a packed row."""
    if isinstance(coef, FishParams):
        coef = coefficient_vector(coef)
    return BodyCoefficients(*(float(coef[i]) for i in range(len(BodyCoefficients._fields))))


@dataclass(frozen=True)
class FinBeat:
    """One fin's beat pattern, eq. (21): ``(bias, amplitude, period, ratio)``.

    The fin sweeps from ``bias - amplitude`` to ``bias + amplitude`` (power
    stroke, backward, duration ``period / (ratio + 1)``) and back (recovery,
    ``ratio`` times slower).

    Attributes:
        bias: ``gamma_0`` [rad], angle of the stroke centre from the body x-axis.
        amplitude: ``gamma_A`` [rad], half the stroke angle, >= 0.
        period: ``T_p`` [s], > 0.
        ratio: ``zeta`` [-], power/recovery angular-speed ratio, > 0.
    """

    bias: float
    amplitude: float
    period: float
    ratio: float

    def __post_init__(self) -> None:
        for name in ("bias", "amplitude", "period", "ratio"):
            value = getattr(self, name)
            try:
                finite = math.isfinite(value)
            except TypeError:
                raise ValueError(f"FinBeat.{name} must be a number, got {value!r}") from None
            if not finite:
                raise ValueError(f"FinBeat.{name} must be finite, got {value!r}")
        if self.amplitude < 0:
            raise ValueError(f"FinBeat.amplitude must be >= 0 rad, got {self.amplitude!r}")
        if self.period <= 0:
            raise ValueError(f"FinBeat.period must be > 0 s, got {self.period!r}")
        if self.ratio <= 0:
            raise ValueError(f"FinBeat.ratio must be > 0, got {self.ratio!r}")
        if self.bias - self.amplitude < 0 or self.bias + self.amplitude > math.pi:
            raise ValueError(
                "FinBeat.bias/amplitude: the stroke "
                f"[{math.degrees(self.bias - self.amplitude):.1f}, "
                f"{math.degrees(self.bias + self.amplitude):.1f}] deg leaves [0, 180] deg "
                "and would pass the fin through the body"
            )

    @classmethod
    def from_degrees(cls, bias: float, amplitude: float, period: float, ratio: float) -> FinBeat:
        """Build from the paper's tuple ``(g0 [deg], gA [deg], T_p [s], zeta)``."""
        return cls(math.radians(bias), math.radians(amplitude), float(period), float(ratio))

    @classmethod
    def rest(cls, bias: float = math.pi / 2) -> FinBeat:
        """A fin held still at ``bias`` (zero amplitude; the stroke clock ticks at 1 s)."""
        return cls(bias, 0.0, 1.0, 1.0)

    def as_array(self) -> np.ndarray:
        """``[bias, amplitude, period, ratio]`` as float64."""
        return np.array([self.bias, self.amplitude, self.period, self.ratio], dtype=np.float64)

    def degrees(self) -> tuple[float, float, float, float]:
        """The paper's tuple ``(g0 [deg], gA [deg], T_p [s], zeta)``."""
        return (math.degrees(self.bias), math.degrees(self.amplitude), self.period, self.ratio)


# ---------------------------------------------------------------- parameters files
PARAMS_FIELDS = tuple(f.name for f in dataclasses.fields(FishParams))


def params_dict(params: FishParams) -> dict[str, float]:
    """The fields of ``params`` as a JSON-ready dict (the format of a parameters file)."""
    return {name: float(getattr(params, name)) for name in PARAMS_FIELDS}


def params_from_dict(data: Mapping[str, Any], source: str = "params") -> FishParams:
    """A :class:`FishParams` from a mapping of its fields; fields not given keep their Table 1 defaults.

    Raises:
        ValueError: If ``data`` is not a mapping, names unknown fields, or a value is invalid.
    """
    if not isinstance(data, Mapping):
        raise ValueError(f"{source}: expected a mapping of FishParams fields, got {type(data).__name__}")
    unknown = sorted(set(data) - set(PARAMS_FIELDS))
    if unknown:
        raise ValueError(f"{source}: unknown FishParams fields {unknown}; valid names: {list(PARAMS_FIELDS)}")
    for name, value in data.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{source}: {name} must be a number, got {value!r}")
    try:
        return FishParams(**{name: float(value) for name, value in data.items()})
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def load_params(path: str | os.PathLike) -> FishParams:
    """Read a parameters file: a JSON object (``.json``) or YAML mapping (``.yaml``/``.yml``) of FishParams fields.

    Fields not in the file keep their Table 1 defaults, so a file may hold only what
    differs from the paper's robot, e.g. ``{"fin_span": 0.05}``.

    Raises:
        FileNotFoundError: If the file does not exist.
        ValueError: If the file is larger than :data:`pectoral_gym.inputfile.SMALL_FILE_BYTES`, cannot be parsed,
            or its content is not valid parameters.
    """
    path = Path(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        text = read_text(path, SMALL_FILE_BYTES)
        try:
            import yaml
        except ImportError as error:  # pragma: no cover - pyyaml is in the rl extra
            raise ValueError(f"{path}: reading YAML needs pyyaml (pip install pyyaml), or use JSON") from error
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f"{path}: not valid YAML: {' '.join(str(error).split())}") from None
        except RecursionError:
            raise ValueError(f"{path}: YAML nested too deep (not a parameters file)") from None
    else:
        data = load_json(path, SMALL_FILE_BYTES)
    return params_from_dict(data if data is not None else {}, source=str(path))


def save_params(params: FishParams, path: str | os.PathLike) -> None:
    """Write ``params`` as a JSON parameters file (every field), readable by :func:`load_params`."""
    Path(path).write_text(json.dumps(params_dict(params), indent=2) + "\n")


def as_params(value: FishParams | Mapping[str, Any] | str | os.PathLike | None) -> FishParams:
    """Parameters from ``None`` (Table 1), a :class:`FishParams`, a mapping of its fields, or a parameters file path.

    Raises:
        ValueError: For any other type or invalid content.
    """
    if value is None:
        return FishParams()
    if isinstance(value, FishParams):
        return value
    if isinstance(value, Mapping):
        return params_from_dict(value)
    if isinstance(value, (str, os.PathLike)):
        return load_params(value)
    raise ValueError(
        f"params must be a FishParams, a dict of its fields, a parameters file path or None, got {type(value).__name__}"
    )
