"""The PC stack's RadioLink against the firmware on a simulated ATmega2560 (simavr), in real time.

Starts ``pfw_simavr --tcp 0 --realtime`` on the AVR build, connects
:class:`pectoral_gym.hardware.radio.link.RadioLink` to it (``socket://127.0.0.1:PORT``, the same URL form as the
emulator's), waits for the robot's first STATUS, commands both fins for ``--seconds``, stops them, and prints
what the link saw (STATUS states, LATCH reports) and what the simulated servo pins did (pulse widths).

Usage (from the repository root, after ``make -C firmware avr avr-sim``)::

    .venv/bin/python firmware/ports/avr/sim/radiolink_demo.py [--seconds 3] [--servo-log FILE]

Exit status 0 when the exchange worked: a STATUS RUNNING after SET_FINS, LATCH reports, servo pulses that moved,
STOPPED after STOP.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

FIRMWARE = Path(__file__).resolve().parents[3]  # firmware/
ELF = FIRMWARE / "build" / "avr" / "pfw_avr.elf"
SIM = FIRMWARE / "build" / "avr" / "pfw_simavr"


@dataclass
class Exchange:
    """What one run showed: the link's view and the simulator's."""

    boot: int = 0
    states: list[tuple[float, int]] = field(default_factory=list)  # (PC time since start [s], STATUS state)
    latches: int = 0
    rtt: float | None = None
    report: dict = field(default_factory=dict)  # the simulator's JSON report
    servo_log: list[tuple[float, int, float]] = field(default_factory=list)  # (sim ms, pin, width [us])


def run(seconds: float = 3.0, servo_log: str | None = None, beats: np.ndarray | None = None) -> Exchange:
    """Run the exchange; raises ``RuntimeError`` with the reason if the simulator or the link fails."""
    from pectoral_gym.hardware.radio.link import RadioLink
    from pectoral_gym.hardware.radio.protocol import RobotState

    if not (ELF.exists() and SIM.exists()):
        raise RuntimeError("build first: make -C firmware avr avr-sim")
    if beats is None:  # right and left fin: bias, amplitude [rad], period [s], ratio
        beats = np.array([[math.radians(90), math.radians(40), 1.0, 2.0],
                          [math.radians(90), math.radians(25), 1.0, 1.0]])
    out = Exchange()
    with tempfile.TemporaryDirectory() as tmp:
        report_path = os.path.join(tmp, "report.json")
        log_path = servo_log or os.path.join(tmp, "servo.log")
        proc = subprocess.Popen([str(SIM), "--tcp", "0", "--realtime", "--report", report_path, "--servo-log",
                                 log_path, "--adc-seed", str(int(time.time()) & 0xFFFF), str(ELF)],
                                stdout=subprocess.PIPE, text=True)
        try:
            url = _wait_url(proc)
            link = RadioLink(url)
            try:
                t0 = time.monotonic()
                if not _wait(lambda: link.last_status is not None, 5.0):
                    raise RuntimeError("no STATUS from the simulated robot within 5 s")
                out.boot = int(link.boot or 0)
                seq = link.set_fins(beats, lease=0.8)
                if not link.wait_ack(seq, 2.0):
                    raise RuntimeError("SET_FINS not acknowledged within 2 s")
                end = time.monotonic() + seconds
                while time.monotonic() < end:  # a controller's step(): a new command identity every 0.5 s
                    out.states.append((time.monotonic() - t0, int(link.last_status.state)))
                    time.sleep(0.5)
                    link.set_fins(beats, lease=0.8)
                out.latches = len(link.drain_latches())
                out.rtt = link.rtt()
                stopped = link.stop(wait=2.0)
                out.states.append((time.monotonic() - t0, int(link.last_status.state)))
                if not stopped or link.last_status.state != RobotState.STOPPED:
                    raise RuntimeError(f"STOP not confirmed (last state {link.last_status.state})")
            finally:
                link.close()
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=10)
        with open(report_path) as fh:
            out.report = json.load(fh)
        with open(log_path) as fh:
            out.servo_log = [(float(a), int(b), float(c)) for a, b, c in (line.split() for line in fh)]
    return out


def _wait_url(proc: subprocess.Popen) -> str:
    """The simulator's ``socket://`` URL, from its first lines of output."""
    assert proc.stdout is not None
    for _ in range(20):
        line = proc.stdout.readline()
        if not line:
            break
        if line.startswith("listening "):
            return line.split()[1]
    raise RuntimeError("pfw_simavr did not start listening")


def _wait(predicate, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def main() -> int:
    """Run the exchange once and print it; 0 if it worked (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="how long the fins run [s] (default 3)")
    parser.add_argument("--servo-log", help="keep the servo pulse log here (sim ms, pin 0/1, width us)")
    args = parser.parse_args()
    try:
        ex = run(args.seconds, args.servo_log)
    except RuntimeError as err:
        print(f"radiolink_demo: {err}", file=sys.stderr)
        return 1
    widths = [w for _, _, w in ex.servo_log[2:]]
    print(f"boot id {ex.boot:#010x}; STATUS states over time: {ex.states}")
    print(f"LATCH reports received: {ex.latches}; RTT estimate {ex.rtt}")
    print(f"servo pulses: {ex.report['servos']}; logged width changes: {len(ex.servo_log)}, "
          f"range {min(widths, default=0):.1f}..{max(widths, default=0):.1f} us")
    print(f"simulated {ex.report['sim_ms']:.0f} ms; uart {ex.report['uart']}; longest step "
          f"{ex.report['probes'][0]['max_cycles']} cycles")
    running = any(state == 1 for _, state in ex.states)
    ok = running and ex.latches > 0 and len(widths) > 10 and ex.states[-1][1] == 2
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
