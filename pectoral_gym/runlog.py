"""Run logs: what a robot run records for the model's calibration, one JSON object per line (``docs/run-log.md``).

A run log is JSON Lines. Each line is one record with a ``"type"``:

* ``header`` (first line, once): ``format`` (``"pectoral-run-log"``), ``version`` (2; 1 is read too), ``source``
  (``"robot"``, ``"emulator"``, ...), ``control_period`` [s], ``firmware`` (the
  :class:`~pectoral_gym.model.finrules.FirmwareConfig` the fins ran under, :func:`firmware_dict`),
  optional ``known_params`` (:class:`~pectoral_gym.model.params.FishParams` fields the user measured).
* ``episode``: ``episode`` (int), ``t`` [s]: a new segment starts (the fish may have been placed by hand).
* ``command``: ``t`` [s, PC clock, when sent], ``beats`` ``[[bias, amplitude, period, ratio] right, [...] left]``
  (rad, rad, s, -) exactly as sent on the wire.
* ``stop``: ``t`` [s]: the fins were halted (STOP, a safety trip, the end of an episode).
* ``pose``: ``t`` [s, the frame's capture stamp on the same clock], ``x``, ``y`` [m, tank frame], ``psi`` [rad],
  ``confidence`` (0..1).
* ``latch`` (version 2): ``t`` [s, the robot's report mapped onto the PC clock], ``fin`` (0 right, 1 left),
  ``beat`` ``[bias, amplitude, period, ratio]`` the fin latched at a stroke turning point, ``turn`` [rad] its
  angle there, ``power`` (a power stroke starts), ``uptime_ms`` (the robot's clock), optional ``boot``.
* ``ack``, ``estimate``, ``safety``: ``t`` [s] and free fields; kept, not needed by the calibration.

The records' checks are :mod:`pectoral_gym.runlog_schema`'s (re-exported here).
:class:`RunLogWriter` writes it (one method per record type, each record checked before it is written);
:func:`read_run_log` reads and checks a file and raises :class:`RunLogError` naming the file, the line and
what is wrong with the first bad record.
"""

from __future__ import annotations

import io
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.runlog_schema import (
    FORMAT,
    RECORD_TYPES,
    VERSION,
    VERSIONS,
    RunLogError,
    check_record,
    firmware_dict,
    firmware_from_dict,
)

