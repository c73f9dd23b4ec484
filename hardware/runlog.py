"""Run logs: what a robot run records for the model's calibration, one JSON object per line (``docs/run-log.md``).

A run log is JSON Lines. Each line is one record with a ``"type"``:

* ``header`` (first line, once): ``format`` (``"pectoral-run-log"``), ``version`` (1), ``source``
  (``"robot"``, ``"emulator"``, ...), ``control_period`` [s], ``firmware`` (the
  :class:`~pectoral_gym.hardware.radio.firmware.FirmwareConfig` the fins ran under, :func:`firmware_dict`),
  optional ``known_params`` (:class:`~pectoral_gym.model.params.FishParams` fields the user measured).
* ``episode``: ``episode`` (int), ``t`` [s]: a new segment starts (the fish may have been placed by hand).
* ``command``: ``t`` [s, PC clock, when sent], ``beats`` ``[[bias, amplitude, period, ratio] right, [...] left]``
  (rad, rad, s, -) exactly as sent on the wire.
* ``stop``: ``t`` [s]: the fins were halted (STOP, a safety trip, the end of an episode).
* ``pose``: ``t`` [s, the frame's capture stamp on the same clock], ``x``, ``y`` [m, tank frame], ``psi`` [rad],
  ``confidence`` (0..1).
* ``ack``, ``estimate``, ``safety``: ``t`` [s] and free fields; kept, not needed by the calibration.

:class:`RunLogWriter` writes it (one method per record type, each record checked before it is written);
:func:`read_run_log` reads and checks a file and raises :class:`RunLogError` naming the file, the line and
what is wrong with the first bad record.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from pectoral_gym.hardware.radio.firmware import FirmwareConfig, ServoLimits
from pectoral_gym.model.params import PARAMS_FIELDS

__all__ = ["FORMAT", "VERSION", "RECORD_TYPES", "Episode", "RunLog", "RunLogError", "RunLogWriter",
           "check_record", "dumps_example", "firmware_dict", "firmware_from_dict", "read_run_log", "validate"]

FORMAT = "pectoral-run-log"
VERSION = 1
#: Required fields of each record type besides ``type`` (``ack``, ``estimate``, ``safety``: ``t`` only).
RECORD_TYPES: dict[str, tuple[str, ...]] = {
    "header": ("format", "version", "source", "control_period", "firmware"),
    "episode": ("episode", "t"),
    "command": ("t", "beats"),
    "stop": ("t",),
    "pose": ("t", "x", "y", "psi", "confidence"),
    "ack": ("t",),
    "estimate": ("t",),
    "safety": ("t",),
}
_WIRE_MAX = 65.535  # largest SI value a SET_FINS field carries (hardware/radio/protocol.py, _FIN_SCALE)


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


@dataclass
class Episode:
    """One segment of a run: the records between an ``episode`` record and the next, as arrays.

    Attributes:
        index: The ``episode`` number the log gives.
        t_start: Its start [s].
        command_t: ``(k,)`` send times of the commands [s].
        beats: ``(k, 2, 4)`` the commands as sent (right fin first; rad, rad, s, -).
        stop_t: ``(s,)`` times the fins were halted [s].
        pose_t: ``(p,)`` capture stamps of the poses [s].
        poses: ``(p, 3)`` ``x, y, psi`` [m, m, rad].
        confidence: ``(p,)`` the tracker's confidence (0..1).
    """

    index: int
    t_start: float
    command_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    beats: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 4)))
    stop_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pose_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    confidence: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def t_end(self) -> float:
        """The last time any record of the episode names [s]."""
        times = [self.t_start, *self.command_t[-1:], *self.stop_t[-1:], *self.pose_t[-1:]]
        return float(max(times))


@dataclass
class RunLog:
    """A checked run log.

    Attributes:
        path: Where it was read from.
        header: The header record (without ``type``).
        episodes: The episodes in order.
        other: The ``ack``, ``estimate`` and ``safety`` records, as read.
    """

    path: str
    header: dict[str, Any]
    episodes: list[Episode]
    other: list[dict[str, Any]]

    @property
    def firmware(self) -> FirmwareConfig:
        """The firmware settings the fins ran under."""
        return firmware_from_dict(self.header["firmware"])

    @property
    def known_params(self) -> dict[str, float]:
        """FishParams fields the user measured (may be empty)."""
        return dict(self.header.get("known_params") or {})

    @property
    def duration(self) -> float:
        """Logged robot time: the sum of the episodes' spans [s]."""
        return float(sum(ep.t_end - ep.t_start for ep in self.episodes))


