"""The records of a run log and their checks (``docs/run-log.md``): one record at a time, not its place in the file.

:func:`check_record` checks a record's fields and values and returns its type; :mod:`pectoral_gym.runlog`
reads and writes whole logs with it (the order of records, episodes, the header's place).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import PARAMS_FIELDS
from pectoral_gym.model.servo import ServoLimits

__all__ = ["FORMAT", "VERSION", "VERSIONS", "RECORD_TYPES", "RunLogError", "check_record", "firmware_dict",
           "firmware_from_dict"]

FORMAT = "pectoral-run-log"
VERSION = 2  # what the writer writes; 2 added the ``latch`` record
VERSIONS = (1, 2)  # what the reader reads
#: Required fields of each record type besides ``type`` (``ack``, ``estimate``, ``safety``: ``t`` only).
RECORD_TYPES: dict[str, tuple[str, ...]] = {
    "header": ("format", "version", "source", "control_period", "firmware"),
    "episode": ("episode", "t"),
    "command": ("t", "beats"),
    "stop": ("t",),
    "pose": ("t", "x", "y", "psi", "confidence"),
    "latch": ("t", "fin", "beat", "turn", "power", "uptime_ms"),
    "ack": ("t",),
    "estimate": ("t",),
    "safety": ("t",),
}
_WIRE_MAX = 65.535  # largest SI value a SET_FINS field carries (pectoral_gym.model.finrules.FIN_WIRE_SCALE)


class RunLogError(ValueError):
    """A run log that cannot be read: ``str()`` is ``"<file>:<line>: <what is wrong>"``.

    Attributes:
        path: The file (or ``"<stream>"``).
        line: 1-based line number of the first bad record (0: the file as a whole).
        reason: What is wrong.
    """

    def __init__(self, path: str, line: int, reason: str):
        self.path, self.line, self.reason = path, line, reason
        super().__init__(f"{path}:{line}: {reason}")


def firmware_dict(config: FirmwareConfig) -> dict[str, Any]:
    """The header's ``firmware`` entry: the fields of ``config`` and of its :class:`ServoLimits` as plain values."""
    out = dataclasses.asdict(config)
    out["limits"]["max_rate"] = list(config.limits.max_rate)
    return out


def firmware_from_dict(data: Mapping[str, Any]) -> FirmwareConfig:
    """The :class:`FirmwareConfig` of a header's ``firmware`` entry (missing fields keep their defaults).

    Raises:
        ValueError: For unknown fields or invalid values.
    """
    data = dict(data)
    limits = dict(data.pop("limits", {}) or {})
    if "max_rate" in limits:
        limits["max_rate"] = tuple(float(v) for v in limits["max_rate"])
    try:
        return FirmwareConfig(**data, limits=ServoLimits(**limits))
    except TypeError as error:  # unknown field names
        raise ValueError(f"firmware: {error}") from None


def _number(rec: Mapping[str, Any], name: str) -> float:
    value = rec[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return float(value)


def _check_beats(value: Any) -> np.ndarray:
    """``(2, 4)`` beats inside the envelope: what the wire carries and a stroke that stays clear of the body."""
    try:
        beats = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"beats must be [[bias, amplitude, period, ratio] right, [...] left], got {value!r}") from None
    if beats.shape != (2, 4):
        raise ValueError(f"beats must be 2 rows (right, left) of [bias, amplitude, period, ratio], got {value!r}")
    if not np.all(np.isfinite(beats)):
        raise ValueError(f"beats must be finite, got {value!r}")
    for side, row in zip(("right", "left"), beats, strict=True):
        _check_beat_row(side, row)
    return beats


def _check_beat_row(side: str, row: np.ndarray) -> None:
    """One fin's ``[bias, amplitude, period, ratio]`` inside the envelope (what the wire carries, clear of the body)."""
    bias, amp, period, ratio = (float(v) for v in row)
    if not (0.0 <= min(bias, amp, period, ratio) and max(bias, amp, period, ratio) <= _WIRE_MAX):
        raise ValueError(f"{side} fin beat {[bias, amp, period, ratio]} outside the envelope: every value "
                         f"must be in [0, {_WIRE_MAX}] (the wire format)")
    if period <= 0 or ratio <= 0:
        raise ValueError(f"{side} fin beat outside the envelope: period {period} s and ratio {ratio} must be > 0")
    if bias - amp < 0 or bias + amp > math.pi:
        raise ValueError(f"{side} fin beat outside the envelope: the stroke [{math.degrees(bias - amp):.1f}, "
                         f"{math.degrees(bias + amp):.1f}] deg leaves [0, 180] deg")


