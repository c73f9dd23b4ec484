"""Scaling functions ``K_fx, K_fy, K_m`` read from a coefficients file.

The averaged model (eq. 25) multiplies each fin's averaged force and moment by
scaling functions of the fin-beat parameters. They are identified by the
``scaling/`` pipeline (Sec. 4.3 of the paper) and stored as data, so this
package never imports ``scaling``.

The file format (its sections and what they mean) is specified in
:mod:`pectoral_gym.model.kfile`, which also parses its spline sections.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.inputfile import K_FILE_BYTES, load_json
from pectoral_gym.model.kfile import (
    SPLINE_AXES,
    WAVEFORM_TAG,
    checked_spline,
    padded,
    spline_dict,
    spline_section,
)
from pectoral_gym.model.ktables import (
    KTables,
    bspline_basis,
    interleave,
    oscillation_phasor,
    scaling_values,
    spline_values,
)
from pectoral_gym.model.params import PER_FIN_DEFAULTS

__all__ = [
    "FEATURES", "FORMAT", "FORMATS", "K_NAMES", "SPLINE_AXES", "SWAY_MODES", "UNIT_K", "KTables", "ScalingFunctions",
    "bspline_basis", "default_scaling_path", "oscillation_phasor", "spline_values",
]

FEATURES = ("bias", "amplitude", "period", "ratio", "inv_period", "inv_ratio")
K_NAMES = ("K_fx", "K_fy", "K_m")
FORMAT = "pectoral-gym-scaling/3"
FORMATS = ("pectoral-gym-scaling/1", "pectoral-gym-scaling/2", FORMAT)
SWAY_MODES = ("paper", "base")
_NUMBER_LIST = re.compile(r"\[\s*((?:-?[\d.eE+-]+|null),?(?:\s*(?:-?[\d.eE+-]+|null),?)*)\s*\]")
_UNITS = {"bias": "rad", "amplitude": "rad", "period": "s", "ratio": "-", "inv_period": "1/s", "inv_ratio": "-"}


def default_scaling_path() -> Path:
    """Path of the coefficients file the averaged model loads by default."""
    return Path(str(resources.files("pectoral_gym") / "data" / "scaling_coefficients.json"))


@dataclass(frozen=True)
class ScalingFunctions:
    """Scaling functions: an optional polynomial plus an optional tensor-product cubic spline, per K.

    Attributes:
        powers: ``(3, n_terms, len(FEATURES))`` float exponents of :data:`FEATURES` per K.
        coefs: ``(3, n_terms)`` polynomial coefficients (zero pads unused terms).
        metadata: Free-form provenance (grid, solver, fit statistics, version).
        knots: Three knot vectors (bias [rad], amplitude [rad], 1/ratio [-]), or ``()`` for no spline.
        table: ``(3, n_bias, n_amplitude, n_inv_ratio)`` spline coefficients, or ``None``.
        sway: ``"paper"`` or ``"base"``: what ``K_fy`` multiplies (module docstring).
        oscillation_knots: Three knot vectors of the yaw-oscillation splines, or ``()`` for none.
        oscillation_table: ``(2, n_bias, n_amplitude, n_inv_ratio)`` coefficients of the
            phasor components ``A T_p cos(phi)``, ``A T_p sin(phi)`` [rad], or ``None``.
    """

    powers: np.ndarray
    coefs: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)
    knots: tuple[np.ndarray, ...] = ()
    table: np.ndarray | None = None
    sway: str = "paper"
    oscillation_knots: tuple[np.ndarray, ...] = ()
    oscillation_table: np.ndarray | None = None

    def __post_init__(self) -> None:
        # The compiled kernels index powers[k, j, :len(FEATURES)] without bounds checks.
        n_terms = np.shape(self.coefs)[1] if np.ndim(self.coefs) == 2 else -1
        if np.shape(self.coefs) != (3, n_terms) or np.shape(self.powers) != (3, n_terms, len(FEATURES)):
            raise ValueError(
                f"ScalingFunctions needs coefs (3, n) and powers (3, n, {len(FEATURES)}); "
                f"got {np.shape(self.coefs)} and {np.shape(self.powers)}"
            )
        if self.sway not in SWAY_MODES:
            raise ValueError(f"sway must be one of {SWAY_MODES}, got {self.sway!r}")
        knots, table = checked_spline(self.knots, self.table, len(K_NAMES), "spline")
        object.__setattr__(self, "knots", knots)
        object.__setattr__(self, "table", table)
        knots, table = checked_spline(self.oscillation_knots, self.oscillation_table, 2, "yaw-oscillation spline")
        object.__setattr__(self, "oscillation_knots", knots)
        object.__setattr__(self, "oscillation_table", table)

    @classmethod
    def unit(cls) -> ScalingFunctions:
        """``K_fx = K_fy = K_m = 1``: plain classical averaging."""
        return cls(np.zeros((3, 1, len(FEATURES))), np.ones((3, 1)), {"status": "unit: K = 1"})

    @property
    def has_spline(self) -> bool:
        """True when a spline part is present."""
        return self.table is not None

    @property
    def has_oscillation(self) -> bool:
        """True when the yaw-oscillation splines are present (oscillation-averaged yaw damping)."""
        return self.oscillation_table is not None

    def kernel_arrays(self) -> KTables:
        """The tables packed for the compiled kernels (:class:`pectoral_gym.model.ktables.KTables`).

        Knot vectors are padded to one ``(3, longest)`` array; absent splines
        are empty tables (``(3, 0, 0, 0)``, ``(2, 0, 0, 0)``).
        """
        return self._tables

    @cached_property
    def _tables(self) -> KTables:
        knots, table = padded(self.knots, self.table, 3)
        osc_knots, osc_table = padded(self.oscillation_knots, self.oscillation_table, 2)
        return KTables(np.ascontiguousarray(self.powers, dtype=np.float64),
                       np.ascontiguousarray(self.coefs, dtype=np.float64),
                       knots, table, self.sway == "base", osc_knots, osc_table,
                       interleave(knots, table, osc_knots, osc_table))

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<dict>") -> ScalingFunctions:
        """Build from the JSON structure described in the module docstring.

        Raises:
            ValueError: With the file and the offending entry when malformed.
        """
        if not isinstance(data, dict):
            raise ValueError(f"{source}: expected a JSON object (a K file), got {type(data).__name__}")
        if data.get("format") not in FORMATS:
            raise ValueError(f"{source}: 'format' must be one of {list(FORMATS)}, got {data.get('format')!r}")
        features = tuple(data.get("features", ()))
        if features not in (FEATURES, FEATURES[:5]):
            raise ValueError(f"{source}: 'features' must be {list(FEATURES)}")
        sway = data.get("sway", "paper")
        if sway not in SWAY_MODES:
            raise ValueError(f"{source}: 'sway' must be one of {list(SWAY_MODES)}, got {sway!r}")
        width = len(features)
        functions = data.get("functions")
        if not isinstance(functions, dict) or set(functions) != set(K_NAMES):
            raise ValueError(f"{source}: 'functions' must have exactly the keys {list(K_NAMES)}")
        if not all(isinstance(functions[name], list) for name in K_NAMES):
            raise ValueError(f"{source}: each of 'functions' {list(K_NAMES)} must be a list of terms")
        n_terms = max(1, max(len(functions[name]) for name in K_NAMES))
        powers = np.zeros((3, n_terms, len(FEATURES)))
        coefs = np.zeros((3, n_terms))
        for i, name in enumerate(K_NAMES):
            for j, term in enumerate(functions[name]):
                try:
                    c = float(term["coef"])
                    p = np.asarray(term["powers"], dtype=np.float64)
                except (KeyError, TypeError, ValueError) as err:
                    raise ValueError(f"{source}: {name} term {j} needs 'coef' and 'powers': {err}") from None
                if p.shape != (width,) or not np.all(np.isfinite(p)) or not np.isfinite(c):
                    raise ValueError(f"{source}: {name} term {j}: {width} finite powers and a finite coef required")
                if np.any(p < 0) or np.any(p != np.round(p)):
                    raise ValueError(f"{source}: {name} term {j}: powers must be non-negative integers")
                powers[i, j, :width] = p
                coefs[i, j] = c
        knots, table = cls._spline_from_dict(data.get("spline"), source)
        osc_knots, osc_table = cls._oscillation_from_dict(data.get("yaw_oscillation"), source)
        if "yaw_waveform" in data:
            raise ValueError(f"{source}: its 'yaw_waveform' section is for the yaw-waveform damping, an experiment "
                             f"that left the package (kept at the git tag {WAVEFORM_TAG}); remove the section to "
                             "use the file's yaw_oscillation")
        try:
            return cls(powers, coefs, dict(data.get("metadata", {})), knots, table, sway, osc_knots, osc_table)
        except ValueError as err:
            raise ValueError(f"{source}: {err}") from None

    @staticmethod
    def _spline_from_dict(spline: Any, source: str) -> tuple[tuple[np.ndarray, ...], np.ndarray | None]:
        def channels(section: dict) -> list:
            coefficients = section["coefficients"]
            if not isinstance(coefficients, dict) or set(coefficients) != set(K_NAMES):
                raise ValueError(f"3 knot vectors and coefficients for {list(K_NAMES)} required")
            return [coefficients[name] for name in K_NAMES]

        return spline_section(spline, source, "spline", channels)

    @staticmethod
    def _oscillation_from_dict(section: Any, source: str) -> tuple[tuple[np.ndarray, ...], np.ndarray | None]:
        return spline_section(section, source, "yaw_oscillation", lambda sec: [sec["cos"], sec["sin"]])

    @classmethod
    def load(cls, path: str | Path | None = None) -> ScalingFunctions:
        """Read a coefficients file (the shipped default if ``path`` is ``None``)."""
        path = Path(path) if path is not None else default_scaling_path()
        try:
            data = load_json(path, K_FILE_BYTES)
        except FileNotFoundError:
            raise FileNotFoundError(f"scaling coefficients file not found: {path}") from None
        return cls.from_dict(data, str(path))

    def to_dict(self) -> dict[str, Any]:
        """The JSON structure of the module docstring (zero-coefficient pads dropped)."""
        functions = {
            name: [
                {"coef": float(self.coefs[i, j]), "powers": [int(v) for v in self.powers[i, j]]}
                for j in range(self.coefs.shape[1])
                if self.coefs[i, j] != 0.0
            ]
            for i, name in enumerate(K_NAMES)
        }
        out: dict[str, Any] = {
            "format": FORMAT,
            "sway": self.sway,
            "features": list(FEATURES),
            "units": dict(_UNITS),
            "functions": functions,
        }
        if self.table is not None:
            out["spline"] = spline_dict(self.knots, {
                "coefficients": {name: self.table[i].ravel().tolist() for i, name in enumerate(K_NAMES)}})
        if self.oscillation_table is not None:
            out["yaw_oscillation"] = spline_dict(self.oscillation_knots, {
                "cos": self.oscillation_table[0].ravel().tolist(), "sin": self.oscillation_table[1].ravel().tolist()})
        out["metadata"] = self.metadata
        return out

    def save(self, path: str | Path) -> None:
        """Write the coefficients file."""
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        # One line per innermost list of numbers (powers, data rows): readable and compact.
        text = _NUMBER_LIST.sub(lambda m: "[" + " ".join(m.group(1).split()) + "]", text)
        Path(path).write_text(text + "\n")

    @property
    def identified_params(self) -> dict[str, float] | None:
        """The model parameters the file was identified for (``metadata["model_parameters"]``), or ``None``."""
        recorded = self.metadata.get("model_parameters")
        return dict(recorded) if isinstance(recorded, dict) else None

    def params_mismatch(self, params: Any, rtol: float = 1e-9) -> dict[str, tuple[float | None, float]]:
        """Fields of ``params`` (a ``FishParams``) that differ from :attr:`identified_params`: name -> (file, given).

        Empty when they agree to ``rtol``, or when the file records no parameters (unit K or an old file). The
        per-fin fields (``params.PER_FIN_DEFAULTS``) are not compared: K is a function of each fin's own pattern,
        evaluated at the pattern the fin actually beats (so a servo map needs no other K), and each fin's averaged
        forcing is linear in its force factor; what a force factor moves K by is measured in ``docs/model.md``
        section 2, "Fins that differ".
        """
        recorded = self.identified_params
        if recorded is None:
            return {}
        out: dict[str, tuple[float | None, float]] = {}
        for name in dataclasses.fields(params):
            if name.name in PER_FIN_DEFAULTS:
                continue
            given = float(getattr(params, name.name))
            known = recorded.get(name.name)
            if known is None or not math.isclose(float(known), given, rel_tol=rtol, abs_tol=0.0):
                out[name.name] = (None if known is None else float(known), given)
        return out

    def check_params(self, params: Any, where: str = "the coefficients file") -> None:
        """Raise ``ValueError`` naming the differing fields if the file was identified for other parameters.

        The check behind ``check_scaling_params`` of the envs and ``--params`` of the command lines:
        K identified for one robot does not describe another one.
        """
        mismatch = self.params_mismatch(params)
        if mismatch:
            shown = ", ".join(f"{k}: identified {a!r}, given {b!r}" for k, (a, b) in sorted(mismatch.items()))
            raise ValueError(
                f"{where} was identified for other model parameters ({shown}); its K would not describe "
                "this robot. Identify K for it (python -m pectoral_gym.scaling identify --params FILE) and use that "
                "file (scaling=FILE; --scaling FILE on the command lines), or turn the check off "
                "(check_scaling_params=False; pectoral-fish --no-params-check)"
            )

    @classmethod
    def load_for(cls, params: Any, path: str | Path | None = None, check: bool = True) -> ScalingFunctions:
        """Load a coefficients file (``None``: the shipped one), then :meth:`check_params` unless ``check`` is False."""
        scaling = cls.load(path)
        if check:
            where = "the shipped coefficients file" if path is None else f"coefficients file {path}"
            scaling.check_params(params, where)
        return scaling

    def evaluate(self, bias: float, amplitude: float, period: float, ratio: float) -> tuple[float, float, float]:
        """``(K_fx, K_fy, K_m)`` at one fin-beat pattern (rad, rad, s, -); ``K_fy`` in the file's :attr:`sway` sense.

        The compiled :func:`pectoral_gym.model.ktables.scaling_values`, the kernels' own evaluation.
        """
        kx, ky, km = scaling_values(float(bias), float(amplitude), float(period), float(ratio), self.kernel_arrays())
        return float(kx), float(ky), float(km)

    def yaw_oscillation(self, bias: float, amplitude: float, period: float, ratio: float) -> tuple[float, float]:
        """Amplitude ``A`` [rad/s] and phase ``phi`` [rad] of the fin's yaw-rate oscillation (module docstring).

        ``(0, 0)`` without yaw-oscillation splines.
        """
        tables = self.kernel_arrays()
        pc, ps = oscillation_phasor(float(bias), float(amplitude), 1.0 / ratio, tables.osc_knots, tables.osc_table)
        return float(np.hypot(pc, ps) / period), float(np.arctan2(ps, pc))

    def paper_k_fy(self, bias: float, amplitude: float, period: float, ratio: float) -> float:
        """The paper's ``K_fy`` (multiplying ``f_hy_avg``); infinite at ``cos(bias) = 0`` in ``"base"`` files."""
        k_fy = self.evaluate(bias, amplitude, period, ratio)[1]
        if self.sway == "paper":
            return k_fy
        with np.errstate(divide="ignore", invalid="ignore"):
            return float(np.float64(k_fy) / np.cos(bias))

    @property
    def is_unit(self) -> bool:
        """True when every K is identically 1 (in the paper's sense: plain averaging)."""
        return bool(self.table is None and self.oscillation_table is None and self.sway == "paper"
                    and np.all(self.powers[self.coefs != 0] == 0) and np.allclose(self.coefs.sum(axis=1), 1.0))


UNIT_K = ScalingFunctions.unit()  #: ``K = 1`` everywhere (plain classical averaging), shared: build it once
