"""The liveness check's model calls on synthetic sightings: how many, how many fish-steps, and what it predicted.

Usage: ``python liveness_calls.py [SECONDS]`` (default 20 simulated seconds).

A fish rows under a new random command every 0.5 s (the full model with the firmware's rules, as the emulator runs
its fins); a :class:`~pectoral_gym.hardware.safety.liveness.LivenessWatch` sees its poses at 30 per second with
2 mm of noise, and each command's acknowledgement 60 ms after its send. Printed: the model calls
(``FishModel.advance``), the fish they advanced, the CPU time of the sightings, and a SHA-256 of every prediction
the watch made (``predictions``): the same digest before and after a change means the same floats.
"""

from __future__ import annotations

import hashlib
import math
import sys
import time

import numpy as np

from pectoral_gym.hardware.safety.geofence import SpeedBound
from pectoral_gym.hardware.safety.liveness import LivenessWatch
from pectoral_gym.model import models
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.servo import ServoLimits

ACK_DELAY = 0.06  # s from a command's send to its acknowledgement


def main() -> None:
    """Run the synthetic sightings and print the counts, the CPU time and the predictions' digest."""
    duration = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    params, rng = FishParams(), np.random.default_rng(1)
    bound = SpeedBound(params, ServoLimits())
    bound.reset(0.0)
    watch = LivenessWatch(params, bound, pose_noise=0.002)
    commands = [(k * 0.5, np.array([[math.pi / 2, rng.uniform(0.3, 1.0), 0.6, rng.uniform(1.0, 3.0)]
                                    for _ in range(2)])) for k in range(int(duration / 0.5))]
    robot = FinReplay(params)
    robot.model.state[0] = (1.0, 0.5, 0.0, 0.0, 0.0, 0.0)
    poses, taken = [], 0
    for k in range(int(duration * 30)):
        t = k / 30
        while taken < len(commands) and commands[taken][0] <= t:
            robot.command(*commands[taken])
            taken += 1
        robot.advance(t)
        poses.append((t, *robot.model.state[0, :3]))

    counts, advance = {"calls": 0, "fish": 0}, models.FishModel.advance

    def counted(model: models.FishModel, duration: float) -> np.ndarray:
        counts["calls"] += 1
        counts["fish"] += model.n
        return advance(model, duration)

    models.FishModel.advance = counted  # type: ignore[method-assign]
    now, sent, reasons, cpu = [0.0], 0, 0, time.process_time()
    for t, x, y, psi in poses:
        while sent < len(commands) and commands[sent][0] <= t:
            at = commands[sent][0]
            watch.command(at, commands[sent][1], lambda at=at: at + ACK_DELAY if now[0] >= at + ACK_DELAY else None)
            bound.running(at, at + 1.0)
            sent += 1
        now[0] = t
        reasons += bool(watch.sighting(t, x + rng.normal(0.0, 0.002), y + rng.normal(0.0, 0.002), psi))
    cpu = time.process_time() - cpu
    digest = hashlib.sha256(np.array(list(watch.predictions), dtype=float).tobytes()).hexdigest()[:16]
    print(f"{len(poses)} sightings, {len(watch.predictions)} checks, {reasons} stops; model calls {counts['calls']}, "
          f"fish-steps {counts['fish']}; CPU {cpu:.2f} s; predictions sha256 {digest}")


if __name__ == "__main__":
    main()