# ------------------------------------------------------------------ record checks
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
    for side, (bias, amp, period, ratio) in zip(("right", "left"), beats, strict=True):
        if not (0.0 <= min(bias, amp, period, ratio) and max(bias, amp, period, ratio) <= _WIRE_MAX):
            raise ValueError(f"{side} fin beat {[bias, amp, period, ratio]} outside the envelope: every value "
                             f"must be in [0, {_WIRE_MAX}] (the wire format)")
        if period <= 0 or ratio <= 0:
            raise ValueError(f"{side} fin beat outside the envelope: period {period} s and ratio {ratio} must be > 0")
        if bias - amp < 0 or bias + amp > math.pi:
            raise ValueError(f"{side} fin beat outside the envelope: the stroke [{math.degrees(bias - amp):.1f}, "
                             f"{math.degrees(bias + amp):.1f}] deg leaves [0, 180] deg")
    return beats


def _check_header(rec: Mapping[str, Any]) -> None:
    if rec["format"] != FORMAT:
        raise ValueError(f"header: format must be {FORMAT!r}, got {rec['format']!r}")
    if rec["version"] != VERSION:
        raise ValueError(f"header: version {rec['version']!r} is not supported (this reader: {VERSION})")
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
    if kind == "pose":
        for name in ("x", "y", "psi"):
            _number(rec, name)
        if not 0.0 <= _number(rec, "confidence") <= 1.0:
            raise ValueError(f"confidence must be in [0, 1], got {rec['confidence']!r}")
    return kind


# ------------------------------------------------------------------ reader
class _Builder:
    """Collects records into episodes, checking their order."""

    def __init__(self) -> None:
        self.episodes: list[Episode] = []
        self.lists: list[dict[str, list]] = []
        self.last: dict[str, float] = {}

    def _start(self, index: int, t: float) -> None:
        self.episodes.append(Episode(index, t))
        self.lists.append({name: [] for name in ("command_t", "beats", "stop_t", "pose_t", "poses", "confidence")})

    def add(self, kind: str, rec: Mapping[str, Any]) -> None:
        t = float(rec["t"])
        if t < self.last.get(kind, -math.inf):
            raise ValueError(f"timestamps go backwards: {kind} at t = {t!r} s after one at {self.last[kind]!r} s")
        self.last[kind] = t
        if kind == "episode":
            start = max((v for k, v in self.last.items() if k != "episode"), default=-math.inf)
            if self.episodes and t < start:
                raise ValueError(f"timestamps go backwards: episode starts at t = {t!r} s before the previous "
                                 f"episode's last record ({start!r} s)")
            self._start(int(rec["episode"]), t)
            return
        if not self.episodes:  # records before any episode record: an implicit episode 0 (docs/run-log.md)
            self._start(0, t)
        ep, lists = self.episodes[-1], self.lists[-1]
        if t < ep.t_start:
            raise ValueError(f"timestamps go backwards: {kind} at t = {t!r} s before its episode's start "
                             f"({ep.t_start!r} s)")
        if kind == "command":
            lists["command_t"].append(t)
            lists["beats"].append(np.asarray(rec["beats"], dtype=float))
        elif kind == "stop":
            lists["stop_t"].append(t)
        elif kind == "pose":
            lists["pose_t"].append(t)
            lists["poses"].append((float(rec["x"]), float(rec["y"]), float(rec["psi"])))
            lists["confidence"].append(float(rec["confidence"]))

    def finish(self) -> list[Episode]:
        shapes = {"beats": (-1, 2, 4), "poses": (-1, 3)}
        for ep, lists in zip(self.episodes, self.lists, strict=True):
            for name, values in lists.items():
                setattr(ep, name, np.asarray(values, dtype=float).reshape(shapes.get(name, (-1,))))
        return self.episodes


def _reject_constant(token: str) -> float:
    raise ValueError(f"{token} is not a number JSON allows")


def read_run_log(path: str | os.PathLike | TextIO) -> RunLog:
    """Read and check a run log (a path, or an open text stream).

    Raises:
        RunLogError: For the first bad record: bad JSON, unknown type, missing field, NaN, timestamps going
            backwards (per record type, and against the episode's start), beats outside the envelope;
            or a file without a header first, or without any pose.
        FileNotFoundError: If the path does not exist.
    """
    if isinstance(path, (str, os.PathLike)):
        name = os.fspath(path)
        with Path(path).open() as stream:
            return _read(stream, name)
    return _read(path, "<stream>")


def _read(stream: TextIO, name: str) -> RunLog:
    header: dict[str, Any] | None = None
    builder, other = _Builder(), []
    lineno = 0
    for lineno, line in enumerate(stream, start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line, parse_constant=_reject_constant)
        except ValueError as error:
            raise RunLogError(name, lineno, f"not valid JSON: {error}") from None
        try:
            kind = check_record(rec)
            if header is None and kind != "header":
                raise ValueError(f"the first record must be the header, got a {kind!r} record")
            if kind == "header":
                if header is not None:
                    raise ValueError("a second header record")
                header = {k: v for k, v in rec.items() if k != "type"}
            elif kind in ("ack", "estimate", "safety"):
                other.append(dict(rec))
            else:
                builder.add(kind, rec)
        except ValueError as error:
            raise RunLogError(name, lineno, str(error)) from None
    if header is None:
        raise RunLogError(name, 0, "empty run log: no header record")
    episodes = builder.finish()
    if not any(len(ep.pose_t) for ep in episodes):
        raise RunLogError(name, lineno, "the log holds no pose record")
    return RunLog(name, header, episodes, other)


