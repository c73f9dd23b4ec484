"""The robot's C firmware core (``firmware/``) on the host: a ctypes binding of ``libpfw_host.so``.

The C core runs the rules of :class:`pectoral_gym.hardware.radio.firmware.Firmware` and the fins of
:mod:`pectoral_gym.model.strokes` as the robot does: integer-millisecond clock, float32, bytes in, XBee
frames out. ``tests/test_firmware_differential.py`` holds it to the Python reference stream by stream.

Finding the library: ``$PECTORAL_FIRMWARE_LIB`` (a prebuilt ``.so`` for the correct firmware), else
``<repo>/firmware/build/libpfw_host.so`` (``libpfw_host_<variant>.so`` for a deliberately broken variant),
built with ``make -C <repo>/firmware host`` (``variants``) when missing or older than the C sources.
"""

from __future__ import annotations

import ctypes
import fcntl
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pectoral_gym.model.finrules import FirmwareConfig

__all__ = ["VARIANTS", "FIRMWARE_DIR", "CFirmware", "FinStroke", "FinEvent", "build", "library_path", "config_arrays",
           "library_defaults"]

VARIANTS = ("ignore_lease", "ignore_retired_stop", "skip_crc", "latch_midstroke")
FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware"
_ENV = "PECTORAL_FIRMWARE_LIB"
_INFO_NAMES = ("state", "has_session", "session", "boot", "status_seq", "latch_seq", "clipped", "held_back0",
               "held_back1", "has_command_id", "command_id", "power_up_ms", "fins_ms", "lease_end_ms",
               "has_last_valid", "last_valid_ms", "n_retired",
               "duplicate", "stale", "retired", "refused", "copy", "bad_lease", "late", "boot_mismatch",
               "foreign_stop", "tracker_new", "tracker_duplicates", "tracker_stale", "tracker_lost", "tx_dropped",
               "events_dropped", "rx_overflow",
               "frames", "messages", "skipped_bytes", "framing_errors", "truncated", "checksum_errors", "crc_errors",
               "malformed", "other_frames")
_LIBS: dict[str, ctypes.CDLL] = {}


def _sources() -> list[Path]:
    return [*FIRMWARE_DIR.glob("core/**/*.[ch]"), *FIRMWARE_DIR.glob("ports/host/*.c"), FIRMWARE_DIR / "Makefile"]


def library_path(variant: str | None = None) -> Path:
    """The host library of ``variant`` (``None``: the correct firmware), built if missing or stale.

    Raises:
        RuntimeError: Unknown variant, no firmware sources and no ``$PECTORAL_FIRMWARE_LIB``, no C compiler, or a
            failed build (one line each).
    """
    if variant is not None and variant not in VARIANTS:
        raise RuntimeError(f"unknown firmware variant {variant!r}; known: {', '.join(VARIANTS)}")
    if variant is None and os.environ.get(_ENV):
        return Path(os.environ[_ENV])
    name = "libpfw_host.so" if variant is None else f"libpfw_host_{variant}.so"
    lib = FIRMWARE_DIR / "build" / name
    if not (FIRMWARE_DIR / "Makefile").exists():
        raise RuntimeError(f"no firmware sources at {FIRMWARE_DIR}; set ${_ENV} to a prebuilt libpfw_host.so")
    if lib.exists() and lib.stat().st_mtime >= max(p.stat().st_mtime for p in _sources()):
        return lib
    build("host" if variant is None else f"build/{name}")
    return lib


