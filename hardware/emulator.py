"""Emulated robotic fish: speaks the radio protocol, runs the full model, obeys the firmware rules.

Use it in-process (:class:`EmulatedRobot`, as ``pectoral_gym.hardware.deploy --emulate`` and the tests do) or as a
process that listens on a pseudo-terminal or a TCP port (``pectoral-emulator``, also
``python -m pectoral_gym.hardware.emulator``)::

    pectoral-emulator                       # prints the pty path, e.g. /dev/pts/7
    pectoral-emulator --port 5700 --camera-port 5600 --speed 2

then ``pectoral-deploy --port socket://127.0.0.1:5700 --camera emu://127.0.0.1:5600 ...``.

The emulator stands in for both XBee modules and the dsPIC: it reads the PC's Transmit Request frames
and answers with Receive Packet frames. Its clock runs ``speed`` times faster than the PC's clock
(:mod:`pectoral_gym.hardware.clock`; the wall clock by default); every time it reports (pose timestamps)
is on that clock's base, so the PC side scales with the same ``speed``. On a
:class:`pectoral_gym.hardware.clock.VirtualClock` with a :class:`pectoral_gym.hardware.radio.pipe.StreamPair` end as
its radio (``stream``), it runs in lockstep with the PC's threads (``deploy --emulate --lockstep``).
Firmware times (watchdog, lease) are emulated-robot seconds. Several
PCs may connect at once (like radios on one channel): every connection is heard and hears every reply;
the firmware's session rule decides whom the robot obeys.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import socket
import threading
import time

import numpy as np

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.emulated_firmware import FIRMWARES, ROBOT_ADDRESS, make_firmware
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio.firmware import new_boot_id
from pectoral_gym.hardware.realtime import settle_garbage
from pectoral_gym.model.finrules import CHUNK as _CHUNK
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FinBeat, FishParams
from pectoral_gym.model.spec import FULL_REFERENCE, FullSpec
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name

__all__ = ["EmulatedRobot", "RECEIVED_KEPT", "ROBOT_ADDRESS", "build_parser", "main"]

_POLL = 0.002  # poll period of the I/O loop [clock s]
# EmulatedRobot.received keeps at least the newest RECEIVED_KEPT messages and at most twice as many: older ones
# are dropped in one block, so a long run's memory stays bounded (about 20 messages per emulated second with the
# default link: over 8 emulated minutes kept) while the list keeps its indexing for tests.
RECEIVED_KEPT = 10_000


class EmulatedRobot:
    """One emulated fish behind a byte stream.

    Args:
        port: TCP port to listen on (0 picks a free one); ``None`` with ``pty=True`` uses a pseudo-terminal.
        pty: Listen on a pseudo-terminal instead of TCP (``url`` is the slave device path).
        host: TCP interface.
        speed: Emulated seconds per wall-clock second (1 = real time).
        params: Model parameters (Table 1 defaults).
        firmware: Robot-side rules (watchdog, servo limits).
        start_pose: Initial ``(X, Y, psi)`` [m, m, rad]; default the tank centre, heading +X.
        loss: Probability that an incoming message is lost (radio loss injection for tests).
        camera_port: Serve rendered overhead frames on this TCP port
            (``pectoral_gym.hardware.vision.camera.FrameServer``).
        camera_fps: Frame rate of the served camera [wall frames/s].
        seed: Seed of the loss injection and camera noise.
        model: The physics the emulated fish follows (a full-model spec; default the reference integration).
        clock: The clock of the emulation loop (:mod:`pectoral_gym.hardware.clock`); every stamp is on it.
        stream: The robot's end of a :class:`pectoral_gym.hardware.radio.pipe.StreamPair` as its radio, instead
            of a TCP port or a pseudo-terminal (``port`` and ``pty`` are then ignored).
        firmware_impl: The robot's rules: ``"python"`` (the reference state machine), ``"c"`` (the C firmware
            core through its binding) or ``"python-10ms"`` (the reference ticked every 10 ms as the C core is),
            :mod:`pectoral_gym.hardware.emulated_firmware`.
        variant: With ``"c"``: a deliberately broken build of the C core (for the conformance suite's own tests).
    """

    def __init__(self, port: int | None = 0, pty: bool = False, host: str = "127.0.0.1", speed: float = 1.0,
                 params: FishParams | None = None, firmware: FirmwareConfig | None = None,
                 start_pose: tuple[float, float, float] | None = None, loss: float = 0.0,
                 camera_port: int | None = None, camera_fps: float = 30.0, seed: int | None = None,
                 model: FullSpec = FULL_REFERENCE, clock: Clock = REAL_CLOCK, stream=None,
                 firmware_impl: str = "python", variant: str | None = None):
        if not isinstance(model, FullSpec):
            raise ValueError(f"model must be a FullSpec (pectoral_gym.model.spec), got {model!r}")
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a finite number > 0, got {speed!r}")
        if not 0.0 <= loss < 1.0:
            raise ValueError(f"loss must be in [0, 1), got {loss!r}")
        self.speed = float(speed)
        self.loss = float(loss)
        self.model = model.build(1, params)
        model.build(1, params).advance(_CHUNK)  # load the compiled kernels now, not while the PC waits for acks
        self._rng = np.random.default_rng(seed)
        self._firmware_config = firmware
        self.firmware_impl = firmware_impl
        # emulated clock from 0
        self.rules = make_firmware(firmware_impl, firmware, new_boot_id(self._rng), variant)
        self.reboots = 0
        self.received: list[pr.Message] = []  # the newest valid messages (RECEIVED_KEPT), in arrival order
        self.lost_messages = 0
        # With a list here, every physics chunk appends (t, state (6,), fin rates (2,), peak rates of the
        # half-strokes in progress (2,), running): "stopped within" and servo checks on the emulated clock.
        self.trace: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, bool]] | None = None
        self._seed = seed
        self.clock = clock
        self._lock = threading.Lock()
        self._stop = clock.event()
        self._thread: threading.Thread | None = None
        self._origin = clock.monotonic()
        self._stream = stream
        self._clients: list[socket.socket] = []
        self._listener: socket.socket | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._frame_server = None
        self._camera_port, self._camera_fps = camera_port, float(camera_fps)
        if stream is not None:
            self.url = "stream://"
        elif pty:
            self._master, self._slave = os.openpty()
            self.url = os.ttyname(self._slave)
        else:
            self._listener = socket.create_server((host, 0 if port is None else int(port)))
            self._listener.setblocking(False)
            self.host, self.port = self._listener.getsockname()[:2]
            self.url = f"socket://{self.host}:{self.port}"
        self.place(*(start_pose or (0.5 * TANK_LENGTH, 0.5 * TANK_WIDTH, 0.0)))

    # ------------------------------------------------------------ clock and state
    @property
    def firmware(self):
        """The robot's rules as tests inspect them: ``state``, ``running``, ``boot`` (a ``Firmware`` in Python)."""
        return self.rules.firmware

    @property
    def decoder(self):
        """Counters of what the robot received (``messages``, ``crc_errors``, ...)."""
        return self.rules.decoder

    def now(self) -> float:
        """Emulated time since :meth:`start` [s]."""
        return (self.clock.monotonic() - self._origin) * self.speed

    def place(self, x: float, y: float, psi: float) -> None:
        """Put the fish at rest at ``(x, y, psi)`` with both fins still where they are (a hand in the tank)."""
        with self._lock:
            time_now = self.model.time
            angles = self.model.fin_angles()[0][0]  # a hand moves the fish, not the servos
            self.model.reset(np.array([x, y, psi, 0.0, 0.0, 0.0]), right=FinBeat.rest(float(angles[0])),
                             left=FinBeat.rest(float(angles[1])), index=np.arange(1))
            self.model.time = time_now

    def state(self) -> np.ndarray:
        """``(6,)`` true state ``X, Y, psi, vx, vy, omega``."""
        with self._lock:
            return self.model.state[0].copy()

    def pose(self) -> tuple[float, float, float]:
        """True ``(X, Y, psi)`` [m, m, rad]."""
        return self.pose_stamped()[0]

    def pose_stamped(self) -> tuple[tuple[float, float, float], float]:
        """True pose and the ``clock.monotonic()`` instant it belongs to (``EmulatedCamera``'s ``pose_fn``)."""
        with self._lock:
            x, y, psi = self.model.state[0, :3].tolist()
            stamp = self._origin + self.model.time / self.speed
        return (x, y, psi), stamp

    def fin_rates(self) -> np.ndarray:
        """``(2,)`` fin angular rates [rad/s] (right, left); zero when the fins are still."""
        with self._lock:
            return self.model.fin_angles()[1][0].copy()

    def reboot(self) -> int:
        """A brown-out: the robot powers up again now; returns the new boot id.

        The fins halt where they are, the firmware starts from power-up (state IDLE, no session served,
        sequence numbering afresh, uptime from 0) with a new random boot id, and a frame half received
        is lost. The fish keeps coasting (the physics does not reboot).
        """
        with self._lock:
            boot = new_boot_id(self._rng)
            self.rules.reboot(self.model.time, self.model, boot)
            self.reboots += 1
            return boot

    def camera(self, conditions=None, seed: int | None = None, camera=None):
        """An in-process ``pectoral_gym.hardware.vision.camera.EmulatedCamera`` looking at this fish."""
        from pectoral_gym.hardware.vision.camera import EmulatedCamera

        return EmulatedCamera(self.pose_stamped, camera, conditions, self._seed if seed is None else seed)

    # ------------------------------------------------------------ life cycle
    def start(self) -> EmulatedRobot:
        """Start the emulation thread (and the frame server); returns ``self``."""
        if self._thread is not None:
            return self
        settle_garbage()  # nothing runs yet: the collections that fall later walk only what the emulation makes
        self._origin = self.clock.monotonic() - self.model.time / self.speed
        self._thread = self.clock.thread(self._run, "emulated-robot")
        self._thread.start()
        if self._camera_port is not None:
            from pectoral_gym.hardware.vision.camera import FrameServer

            self._frame_server = FrameServer(self.camera(), port=self._camera_port, fps=self._camera_fps)
        return self

    @property
    def camera_spec(self) -> str | None:
        """``emu://host:port`` of the frame server, if one is running."""
        return None if self._frame_server is None else self._frame_server.spec

    def stop(self) -> None:
        """Stop the emulation and close every endpoint (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._frame_server is not None:
            self._frame_server.close()
            self._frame_server = None
        if self._stream is not None:
            self._stream.close()
        for sock in (*self._clients, self._listener):
            if sock is not None:
                sock.close()
        self._clients, self._listener = [], None
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    def __enter__(self) -> EmulatedRobot:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------ emulation loop
    def _run(self) -> None:
        while not self._stop.is_set():
            data = self._poll()
            self._advance(self.now())  # the model at the time the firmware hears the message
            if data:
                self._handle(data)

    def _poll(self) -> bytes:
        if self._stream is not None:
            # Woken by the bytes themselves: no need to poll faster than the firmware ticks (every _CHUNK)
            if self._stream.is_open:
                return self._stream.read(4096, timeout=_CHUNK / self.speed)
            self.clock.sleep(_CHUNK / self.speed)  # never spin: on a virtual clock that would stop every other thread
            return b""
        if self._master is not None:
            ready, _, _ = select.select([self._master], [], [], _POLL)
            if ready:
                try:
                    return os.read(self._master, 4096)
                except OSError:
                    return b""
            return b""
        fds = [self._listener, *self._clients]
        try:
            ready, _, _ = select.select(fds, [], [], _POLL)
        except (OSError, ValueError):
            return b""
        data = b""
        for sock in ready:
            if sock is self._listener:
                try:
                    client, _ = self._listener.accept()
                except OSError:
                    continue
                self._clients.append(client)  # a new connection joins the channel; nobody is dropped
                continue
            try:
                chunk = sock.recv(4096)
            except OSError:
                chunk = b""
            if not chunk:
                sock.close()
                self._clients.remove(sock)
            data += chunk  # one decoder: frames cut by interleaving are dropped and resynchronised
        return data

    def _write(self, raw: bytes) -> None:
        try:
            if self._stream is not None:
                self._stream.write(raw)
            if self._master is not None:
                os.write(self._master, raw)
            for client in list(self._clients):
                client.sendall(raw)
        except OSError:
            pass

    def _handle(self, data: bytes) -> None:
        with self._lock:
            frames, messages = self.rules.receive(data, self.now(), self.model, self._keep, self.trace)
            self.received += messages
            if len(self.received) > 2 * RECEIVED_KEPT:
                del self.received[:-RECEIVED_KEPT]
        for frame in frames:
            self._write(frame)

    def _keep(self) -> bool:
        """Whether the next incoming message survives the injected loss (counted when not)."""
        if self.loss and self._rng.random() < self.loss:
            self.lost_messages += 1
            return False
        return True

    def _advance(self, target: float) -> None:
        with self._lock:
            frames = self.rules.advance(self.model, target, self.trace)
        for frame in frames:  # the servo controller reports its latches at once, fire and forget
            self._write(frame)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-emulator``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-emulator", "pectoral_gym.hardware.emulator"),
        description=__doc__.split("\n\n")[0] + " Runs until Ctrl-C (or --duration).",
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-emulator",
                        "pectoral-emulator --port 5700 --camera-port 5600 --speed 2",
                        "pectoral-deploy --port socket://127.0.0.1:5700 --camera emu://127.0.0.1:5600 "
                        "--controller hand --speed 2   # in a second shell",
                        note="The pseudo-terminal or port it prints is the --port of pectoral-deploy."))
    parser.add_argument("--port", type=int, default=None, metavar="TCP_PORT",
                        help="listen on this TCP port (default: a pseudo-terminal)")
    parser.add_argument("--host", default="127.0.0.1", help="TCP interface (default %(default)s)")
    parser.add_argument("--speed", type=float, default=1.0, help="emulated seconds per wall second (default 1)")
    parser.add_argument("--watchdog", type=float, default=0.5, metavar="S",
                        help="firmware watchdog timeout, <= 1 s (default %(default)s)")
    parser.add_argument("--camera-port", type=int, default=None, help="serve overhead camera frames on this port")
    parser.add_argument("--camera-fps", type=float, default=30.0, help="served frame rate (default %(default)s)")
    parser.add_argument("--start", type=float, nargs=3, metavar=("X", "Y", "PSI_DEG"), default=None,
                        help="start pose [m, m, deg] (default: tank centre, heading +X)")
    parser.add_argument("--loss", type=float, default=0.0, help="probability of losing an incoming message")
    parser.add_argument("--seed", type=int, default=None, help="seed of loss injection and camera noise")
    parser.add_argument("--duration", type=float, default=None, metavar="S", help="exit after this many wall s")
    parser.add_argument("--firmware", choices=FIRMWARES, default="python",
                        help="the robot's rules: the Python reference, the C firmware core, or the reference ticked "
                             "every 10 ms as the C core is (default %(default)s)")
    parser.add_argument("--variant", default=None, metavar="NAME",
                        help="with --firmware c: a deliberately broken build (as pectoral-firmware-check --variant)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run an emulated robot until Ctrl-C (or ``--duration``)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    start = None if args.start is None else (args.start[0], args.start[1], math.radians(args.start[2]))
    try:
        robot = EmulatedRobot(port=args.port, pty=args.port is None, host=args.host, speed=args.speed,
                              firmware=FirmwareConfig(watchdog_timeout=args.watchdog), start_pose=start,
                              loss=args.loss, camera_port=args.camera_port, camera_fps=args.camera_fps,
                              seed=args.seed, firmware_impl=args.firmware, variant=args.variant)
    except (ValueError, OSError, RuntimeError) as err:
        parser.error(str(err))
    robot.start()
    print(f"emulated robot listening on {robot.url}", flush=True)
    if robot.camera_spec:
        print(f"camera frames on {robot.camera_spec}", flush=True)
    deadline = None if args.duration is None else time.monotonic() + args.duration
    try:
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        robot.stop()
        x, y, psi = robot.pose()
        print(f"stopped at X={x:.3f} m, Y={y:.3f} m, psi={math.degrees(psi):.1f} deg; "
              f"{robot.decoder.messages} messages, firmware state {robot.firmware.state.name}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
