"""One deployment episode whose fins are the simulated ATmega2560's: the whole PC stack, real time.

An emulated robot (:class:`pectoral_gym.hardware.emulator.EmulatedRobot`: physics, rendered overhead camera)
whose rules are the AVR firmware on simavr (:mod:`simavr_core`): the PC's frames go to the simulated USART0,
the MCU's replies come back, and the emulated fish's fins follow the MCU's latches and halts. Then
``pectoral-deploy --controller hand`` (or ``--controller nmpc``) runs episodes against it through the radio and the
camera, as against the robot.

Usage (from the repository root, after ``make -C firmware avr-events``)::

    .venv/bin/python firmware/ports/avr/sim/deploy_episode.py [--episodes 1] [--controller hand] [--out DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from simavr_core import SimavrCore, simavr_adapter  # noqa: E402


def main() -> int:
    """Run the episodes; the exit status is pectoral-deploy's."""
    from pectoral_gym.hardware.emulated_firmware import _ms, _rest
    from pectoral_gym.hardware.emulator import EmulatedRobot

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--controller", default="hand", choices=("hand", "nmpc"))
    parser.add_argument("--out", default=None, help="pectoral-deploy's output folder (default: a temporary one)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--speed", type=float, default=1.0, help="emulated s per wall s (both sides)")
    parser.add_argument("--rules", default="avr", choices=("avr", "c", "python"),
                        help="the emulated robot's rules: the simulated MCU (default), or for comparison the "
                             "C core in-process or the Python reference")
    args = parser.parse_args()

    robot = EmulatedRobot(port=0, camera_port=0, seed=args.seed, speed=args.speed,
                          firmware_impl="c" if args.rules == "c" else "python")
    adapter = simavr_adapter()

    def reboot(self, now, model, boot):  # a power-up: a new simulated MCU whose clock starts now
        self.core.close()
        self.core = SimavrCore(_ms(now), adc_seed=boot & 0xFFFF)
        self._splitter, self._tx_splitter = type(self._splitter)(), type(self._tx_splitter)()
        _rest(model, self.core.fin_angles())

    adapter.reboot = types.MethodType(reboot, adapter)
    if args.rules == "avr":
        robot.rules = adapter
    robot.start()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = args.out or tmp
            cmd = [sys.executable, "-m", "pectoral_gym.hardware.deploy", "--controller", args.controller,
                   "--port", robot.url, "--camera", robot.camera_spec, "--episodes", str(args.episodes),
                   "--seed", str(args.seed), "--out", out, "--no-prompt", "--speed", str(args.speed)]
            print("running:", " ".join(cmd), flush=True)
            done = subprocess.run(cmd)
            core = adapter.core if args.rules == "avr" else None
            if core is not None:
                print(f"simulated MCU: boot id {core.boot:#010x}, state {core.state}; {core.calls} runs of the "
                      f"simulator took {core.call_seconds:.2f} s of wall time; the emulated fish received "
                      f"{len(robot.received)} messages", flush=True)
            return done.returncode
    finally:
        robot.stop()
        adapter.core.close()


if __name__ == "__main__":
    sys.exit(main())