def build(target: str) -> None:
    """``make -C <repo>/firmware <target>``, one build at a time (test workers share the build directory).

    Raises:
        RuntimeError: No make or C compiler, or a failed build (its last line).
    """
    if shutil.which("make") is None or not (shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")):
        raise RuntimeError("building the C firmware needs make and a C compiler (cc or gcc); "
                           f"install them or set ${_ENV} to a prebuilt libpfw_host.so")
    (FIRMWARE_DIR / "build").mkdir(exist_ok=True)
    with open(FIRMWARE_DIR / "build" / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        done = subprocess.run(["make", "-s", "-C", str(FIRMWARE_DIR), target], capture_output=True, text=True)
    if done.returncode != 0:
        last = (done.stderr.strip() or done.stdout.strip()).splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"make -C {FIRMWARE_DIR} {target} failed: {last[0]}")


def _load(variant: str | None) -> ctypes.CDLL:
    key = variant or ""
    if key not in _LIBS:
        lib = ctypes.CDLL(str(library_path(variant)))
        u8p, u32p = ctypes.POINTER(ctypes.c_uint8), ctypes.POINTER(ctypes.c_uint32)
        f32p = ctypes.POINTER(ctypes.c_float)
        lib.pfw_host_size.restype = ctypes.c_size_t
        lib.pfw_host_init.argtypes = [ctypes.c_void_p, f32p, ctypes.POINTER(ctypes.c_uint16), ctypes.c_uint32,
                                      ctypes.c_uint32]
        lib.pfw_host_defaults.argtypes = [f32p, ctypes.POINTER(ctypes.c_uint16)]
        lib.pfw_receive.argtypes = [ctypes.c_void_p, u8p, ctypes.c_size_t, ctypes.c_uint32]
        lib.pfw_tick.argtypes = [ctypes.c_void_p, ctypes.c_uint32]
        lib.pfw_tx_take.argtypes = [ctypes.c_void_p, u8p, ctypes.c_size_t]
        lib.pfw_tx_take.restype = ctypes.c_size_t
        lib.pfw_host_info.argtypes = [ctypes.c_void_p, u32p, ctypes.c_size_t]
        lib.pfw_host_info.restype = ctypes.c_size_t
        lib.pfw_host_fin.argtypes = [ctypes.c_void_p, ctypes.c_uint, f32p]
        lib.pfw_host_event.argtypes = [ctypes.c_void_p, u32p, f32p]
        lib.pfw_uptime_ms.argtypes = [ctypes.c_void_p, ctypes.c_uint32]
        lib.pfw_uptime_ms.restype = ctypes.c_uint32
        _LIBS[key] = lib
    return _LIBS[key]


def config_arrays(config: FirmwareConfig) -> tuple[np.ndarray, np.ndarray]:
    """The C core's configuration from the Python one: ``(limits float32[11], ms uint16[2])``.

    Periods go in ms, the watchdog and the lease cap in whole ms (the robot's clock; anything else is refused).
    """
    lim = config.limits
    limits = np.array([lim.angle_min, lim.angle_max, lim.period_min * 1000.0, lim.period_max * 1000.0, lim.ratio_min,
                       lim.ratio_max, lim.max_speed, *lim.max_rate], dtype=np.float32)
    ms = [1000.0 * config.watchdog_timeout, 1000.0 * config.max_lease]
    if any(abs(v - round(v)) > 1e-9 for v in ms):
        raise ValueError(f"the robot counts whole ms: watchdog_timeout and max_lease must be whole ms, got {ms}")
    return limits, np.array([round(v) for v in ms], dtype=np.uint16)


def library_defaults(variant: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The C header's default configuration (``PFW_DEFAULT_*``), as :func:`config_arrays` gives it."""
    lib = _load(variant)
    limits, ms = np.zeros(11, dtype=np.float32), np.zeros(2, dtype=np.uint16)
    lib.pfw_host_defaults(limits.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
                          ms.ctypes.data_as(ctypes.POINTER(ctypes.c_uint16)))
    return limits, ms


@dataclass(frozen=True)
class FinStroke:
    """A fin's half-stroke in progress (as :mod:`pectoral_gym.model.strokes`' fields; SI units)."""

    angle_from: float  # rad
    angle_to: float  # rad
    duration: float  # s
    elapsed: float  # s, at the fins' time
    power: bool
    pattern: tuple[float, float, float, float]  # bias [rad], amplitude [rad], period [s], ratio
    angle: float  # rad, the fin angle at the fins' time


@dataclass(frozen=True)
class FinEvent:
    """A latch (``kind == "latch"``) or a halt (``"halt"``) of the fins, at clock ``ms + frac_ms`` [ms].

    Latch: ``fin`` started a half-stroke of ``pattern`` (bias, amplitude [rad], period [s], ratio) from ``turn``
    [rad], a power stroke if ``power``; ``still``: it ends where it starts (no LATCH report is sent for it).
    Halt: both fins hold ``angles`` [rad] from then on.
    """

    kind: str
    ms: int
    frac_ms: float
    fin: int = 0
    power: bool = False
    still: bool = False
    turn: float = 0.0
    pattern: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    angles: tuple[float, float] = (0.0, 0.0)


class CFirmware:
    """One robot's firmware: the C core, fed bytes and ticks on its own millisecond clock.

    Contract for an emulator: call :meth:`receive_bytes` with what the robot's XBee delivers (Receive Packet
    ``0x90`` frames) and :meth:`tick` every 10 ms of the robot clock (``now_ms`` is a u32 clock that may wrap);
    send :meth:`take_tx` (Transmit Request ``0x10`` frames: STATUS replies to the asker's ``src64``, LATCH
    reports to the served session's last address). After each call, :meth:`take_events` lists what the fins did
    since the last read, in time order: every latch (still fins' included, flagged ``still``) and every halt. A
    physics model follows the C fins by applying each latch with ``finrules.force_latch(model, fin, t,
    pattern, turn, power)`` at ``t = (ms + frac_ms) / 1000`` on its clock, and holding the fins at ``angles``
    from a halt on; :meth:`fins` gives the half-strokes in progress to check against.

    Args:
        config: The rules' settings (the C core gets these numbers: one source of truth).
        boot: Boot id (nonzero).
        power_up_ms: The clock at power-up (uptime 0); may be "in the past" to start near an uptime wrap.
        variant: ``None``, or one of :data:`VARIANTS` (deliberately broken builds for the conformance suite).
    """

    def __init__(self, config: FirmwareConfig | None = None, boot: int = 1, power_up_ms: int = 0,
                 variant: str | None = None):
        self.config = config or FirmwareConfig()
        self._lib = _load(variant)
        self._mem = ctypes.create_string_buffer(int(self._lib.pfw_host_size()))
        self._fw = ctypes.cast(self._mem, ctypes.c_void_p)
        limits, ms = config_arrays(self.config)
        if self._lib.pfw_host_init(self._fw, limits.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
                                   ms.ctypes.data_as(ctypes.POINTER(ctypes.c_uint16)), int(boot) & 0xFFFFFFFF,
                                   int(power_up_ms) & 0xFFFFFFFF) != 0:
            raise ValueError(f"the C firmware refused the config or boot id {boot!r} (must be nonzero)")

    def receive_bytes(self, data: bytes, now_ms: int) -> None:
        """Bytes from the XBee at clock ``now_ms``: fins run to then, messages handled, fins handed over."""
        buf = (ctypes.c_uint8 * max(len(data), 1)).from_buffer_copy(bytes(data) or b"\0")
        self._lib.pfw_receive(self._fw, buf, len(data), int(now_ms) & 0xFFFFFFFF)

    def tick(self, now_ms: int) -> None:
        """The firmware's tick at clock ``now_ms``: fins run to then, lease and watchdog, hand-over."""
        self._lib.pfw_tick(self._fw, int(now_ms) & 0xFFFFFFFF)

    def take_tx(self) -> bytes:
        """The escaped Transmit Request frames sent since the last call."""
        out = bytearray()
        buf = (ctypes.c_uint8 * 4096)()
        while n := self._lib.pfw_tx_take(self._fw, buf, len(buf)):
            out += bytes(buf[:n])
        return bytes(out)

    def info(self) -> dict[str, int]:
        """State, served session, counters (the rules' ``ignored``, the tracker's, the decoder's), as integers."""
        out = (ctypes.c_uint32 * 64)()
        n = self._lib.pfw_host_info(self._fw, out, 64)
        return dict(zip(_INFO_NAMES, out[:n], strict=True))

    @property
    def state(self) -> int:
        """The robot state (:class:`~pectoral_gym.hardware.radio.protocol.RobotState` value)."""
        return self.info()["state"]

    @property
    def session(self) -> int | None:
        """The served session (``None`` before the first)."""
        info = self.info()
        return info["session"] if info["has_session"] else None

    @property
    def boot(self) -> int:
        """This power-up's boot id."""
        return self.info()["boot"]

    def uptime_ms(self, now_ms: int) -> int:
        """Uptime [ms, u32] at clock ``now_ms``."""
        return int(self._lib.pfw_uptime_ms(self._fw, int(now_ms) & 0xFFFFFFFF))

    def raw_fin(self, fin: int) -> np.ndarray:
        """``float32[23]`` of fin ``fin`` as the core keeps it (``firmware/ports/host/pfw_host.c``).

        From, to [rad], duration, elapsed [ms], power, pattern[4] (period in ms), angle, pending[4], due,
        command[4], setpoint[4].
        """
        out = np.zeros(23, dtype=np.float32)
        self._lib.pfw_host_fin(self._fw, int(fin), out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)))
        return out

    def fins(self) -> list[FinStroke]:
        """Both fins' half-strokes in progress at the fins' time (right fin first)."""
        strokes = []
        for f in range(2):
            r = self.raw_fin(f).astype(float)
            strokes.append(FinStroke(r[0], r[1], r[2] / 1000.0, r[3] / 1000.0, r[4] > 0.5,
                                     (r[5], r[6], r[7] / 1000.0, r[8]), r[9]))
        return strokes

    def fin_angles(self) -> np.ndarray:
        """``(2,)`` fin angles [rad] at the fins' time."""
        return np.array([self.raw_fin(f)[9] for f in range(2)], dtype=float)

    def take_events(self) -> list[FinEvent]:
        """Latches and halts since the last read, oldest first (the core keeps the last 16; ``events_dropped``)."""
        ints, floats = (ctypes.c_uint32 * 5)(), (ctypes.c_float * 8)()
        events = []
        while self._lib.pfw_host_event(self._fw, ints, floats):
            if ints[0] == 1:
                pattern = (float(floats[2]), float(floats[3]), float(floats[4]) / 1000.0, float(floats[5]))
                events.append(FinEvent("latch", int(ints[4]), float(floats[0]), int(ints[1]), bool(ints[2]),
                                       bool(ints[3]), float(floats[1]), pattern))
            else:
                events.append(FinEvent("halt", int(ints[4]), float(floats[0]),
                                       angles=(float(floats[6]), float(floats[7]))))
        return events