__all__ = ["FORMAT", "VERSION", "VERSIONS", "RECORD_TYPES", "Episode", "RunLog", "RunLogError", "RunLogWriter",
           "check_record", "dumps_example", "firmware_dict", "firmware_from_dict", "read_run_log", "validate"]


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
        latch_t: ``(r,)`` times of the robot's latch reports [s, PC clock] (none in a version-1 log).
        latch_fin: ``(r,)`` their fins (0 right, 1 left).
        latch_beat: ``(r, 4)`` the patterns latched (rad, rad, s, -).
        latch_turn: ``(r,)`` the fin angles at the turning points [rad].
        latch_power: ``(r,)`` 1.0 where a power stroke starts, 0.0 for a recovery.
    """

    index: int
    t_start: float
    command_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    beats: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 4)))
    stop_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pose_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    confidence: np.ndarray = field(default_factory=lambda: np.zeros(0))
    latch_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    latch_fin: np.ndarray = field(default_factory=lambda: np.zeros(0))
    latch_beat: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    latch_turn: np.ndarray = field(default_factory=lambda: np.zeros(0))
    latch_power: np.ndarray = field(default_factory=lambda: np.zeros(0))

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


# ------------------------------------------------------------------ reader
class _Builder:
    """Collects records into episodes, checking their order."""

    def __init__(self) -> None:
        self.episodes: list[Episode] = []
        self.lists: list[dict[str, list]] = []
        self.last: dict[str, float] = {}

    def _start(self, index: int, t: float) -> None:
        self.episodes.append(Episode(index, t))
        self.lists.append({name: [] for name in ("command_t", "beats", "stop_t", "pose_t", "poses", "confidence",
                                                 "latch_t", "latch_fin", "latch_beat", "latch_turn", "latch_power")})

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
        elif kind == "latch":
            lists["latch_t"].append(t)
            lists["latch_fin"].append(int(rec["fin"]))
            lists["latch_beat"].append(np.asarray(rec["beat"], dtype=float))
            lists["latch_turn"].append(float(rec["turn"]))
            lists["latch_power"].append(1.0 if rec["power"] else 0.0)

    def finish(self) -> list[Episode]:
        shapes = {"beats": (-1, 2, 4), "poses": (-1, 3), "latch_beat": (-1, 4)}
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
        with Path(path).open(encoding="utf-8") as stream:
            try:
                return _read(stream, name)
            except UnicodeDecodeError as err:
                raise RunLogError(name, 0, f"not UTF-8 text ({err.reason} at byte {err.start})") from None
    return _read(path, "<stream>")


# A run log's bounds: a record is under 1 kB (a latch report, a command with its two patterns); a log of 100
# hours at 30 camera poses a second holds about 1 GB. Beyond either it is not a run log (or a device, /dev/zero).
MAX_RECORD_CHARS = 1 << 16
MAX_LOG_CHARS = 4 << 30


def _lines(stream: TextIO, name: str):
    """``(number, line)`` of ``stream``, each at most :data:`MAX_RECORD_CHARS`, all at most :data:`MAX_LOG_CHARS`."""
    total, lineno = 0, 0
    while True:
        line = stream.readline(MAX_RECORD_CHARS + 1)
        if not line:
            return
        lineno += 1
        total += len(line)
        if len(line) > MAX_RECORD_CHARS:
            raise RunLogError(name, lineno, f"a record longer than {MAX_RECORD_CHARS} characters (not a run log)")
        if total > MAX_LOG_CHARS:
            raise RunLogError(name, lineno, f"more than {MAX_LOG_CHARS} characters (not a run log)")
        yield lineno, line


def _read(stream: TextIO, name: str) -> RunLog:
    header: dict[str, Any] | None = None
    builder, other = _Builder(), []
    lineno = 0
    for lineno, line in _lines(stream, name):
        if not line.strip():
            continue
        try:
            rec = json.loads(line, parse_constant=_reject_constant)
        except ValueError as error:
            raise RunLogError(name, lineno, f"not valid JSON: {error}") from None
        except RecursionError:
            raise RunLogError(name, lineno, "not valid JSON: nested deeper than Python's recursion limit") from None
        try:
            kind = check_record(rec)
            if header is None and kind != "header":
                raise ValueError(f"the first record must be the header, got a {kind!r} record")
            if kind == "header":
                if header is not None:
                    raise ValueError("a second header record")
                header = {k: v for k, v in rec.items() if k != "type"}
            elif kind == "latch" and header["version"] < 2:
                raise ValueError(f"a latch record in a version-{header['version']} log (latch records came with "
                                 "version 2: write version 2 in the header)")
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
        t, x, y, psi, confidence = float(t), float(x), float(y), float(psi), float(confidence)
        if t >= 0.0 and 0.0 <= confidence <= 1.0 and math.isfinite(t + x + y + psi):
            # one line per camera frame: the bytes json.dumps gives (a finite float is its repr), checked as
            # check_record checks a pose, without building the record
            self._stream.write(f'{{"type": "pose", "t": {t!r}, "x": {x!r}, "y": {y!r}, "psi": {psi!r}, '
                               f'"confidence": {confidence!r}}}\n')
            return
        self._write({"type": "pose", "t": t, "x": x, "y": y, "psi": psi, "confidence": confidence})  # raises

    def latch(self, t: float, fin: int, beat: Any, turn: float, power: bool, uptime_ms: int,
              boot: int | None = None) -> None:
        """The robot reported that fin ``fin`` (0 right, 1 left) latched ``beat`` at a stroke turning point.

        Args:
            t: When, on the log's clock (the robot's uptime mapped onto the PC's) [s].
            fin: 0 right, 1 left.
            beat: ``[bias, amplitude, period, ratio]`` (rad, rad, s, -) as the fin runs it.
            turn: The fin angle at the turning point [rad].
            power: Whether a power stroke starts there (else a recovery).
            uptime_ms: The robot's clock at the latch [ms since its power-up].
            boot: The robot's boot id (the clock ``uptime_ms`` is on), if known.
        """
        row = np.asarray(beat, dtype=float).reshape(4).tolist()
        rec = {"type": "latch", "t": float(t), "fin": int(fin), "beat": row,
               "turn": float(turn), "power": bool(power), "uptime_ms": int(uptime_ms)}
        if boot is not None:
            rec["boot"] = int(boot)
        self._write(rec)

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
    log.latch(0.434, 0, [1.5708, 0.5236, 1.0, 2.0], 2.0944, False, 1434, boot=2718281)
    log.stop(4.0)
    log.episode(1, 10.0)
    log.pose(10.033, 1.150, 0.575, 3.140, 0.99)
    return buf.getvalue()