def _integer(rec: Mapping[str, Any], name: str) -> int:
    value = rec[name]
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return value


def _check_latch(rec: Mapping[str, Any]) -> None:
    """A reported latch: the fin, the pattern it runs from its turning point, the angle there, the robot's clock."""
    if _integer(rec, "fin") not in (0, 1):
        raise ValueError(f"latch: fin must be 0 (right) or 1 (left), got {rec['fin']!r}")
    try:
        beat = np.array(rec["beat"], dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"latch: beat must be [bias, amplitude, period, ratio], got {rec['beat']!r}") from None
    if beat.shape != (4,) or not np.all(np.isfinite(beat)):
        raise ValueError(f"latch: beat must be 4 finite numbers [bias, amplitude, period, ratio], got {rec['beat']!r}")
    _check_beat_row(("right", "left")[rec["fin"]], beat)
    if not 0.0 <= _number(rec, "turn") <= math.pi:
        raise ValueError(f"latch: turn must be a fin angle in [0, pi] rad, got {rec['turn']!r}")
    if not isinstance(rec["power"], bool):
        raise ValueError(f"latch: power must be true (a power stroke starts) or false (a recovery), got "
                         f"{rec['power']!r}")
    if not 0 <= _integer(rec, "uptime_ms") <= 0xFFFFFFFF:
        raise ValueError(f"latch: uptime_ms must be the robot's u32 clock [ms], got {rec['uptime_ms']!r}")
    if "boot" in rec and not 0 <= _integer(rec, "boot") <= 0xFFFFFFFF:
        raise ValueError(f"latch: boot must be the robot's u32 boot id, got {rec['boot']!r}")


def _check_header(rec: Mapping[str, Any]) -> None:
    if rec["format"] != FORMAT:
        raise ValueError(f"header: format must be {FORMAT!r}, got {rec['format']!r}")
    if isinstance(rec["version"], bool) or rec["version"] not in VERSIONS:
        raise ValueError(f"header: version {rec['version']!r} is not supported (this reader: {list(VERSIONS)})")
    if not isinstance(rec["source"], str) or not rec["source"]:
        raise ValueError(f"header: source must be a non-empty string, got {rec['source']!r}")
    if not _number(rec, "control_period") > 0:
        raise ValueError(f"header: control_period must be > 0 s, got {rec['control_period']!r}")
    if not isinstance(rec["firmware"], Mapping):
        raise ValueError("header: firmware must be an object of FirmwareConfig fields")
    try:
        firmware_from_dict(rec["firmware"])
    except (TypeError, ValueError) as error:
        raise ValueError(f"header: bad firmware: {error}") from None
    known = rec.get("known_params") or {}
    if not isinstance(known, Mapping):
        raise ValueError("header: known_params must be an object of FishParams fields")
    unknown = sorted(set(known) - set(PARAMS_FIELDS))
    if unknown:
        raise ValueError(f"header: known_params names unknown FishParams fields {unknown}")
    for name in known:
        _number(known, name)


def check_record(rec: Any) -> str:
    """Check one record's fields and values (not its place in the file); returns its type.

    Raises:
        ValueError: Saying what is wrong.
    """
    if not isinstance(rec, Mapping):
        raise ValueError(f"a record must be a JSON object, got {type(rec).__name__}")
    kind = rec.get("type")
    if kind not in RECORD_TYPES:
        raise ValueError(f"unknown record type {kind!r}; known: {sorted(RECORD_TYPES)}")
    missing = [name for name in RECORD_TYPES[kind] if name not in rec]
    if missing:
        raise ValueError(f"{kind} record lacks field(s) {missing}")
    if kind == "header":
        _check_header(rec)
        return kind
    if not _number(rec, "t") >= 0:
        raise ValueError(f"t must be >= 0 s, got {rec['t']!r}")
    if kind == "episode" and (isinstance(rec["episode"], bool) or not isinstance(rec["episode"], int)):
        raise ValueError(f"episode must be an integer, got {rec['episode']!r}")
    if kind == "command":
        _check_beats(rec["beats"])
    if kind == "latch":
        _check_latch(rec)
    if kind == "pose":
        for name in ("x", "y", "psi"):
            _number(rec, name)
        if not 0.0 <= _number(rec, "confidence") <= 1.0:
            raise ValueError(f"confidence must be in [0, 1], got {rec['confidence']!r}")
    return kind
