"""Check a robot firmware against the protocol's robot rules over the radio (``pectoral-firmware-check``).

Connects to a robot through its XBee (``--port``, any ``serial_for_url`` URL) or starts an emulated one
(``--emulate``, running the Python reference rules or the C firmware, ``--firmware``), and drives it through one
scripted scenario per rule of ``docs/protocol.md`` section 5. The fins must be free to move (no camera is
used): every verdict comes from the robot's STATUS and LATCH messages and the robot-clock times they carry
(tolerances argued in :mod:`pectoral_gym.hardware.conformance.judge`). Prints a table of rules with PASS, FAIL
or SKIP and the reason. Exit status: 0 every rule passed, 1 a rule failed, 3 none failed but some were skipped
(2: bad arguments).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections.abc import Callable

import numpy as np

from pectoral_gym.hardware.conformance import fins, sessions, timing
from pectoral_gym.hardware.conformance.judge import Broken, Result, Unchecked
from pectoral_gym.hardware.conformance.probe import READ_SLICE, Probe
from pectoral_gym.hardware.emulated_firmware import FIRMWARES
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name

__all__ = ["RULES", "build_parser", "check", "emulated_probe", "main"]

MAX_RTT = 0.45  # slowest round trip the scenarios allow [robot s]: below the watchdog's 0.5 s, with a margin
ATTEMPTS = 3  # runs of a scenario that failed while the radio lost messages (a loss-free failure counts at once)

# One scenario per robot rule, in the order they run; the reboot runs last (it power-cycles the robot).
RULES: dict[str, tuple[str, Callable[[Probe], dict]]] = {
    "lease": ("a SET_FINS then silence: EXPIRED at the lease's end", timing.lease),
    "deadline": ("a deadline before the lease's end stops the fins at the deadline", timing.deadline),
    "watchdog": ("no new message for 0.5 s: WATCHDOG (duplicates do not count)", timing.watchdog),
    "stop_retired": ("a STOP from a retired session halts", sessions.stop_retired),
    "stop_unknown": ("a STOP from an unknown session halts, takes no control", sessions.stop_unknown),
    "claim": ("CLAIM takes over, halts and retires the old session", sessions.claim_takes_over),
    "refused": ("another live session is refused, answered naming the served one", sessions.refused),
    "stale_duplicate": ("a duplicate is acknowledged without effect; a stale one unanswered",
                        sessions.stale_duplicate),
    "copies": ("copies of a command never extend, change or restart it", timing.copies),
    "deadline_never_starts": ("a deadline past, or for another boot, never starts the fins",
                              timing.deadline_never_starts),
    "crc": ("a bad CRC-16 under a good XBee checksum: ignored and counted", sessions.crc),
    "clipping": ("servo limits: CLIPPED flag, every latched pattern within them", fins.clipping),
    "rate_at_latch": ("a moving fin's latched pattern moves at most max_rate x its half-stroke",
                      fins.rate_at_latch),
    "turning_points": ("fins latch only at turning points, a half-stroke apart", fins.turning_points),
    "boot_id": ("boot id nonzero and steady; new after a power-up, uptime from 0", timing.reboot),
}


def check(probe: Probe, rules: list[str] | None = None) -> tuple[dict, list[Result]]:
    """Measure the round trip, then run ``rules`` (default all, :data:`RULES`); the fins are stopped at the end."""
    rtt = probe.measure_rtt()
    if rtt["max"] >= MAX_RTT:
        raise ConnectionError(f"the radio's round trip reaches {rtt['max']:.2f} s: the scenarios need answers within "
                              f"{MAX_RTT} s (a robot's watchdog halts it after 0.5 s without a message)")
    results = []
    try:
        for name in rules or list(RULES):
            results.append(_run_rule(probe, name))
    finally:
        closer = probe.session()  # a STOP needs no authority: leave the fins still whatever happened
        probe.exchange(closer.message(pr.MsgType.STOP), expect=False)
    return rtt, results


def _run_rule(probe: Probe, name: str, attempts: int = ATTEMPTS) -> Result:
    """One rule's scenario; run again (up to ``attempts`` in all) when it failed while the radio lost messages."""
    for attempt in range(1, attempts + 1):
        mark = probe.mark()
        if attempt > 1:
            probe.cache.clear()  # a fresh run of what several scenarios judge
        try:
            figures = RULES[name][1](probe)
            return Result(name, "PASS", RULES[name][0], {**figures, **({"attempts": attempt} if attempt > 1 else {})})
        except Unchecked as err:
            return Result(name, "SKIP", str(err))
        except Broken as err:
            lost = probe.lost_since(mark)
            if not lost or attempt == attempts:
                note = f" ({attempts} attempts, each losing messages)" if lost else ""
                return Result(name, "FAIL", str(err) + note, {"attempts": attempt, "lost": lost})
    raise AssertionError("unreachable")


