"""The CPU time of ``settle_garbage`` in a lockstep deployment: every call, and their sum.

Usage: ``python settle_cost.py --policy ... --emulate --lockstep --episodes N --jobs 1 ...`` (the arguments of
``pectoral_gym.hardware.deploy``; ``--jobs 1``: the episodes run in this process). It wraps the function where the
robot stack calls it (the emulated robot's start, the env's reset), runs the deployment in this process, and prints
per call the calling thread's CPU time, the frozen set's size after it, and whether it walked every object (a code
whose ``settle_garbage`` always does reads ``-``).
"""

from __future__ import annotations

import atexit
import gc
import sys
import time

from pectoral_gym.hardware import emulator, env_reset, realtime

calls: list[tuple[float, int, str]] = []
original = realtime.settle_garbage


def timed() -> float:
    """``settle_garbage()``, timed."""
    before = getattr(realtime, "_frozen_after_full", None)
    start = time.thread_time()
    wall = original()
    cpu = time.thread_time() - start
    after = getattr(realtime, "_frozen_after_full", None)
    calls.append((cpu, gc.get_freeze_count(), "-" if after is None else "yes" if after != before else "no"))
    return wall


def report() -> None:
    """Print the calls and their sum."""
    for k, (cpu, frozen, full) in enumerate(calls):
        print(f"call {k:3d}: {cpu * 1000:7.1f} ms of CPU, {frozen} objects frozen, walked all: {full}",
              file=sys.stderr)
    print(f"{len(calls)} calls, {sum(c[0] for c in calls):.2f} s of CPU", file=sys.stderr)


env_reset.settle_garbage = emulator.settle_garbage = timed
atexit.register(report)

if __name__ == "__main__":
    from pectoral_gym.hardware.deploy import main

    sys.argv = ["pectoral_gym.hardware.deploy", *sys.argv[1:]]
    main()
