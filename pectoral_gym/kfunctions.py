"""Scaling functions ``K_fx, K_fy, K_m`` read from a coefficients file.

The averaged model (eq. 25) multiplies each fin's averaged force and moment by
scaling functions of the fin-beat parameters. They are identified by the
``scaling/`` pipeline (Sec. 4.3 of the paper) and stored as data, so this
package never imports ``scaling``.

File format (JSON, ``format = "pectoral-gym-scaling/1"``)::

    {
      "format": "pectoral-gym-scaling/1",
      "features": ["bias", "amplitude", "period", "ratio", "inv_period", "inv_ratio"],
      "units": {"bias": "rad", "amplitude": "rad", "period": "s", "ratio": "-", "inv_period": "1/s", "inv_ratio": "-"},
      "functions": {
        "K_fx": [{"coef": 1.0, "powers": [0, 0, 0, 0, 0]}, ...],
        "K_fy": [...],
        "K_m":  [...]
      },
      "metadata": {...}
    }

Each function is a sum of monomials ``coef * prod(feature_i ** powers_i)``.
Files written before ``inv_ratio`` existed list the first five features and
five powers per term; they load unchanged (the sixth power is 0).
The shipped ``data/scaling_coefficients.json`` holds ``K = 1`` until the
scaling issue ships identified coefficients (its ``metadata.status`` says so).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FEATURES", "K_NAMES", "FORMAT", "ScalingFunctions", "default_scaling_path"]

FEATURES = ("bias", "amplitude", "period", "ratio", "inv_period", "inv_ratio")
K_NAMES = ("K_fx", "K_fy", "K_m")
FORMAT = "pectoral-gym-scaling/1"
_NUMBER_LIST = re.compile(r"\[\s*((?:-?[\d.eE+-]+|null),?(?:\s*(?:-?[\d.eE+-]+|null),?)*)\s*\]")
_UNITS = {"bias": "rad", "amplitude": "rad", "period": "s", "ratio": "-", "inv_period": "1/s", "inv_ratio": "-"}


def default_scaling_path() -> Path:
    """Path of the coefficients file the averaged model loads by default."""
    return Path(str(resources.files("pectoral_gym") / "data" / "scaling_coefficients.json"))


@dataclass(frozen=True)
class ScalingFunctions:
    """Polynomial scaling functions in packed array form.

    Attributes:
        powers: ``(3, n_terms, len(FEATURES))`` float exponents of :data:`FEATURES` per K.
        coefs: ``(3, n_terms)`` coefficients (zero pads unused terms).
        metadata: Free-form provenance (grid, solver, fit statistics, version).
    """

    powers: np.ndarray
    coefs: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # The compiled kernels index powers[k, j, :len(FEATURES)] without bounds checks.
        n_terms = np.shape(self.coefs)[1] if np.ndim(self.coefs) == 2 else -1
        if np.shape(self.coefs) != (3, n_terms) or np.shape(self.powers) != (3, n_terms, len(FEATURES)):
            raise ValueError(
                f"ScalingFunctions needs coefs (3, n) and powers (3, n, {len(FEATURES)}); "
                f"got {np.shape(self.coefs)} and {np.shape(self.powers)}"
            )

    @classmethod
    def unit(cls) -> ScalingFunctions:
        """``K_fx = K_fy = K_m = 1``: plain classical averaging."""
        return cls(np.zeros((3, 1, len(FEATURES))), np.ones((3, 1)), {"status": "unit: K = 1"})

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<dict>") -> ScalingFunctions:
        """Build from the JSON structure described in the module docstring.

        Raises:
            ValueError: With the file and the offending entry when malformed.
        """
        if data.get("format") != FORMAT:
            raise ValueError(f"{source}: 'format' must be {FORMAT!r}, got {data.get('format')!r}")
        features = tuple(data.get("features", ()))
        if features not in (FEATURES, FEATURES[:5]):
            raise ValueError(f"{source}: 'features' must be {list(FEATURES)}")
        width = len(features)
        functions = data.get("functions")
        if not isinstance(functions, dict) or set(functions) != set(K_NAMES):
            raise ValueError(f"{source}: 'functions' must have exactly the keys {list(K_NAMES)}")
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
        return cls(powers, coefs, dict(data.get("metadata", {})))

    @classmethod
    def load(cls, path: str | Path | None = None) -> ScalingFunctions:
        """Read a coefficients file (the shipped default if ``path`` is ``None``)."""
        path = Path(path) if path is not None else default_scaling_path()
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            raise FileNotFoundError(f"scaling coefficients file not found: {path}") from None
        except json.JSONDecodeError as err:
            raise ValueError(f"{path}: not valid JSON ({err})") from None
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
        return {
            "format": FORMAT,
            "features": list(FEATURES),
            "units": dict(_UNITS),
            "functions": functions,
            "metadata": self.metadata,
        }

    def save(self, path: str | Path) -> None:
        """Write the coefficients file."""
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        # One line per innermost list of numbers (powers, data rows): readable and compact.
        text = _NUMBER_LIST.sub(lambda m: "[" + " ".join(m.group(1).split()) + "]", text)
        Path(path).write_text(text + "\n")

    def evaluate(self, bias: float, amplitude: float, period: float, ratio: float) -> tuple[float, float, float]:
        """``(K_fx, K_fy, K_m)`` at one fin-beat pattern (rad, rad, s, -)."""
        x = np.array([bias, amplitude, period, ratio, 1.0 / period, 1.0 / ratio])
        values = np.sum(self.coefs * np.prod(x ** self.powers, axis=-1), axis=-1)
        return float(values[0]), float(values[1]), float(values[2])

    @property
    def is_unit(self) -> bool:
        """True when every K is identically 1."""
        return bool(np.all(self.powers[self.coefs != 0] == 0) and np.allclose(self.coefs.sum(axis=1), 1.0))