@contextlib.contextmanager
def emulated_probe(firmware: str = "python", variant: str | None = None, seed: int = 0, lockstep: bool = True,
                   speed: float = 1.0, latency: float = 0.0, loss: float = 0.0):
    """A :class:`Probe` on an emulated robot started here (lockstep on a virtual clock, or real time over TCP).

    Args:
        firmware: ``"python"`` (the reference rules), ``"c"`` (the C firmware through its binding) or
            ``"python-10ms"`` (the reference ticked as the C firmware is).
        variant: A deliberately broken build of the C firmware (``"ignore_lease"``, ...), for the suite's own test.
        seed: Seed of the robot's boot ids and of the probe's session ids.
        lockstep: Run on a :class:`~pectoral_gym.hardware.clock.VirtualClock` (as fast as the CPU allows).
        speed: Emulated seconds per wall second (real time only).
        latency: One-way radio delay [s] between probe and robot (lockstep only).
        loss: Probability that a frame is lost, each way (lockstep only).
    """
    from pectoral_gym.hardware.clock import REAL_CLOCK, VirtualClock
    from pectoral_gym.hardware.emulator import EmulatedRobot
    from pectoral_gym.hardware.radio.channel import RadioChannel
    from pectoral_gym.hardware.radio.pipe import StreamPair

    rng = np.random.default_rng([seed, 1])
    options = {"firmware_impl": firmware, "variant": variant} if firmware != "python" or variant else {}
    with contextlib.ExitStack() as stack:
        if lockstep:
            clock = VirtualClock()
            pair = StreamPair(clock, RadioChannel(latency, loss, seed=seed) if latency or loss else None)
            robot = EmulatedRobot(speed=1.0, seed=seed, clock=clock, stream=pair.robot, **options).start()
            stack.callback(robot.stop)
            probe = Probe(pair.pc, clock, rng=rng)
        else:
            import serial

            robot = EmulatedRobot(port=0, speed=speed, seed=seed, **options).start()
            stack.callback(robot.stop)
            port = serial.serial_for_url(robot.url, timeout=READ_SLICE)
            stack.callback(port.close)
            probe = Probe(port, REAL_CLOCK, speed=speed, rng=rng)
        probe.reboot_robot = robot.reboot
        yield probe