def validate(path: str | os.PathLike) -> None:
    """Check a run log; raises :class:`RunLogError` for the first bad record (see :func:`read_run_log`)."""
    read_run_log(path)


# ------------------------------------------------------------------ writer
class RunLogWriter:
    """Write a run log, one record per call; every record is checked first (a bad value raises ``ValueError``).

    Args:
        out: A path (created or overwritten) or an open text stream.
        source: Who produced the log: ``"robot"``, ``"emulator"``, ``"synthetic"``, ...
        control_period: The controller's step [s].
        firmware: The firmware settings the fins run under.
        known_params: FishParams fields the user measured (mass, geometry), or ``None``.

    Example::

        with RunLogWriter("run.jsonl", "robot", 0.5, FirmwareConfig()) as log:
            log.episode(0, t=0.0)
            log.command(0.1, [[1.57, 0.4, 1.0, 2.0], [1.57, 0.4, 1.0, 2.0]])
            log.pose(0.133, x=1.15, y=0.57, psi=0.0, confidence=0.98)
            log.stop(30.0)
    """

    def __init__(self, out: str | os.PathLike | TextIO, source: str, control_period: float,
                 firmware: FirmwareConfig | None = None, known_params: Mapping[str, float] | None = None):
        self._own = isinstance(out, (str, os.PathLike))
        self._stream: TextIO = Path(out).open("w") if self._own else out  # type: ignore[arg-type]
        header = {"type": "header", "format": FORMAT, "version": VERSION, "source": source,
                  "control_period": float(control_period), "firmware": firmware_dict(firmware or FirmwareConfig())}
        if known_params:
            header["known_params"] = {k: float(v) for k, v in known_params.items()}
        self._write(header)

    def _write(self, rec: dict[str, Any]) -> None:
        check_record(rec)
        self._stream.write(json.dumps(rec, allow_nan=False) + "\n")

    def episode(self, episode: int, t: float) -> None:
        """A new episode (segment) starts at ``t`` [s]."""
        self._write({"type": "episode", "episode": int(episode), "t": float(t)})

    def command(self, t: float, beats: Any) -> None:
        """A command ``beats`` ``(2, 4)`` (right fin first; rad, rad, s, -) sent at ``t`` [s], as on the wire."""
        self._write({"type": "command", "t": float(t), "beats": np.asarray(beats, dtype=float).reshape(2, 4).tolist()})

    def stop(self, t: float) -> None:
        """The fins were halted at ``t`` [s]."""
        self._write({"type": "stop", "t": float(t)})

    def pose(self, t: float, x: float, y: float, psi: float, confidence: float = 1.0) -> None:
        """A camera pose captured at ``t`` [s]: ``x, y`` [m], ``psi`` [rad], ``confidence`` (0..1)."""
        self._write({"type": "pose", "t": float(t), "x": float(x), "y": float(y), "psi": float(psi),
                     "confidence": float(confidence)})

    def ack(self, t: float, **fields: Any) -> None:
        """The robot acknowledged a message at ``t`` [s] (free fields, e.g. ``seq``, ``state``)."""
        self._write({"type": "ack", "t": float(t), **fields})

    def estimate(self, t: float, **fields: Any) -> None:
        """The observer's estimate at ``t`` [s] (free fields, e.g. ``state``)."""
        self._write({"type": "estimate", "t": float(t), **fields})

    def safety(self, t: float, **fields: Any) -> None:
        """A safety event at ``t`` [s] (free fields, e.g. ``rule``, ``reason``)."""
        self._write({"type": "safety", "t": float(t), **fields})

    def flush(self) -> None:
        """Flush the stream."""
        self._stream.flush()

    def close(self) -> None:
        """Close the file (a stream given by the caller is flushed, not closed)."""
        if self._own:
            self._stream.close()
        else:
            self._stream.flush()

    def __enter__(self) -> RunLogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def dumps_example() -> str:
    """A two-episode example log as text (``docs/run-log.md`` shows it; tests read it back)."""
    buf = io.StringIO()
    log = RunLogWriter(buf, "robot", 0.5, FirmwareConfig(), known_params={"body_mass": 0.795})
    log.episode(0, 0.0)
    log.command(0.10, [[1.5708, 0.5236, 1.0, 2.0], [1.5708, 0.5236, 1.0, 2.0]])
    log.pose(0.133, 1.150, 0.575, 0.000, 0.98)
    log.pose(0.167, 1.150, 0.575, 0.001, 0.97)
    log.stop(4.0)
    log.episode(1, 10.0)
    log.pose(10.033, 1.150, 0.575, 3.140, 0.99)
    return buf.getvalue()
