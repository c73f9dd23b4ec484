"""The firmware's microcontroller ports (firmware/ports/avr, firmware/ports/dspic; docs/firmware.md).

The AVR port is built with avr-gcc and run on simavr's ATmega2560 (instruction level, cycle counted) through the
harness firmware/ports/avr/sim/pfw_simavr.c; the dsPIC30F6014 port's C is checked with the host compiler against
register stubs (XC16 is proprietary and not on CI). Tests skip with the reason when a tool is missing: the Debian
packages gcc-avr, avr-libc, binutils-avr, simavr, libsimavr-dev, libelf-dev, pkg-config provide them all.
"""

from __future__ import annotations

import fcntl
import json
import math
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
AVR_BUILD = FIRMWARE / "build" / "avr"
DSPIC_FLASH, DSPIC_RAM = 144 * 1024, 8 * 1024  # the robot's dsPIC30F6014: program flash, RAM [bytes]
AVR_HZ = 16_000_000  # the simulated ATmega2560's clock
TICK_S = 0.010  # the firmware's tick


def _make(*targets: str) -> subprocess.CompletedProcess:
    """``make -C firmware targets``, one at a time across test workers (pytest -n: they share firmware/build)."""
    (FIRMWARE / "build").mkdir(exist_ok=True)
    with open(FIRMWARE / "build" / ".ports-make.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return subprocess.run(["make", "-C", str(FIRMWARE), *targets], capture_output=True, text=True, timeout=600)


def _need_avr_gcc() -> None:
    for tool in ("avr-gcc", "avr-size", "avr-nm", "make"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} not installed (Debian: gcc-avr avr-libc binutils-avr)")


def _need_simavr() -> None:
    _need_avr_gcc()
    found = shutil.which("pkg-config") and subprocess.run(["pkg-config", "--exists", "simavr"]).returncode == 0
    if not found:
        pytest.skip("libsimavr not installed (Debian: simavr libsimavr-dev libelf-dev pkg-config)")


@pytest.fixture(scope="module")
def avr_build() -> Path:
    _need_avr_gcc()
    done = _make("avr")
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return AVR_BUILD / "pfw_avr.elf"


@pytest.fixture(scope="module")
def simulator(avr_build) -> Path:
    _need_simavr()
    done = _make("avr-sim")
    assert done.returncode == 0, done.stderr[-2000:]
    return AVR_BUILD / "pfw_simavr"


def _sections(elf: Path) -> dict[str, int]:
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    return {parts[0]: int(parts[1]) for parts in (line.split() for line in out.splitlines()) if len(parts) >= 2
            and parts[1].isdigit()}


def test_avr_build_fits_the_dspic_budget(avr_build):
    sections = _sections(avr_build)
    flash = sections[".text"] + sections.get(".data", 0)  # initial values of .data live in flash too
    static_ram = sections.get(".data", 0) + sections[".bss"]
    assert 4096 < flash <= DSPIC_FLASH  # a real program, not an empty build
    assert 1024 < static_ram <= DSPIC_RAM // 2  # the rules' state (pfw_app), leaving half the RAM for the stack
    summary = (AVR_BUILD / "size.txt").read_text()
    assert f"flash {flash} bytes" in summary and f"static RAM {static_ram} bytes" in summary


def test_avr_worst_step_fits_the_tick_and_the_ram(simulator):
    done = _make("avr-timing")
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    report = json.loads((AVR_BUILD / "timing.json").read_text())
    every, worst, latches = report["probes"]
    assert report["state"] != 7, "the simulated MCU crashed"  # cpu_Crashed
    # The constructed steps happened, and both fins latched in each (timing_avr.c pulses PA2 per moving latch).
    assert worst["count"] >= 20
    assert latches["count"] == 2 * worst["count"]
    # They are the longest of all ~20000 steps of the run, and even on the 16 MHz AVR they end within a tick.
    assert every["max_cycles"] <= worst["max_cycles"]
    assert worst["max_cycles"] / AVR_HZ < TICK_S
    # Static RAM plus the deepest stack the run reached fit in 8 KB.
    static_ram = report["stack"]["floor"] - 0x200  # the ATmega2560's RAM starts at 0x200; the floor is _end
    assert 0 < report["stack"]["used_bytes"] < 2048
    assert static_ram + report["stack"]["used_bytes"] < DSPIC_RAM


def _frame(message: pr.Message) -> bytes:
    """What the PC writes to its XBee: a Transmit Request carrying ``message`` (the PC stack's own encoder)."""
    return xb.encode_frame(xb.tx_request(pr.encode_message(message)))


def _status_of(sim: Path, elf: Path, adc_seed: int, session: int) -> pr.Status:
    """Start the simulated robot, send one HEARTBEAT, return the STATUS that answers it."""
    proc = subprocess.Popen([str(sim), "--tcp", "0", "--adc-seed", str(adc_seed), "--report", "/dev/null",
                             str(elf)], stdout=subprocess.PIPE, text=True)
    try:
        url = next(line.split()[1] for line in proc.stdout if line.startswith("listening "))
        host, port = url.removeprefix("socket://").split(":")
        with socket.create_connection((host, int(port)), timeout=10) as conn:
            time.sleep(0.3)  # the robot finishes its power-up (boot id) before it reads the UART
            conn.sendall(_frame(pr.Message(pr.MsgType.HEARTBEAT, 1, session)))
            decoder, deadline = pr.StreamDecoder(), time.monotonic() + 10
            while time.monotonic() < deadline:
                for msg in decoder.feed(conn.recv(4096)):
                    if msg.type == pr.MsgType.STATUS:
                        assert msg.session == session  # addressed to the asker
                        return msg.status
        raise AssertionError("no STATUS within 10 s")
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_avr_answers_a_heartbeat_and_draws_its_boot_id_from_noise(simulator, avr_build):
    session = 0x0BADCAFE
    first = _status_of(simulator, avr_build, adc_seed=11, session=session)
    assert first.served == session and first.ack_seq == 1 and first.ack_type == pr.MsgType.HEARTBEAT
    assert first.state == pr.RobotState.IDLE and first.boot != 0
    # simavr starts every run with an erased EEPROM (the power-up counter repeats): the boot id follows the ADC noise.
    assert _status_of(simulator, avr_build, adc_seed=11, session=session).boot == first.boot
    assert _status_of(simulator, avr_build, adc_seed=12, session=session).boot != first.boot


@pytest.mark.slow  # real time against the simulated MCU: a loaded machine stalls it and the robot's watchdog trips
def test_avr_radiolink_runs_the_servos(simulator):
    sys.path.insert(0, str(FIRMWARE / "ports" / "avr" / "sim"))
    try:
        import radiolink_demo
    finally:
        sys.path.pop(0)
    right, left = math.radians(40), math.radians(25)
    beats = [[math.pi / 2, right, 1.0, 2.0], [math.pi / 2, left, 1.0, 1.0]]
    ex = radiolink_demo.run(seconds=2.0, beats=beats)
    assert any(state == pr.RobotState.RUNNING for _, state in ex.states)
    assert ex.states[-1][1] == pr.RobotState.STOPPED
    assert ex.latches >= 4  # 1 s beats: each fin latches twice a second
    # Pulse widths: 1500 us at 90 deg, 1200 us per 180 deg (hal_avr.h), so 1500 +- 266.7 us (right, 40 deg) and
    # 1500 +- 166.7 us (left, 25 deg); sampled every 20 ms, the extremes are reached within ~1.2 us.
    servo = {s["pin"]: s for s in ex.report["servos"]}
    for pin, amplitude in (("OC1A", right), ("OC1B", left)):
        swing = math.degrees(amplitude) * 1200.0 / 180.0
        assert 1500 - swing - 1.0 <= servo[pin]["min_us"] <= 1500 - swing + 3.0
        assert 1500 + swing - 3.0 <= servo[pin]["max_us"] <= 1500 + swing + 1.0
        assert servo[pin]["pulses"] >= 100  # 50 Hz over > 2 s


def test_dspic_port_checked_on_the_host():
    if shutil.which("make") is None or shutil.which("cc") is None:
        pytest.skip("make or cc not installed")
    done = _make("dspic-check")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "all checks passed" in done.stdout


def test_avr_lockstep_core_follows_the_rules(simulator):
    """The events build in lockstep (what an emulated fish follows, sim/simavr_core.py): start, latches, watchdog."""
    done = _make("avr-events")
    assert done.returncode == 0, done.stderr[-2000:]
    sys.path.insert(0, str(FIRMWARE / "ports" / "avr" / "sim"))
    try:
        from simavr_core import SimavrCore
    finally:
        sys.path.pop(0)
    core = SimavrCore(adc_seed=5)
    try:
        core.tick(100)
        core.take_events()
        assert core.state == pr.RobotState.IDLE and core.boot != 0
        fins = (math.pi / 2, 0.5, 1.0, 2.0) * 2  # both fins: 1 s beats, ratio 2: half-strokes of 333 and 667 ms
        msg = pr.Message(pr.MsgType.SET_FINS, 1, 0x1234, fins=fins, command=1, lease=0.8)
        core.receive_bytes(xb.encode_frame(xb.rx_packet(pr.encode_message(msg), 0x0013A20000000002)), 110)
        events, tx = [], b""
        for ms in range(120, 1000, 10):
            core.tick(ms)
            events += core.take_events()
            tx += core.take_tx()
        latches = [e for e in events if e.kind == "latch"]
        halts = [e for e in events if e.kind == "halt"]
        # The frame (about 54 bytes at 57143 baud: ~9.5 ms) completes near 120 ms; the still fins latch the command at
        # the next tick, both together, then 333 ms later turn (power -> recovery).
        assert [e.fin for e in latches[:4]] == [0, 1, 0, 1]
        first, second = latches[0], latches[2]
        assert 120 <= first.ms <= 140 and first.power
        assert abs((second.ms + second.frac_ms) - (first.ms + first.frac_ms) - 1000.0 / 3.0) < 1.0
        assert not second.power
        # No message after the SET_FINS: the watchdog halts the fins 500 ms after it (lease 800 ms comes later).
        assert len(halts) == 1 and 600 <= halts[0].ms <= 650
        assert core.state == pr.RobotState.WATCHDOG
        # STATUS and LATCH reports went out as Transmit Requests.
        replies = pr.StreamDecoder().feed(b"".join(xb.encode_frame(xb.rx_packet(xb.rf_data(xb.decode_frame(u)),
                                                                                  0)) for u in _frames(tx)))
        kinds = [m.type for m in replies]
        assert kinds.count(pr.MsgType.STATUS) == 1 and kinds.count(pr.MsgType.LATCH) >= 2
    finally:
        core.close()


def _frames(stream: bytes) -> list[bytes]:
    """Split a byte stream of escaped API frames at their start delimiters."""
    return [b"\x7e" + part for part in stream.split(b"\x7e") if part]