def report_table(results: list[Result], rtt: dict) -> str:
    """The human-readable table."""
    width = max(len(r.rule) for r in results)
    lines = [f"round trip: median {1000 * rtt['median']:.1f} ms, max {1000 * rtt['max']:.1f} ms "
             f"({rtt['answered']}/{rtt['sent']} answered); reply timeout {1000 * rtt['reply_timeout']:.0f} ms", ""]
    lines += [f"{r.rule:<{width}}  {r.verdict:<4}  {r.reason}" for r in results]
    counts = {v: sum(r.verdict == v for r in results) for v in ("PASS", "FAIL", "SKIP")}
    lines += ["", f"{counts['PASS']} passed, {counts['FAIL']} failed, {counts['SKIP']} skipped"]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-firmware-check``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-firmware-check", "pectoral_gym.hardware.firmware_check"),
        description=("Check a robot firmware against the robot rules of the radio protocol (docs/protocol.md, "
                     "section 5), one scripted scenario per rule, over the radio: a robot on --port (its fins free "
                     "to move; no camera) or an emulated one (--emulate) running the Python reference or the C "
                     "firmware. Verdicts come from the robot's STATUS and LATCH messages and the robot-clock times "
                     "they carry, so the radio's latency does not enter them. Prints PASS, FAIL or SKIP per rule "
                     "with the reason. Exit status: 0 every rule passed, 1 a rule failed (or no robot answered), "
                     "3 none failed but some were skipped, 2 bad arguments."),
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-firmware-check --emulate",
                        "pectoral-firmware-check --port /dev/ttyUSB0 --dest64 0013A20041B2C3D4",
                        "pectoral-firmware-check --emulate --firmware c --json report.json",
                        "pectoral-firmware-check --emulate --firmware c --variant ignore_lease   # must fail",
                        note="The round trip is measured first; the scenarios need it below 0.45 s."))
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--port", metavar="URL", help="the PC's XBee: a serial device or serial_for_url URL")
    where.add_argument("--emulate", action="store_true", help="start an emulated robot in this process")
    parser.add_argument("--baudrate", type=int, default=57600, help="serial speed (default %(default)s)")
    parser.add_argument("--dest64", default=None, metavar="HEX",
                        help="the robot XBee's 64-bit address (default broadcast)")
    parser.add_argument("--firmware", choices=FIRMWARES, default="python",
                        help="with --emulate: the reference rules, the C firmware, or the reference ticked every 10 "
                             "ms as the C firmware is (default %(default)s)")
    parser.add_argument("--variant", default=None, metavar="NAME",
                        help="with --firmware c: a deliberately broken build (ignore_lease, ignore_retired_stop, "
                             "skip_crc, latch_midstroke), to see the suite catch it")
    parser.add_argument("--realtime", action="store_true",
                        help="with --emulate: run in real time over TCP instead of lockstep")
    parser.add_argument("--speed", type=float, default=1.0, help="with --realtime: emulated s per wall s")
    parser.add_argument("--radio-latency", type=float, default=0.0, metavar="S",
                        help="with --emulate (lockstep): one-way radio delay (default 0)")
    parser.add_argument("--radio-loss", type=float, default=0.0, metavar="P",
                        help="with --emulate (lockstep): probability of losing a frame, each way (default 0)")
    parser.add_argument("--seed", type=int, default=0, help="with --emulate: seed of boot and session ids")
    parser.add_argument("--rules", nargs="+", choices=list(RULES), metavar="RULE",
                        help=f"run only these rules (default all: {', '.join(RULES)})")
    parser.add_argument("--json", nargs="?", const="-", default=None, metavar="PATH",
                        help="write the report as JSON to PATH (or stdout with no PATH)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the suite; the exit status says whether the firmware conforms."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.port and (args.firmware != "python" or args.variant or args.realtime):
        parser.error("--firmware, --variant and --realtime need --emulate")
    if args.variant and args.firmware != "c":
        parser.error("--variant needs --firmware c")
    if not (args.speed > 0 and args.radio_latency >= 0 and 0 <= args.radio_loss < 1):
        parser.error("--speed must be > 0, --radio-latency >= 0 and --radio-loss in [0, 1)")
    try:
        dest64 = xb.BROADCAST if args.dest64 is None else int(args.dest64, 16)
    except ValueError:
        parser.error(f"--dest64 must be 16 hex digits, got {args.dest64!r}")
    if args.port and "://" not in args.port and dest64 == xb.BROADCAST:
        print("pectoral-firmware-check: messages are broadcast, so every robot on this radio channel obeys them; "
              "pass --dest64 <the robot XBee's address>", file=sys.stderr)
    started = time.monotonic()
    try:
        with contextlib.ExitStack() as stack:
            if args.emulate:
                probe = stack.enter_context(emulated_probe(args.firmware, args.variant, args.seed, not args.realtime,
                                                           args.speed, args.radio_latency, args.radio_loss))
            else:
                import serial

                port = stack.enter_context(serial.serial_for_url(args.port, baudrate=args.baudrate, timeout=READ_SLICE))
                probe = Probe(port, dest64=dest64)
            rtt, results = check(probe, args.rules)
    except (OSError, ValueError, ConnectionError, RuntimeError) as err:
        print(f"pectoral-firmware-check: {err}", file=sys.stderr)
        return 1
    report = {"target": "emulator" if args.emulate else args.port, "firmware": args.firmware if args.emulate else None,
              "variant": args.variant, "rtt": rtt, "wall_time": round(time.monotonic() - started, 2),
              "results": [r.__dict__ for r in results], "passed": all(r.verdict == "PASS" for r in results)}
    if args.json == "-":
        print(json.dumps(report, indent=2))
    else:
        print(report_table(results, rtt))
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(report, fh, indent=2)
    if any(r.verdict == "FAIL" for r in results):
        return 1
    return 0 if report["passed"] else 3


if __name__ == "__main__":
    raise SystemExit(main())
