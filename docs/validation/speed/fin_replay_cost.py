"""What the replays of the fins cost in a lockstep deployment: their threads' CPU time, and the fin rules' calls.

Usage: ``python fin_replay_cost.py pectoral_gym.hardware.deploy --policy ... --emulate --lockstep --jobs 1 ...``
(``--jobs 1``: the episodes run in this process's threads), or ``python fin_replay_cost.py --tick``: the parts of one
replay tick, each timed alone (best of 3 repeats of 20 000 calls).

Adds up the CPU time of the calling thread (``time.thread_time``) inside the liveness check
(``LivenessWatch.sighting``, ``.command`` and ``.latch``: all of it), inside its predictions (``Predictions.motion``
and ``.fitted``) and its shadow replays (``ShadowFins.advance`` and ``.view``), and inside the other fin replays
(``FinReplay.advance`` and ``.command`` called from elsewhere: the blind-spell check's), and counts the replays' ticks
run from Python (``finrules.apply_firmware`` as ``advance_with_firmware`` or ``FinReplay.advance`` calls it; the
emulated robot's own ticks are not counted; the quiet ticks a compiled call runs are not either) and the calls of the
fin rules (``finrules.next_latch``, the robot's included). Printed at exit, with the process's CPU time from this
script's start (imports and policy loading included) for scale.
"""

from __future__ import annotations

import atexit
import collections
import runpy
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from pectoral_gym.hardware.safety import liveness, liveness_predictions, shadow_fins
from pectoral_gym.model import finreplay, finrules

seconds: collections.Counter[str] = collections.Counter()
calls: collections.Counter[str] = collections.Counter()
_inside = threading.local()  # the labels being metered in this thread: a call inside one of them is the outer one's


def _meter(owner: Any, name: str, label: str, outside: tuple[str, ...] = ()) -> None:
    """Meter ``owner.name`` under ``label``, unless called inside that label or one of ``outside``."""
    function = getattr(owner, name)

    def metered(*args: Any, **kwargs: Any) -> Any:
        active = _inside.__dict__.setdefault("labels", set())
        if label in active or not active.isdisjoint(outside):
            return function(*args, **kwargs)
        active.add(label)
        start = time.thread_time()
        try:
            return function(*args, **kwargs)
        finally:
            seconds[label] += time.thread_time() - start
            calls[label] += 1
            active.discard(label)

    setattr(owner, name, metered)


def _count(name: str) -> None:
    function: Callable[..., Any] = getattr(finrules, name)

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls[name] += 1
        return function(*args, **kwargs)

    setattr(finrules, name, counted)  # apply_firmware and advance_with_firmware look them up in the module
    if hasattr(finreplay, name):
        setattr(finreplay, name, counted)  # FinReplay.advance, where it runs the ticks itself


def tick_parts() -> None:
    """Print the time of each part of a replay tick, the fins running a command (inputs unchanged since the last)."""
    import timeit

    import numpy as np

    replay = finreplay.FinReplay()
    replay.command(0.0, np.array([[1.5, 0.5, 1.0, 2.0], [1.4, 0.4, 0.8, 1.5]]))
    replay.advance(0.5)
    model, firmware = replay.model, replay.firmware
    parts = {"next_latch (the fin rules)": lambda: finrules.next_latch(firmware.setpoint, model.fins[0],
                                                                         firmware.config.limits),
             "apply_firmware, inputs unchanged": lambda: finrules.apply_firmware(firmware, model),
             "the tick's setpoint and fin angles": lambda: firmware.tick(model.time, model.fin_angles()[0][0]),
             "model.advance(CHUNK)": lambda: model.advance(finrules.CHUNK)}
    for name, part in parts.items():
        print(f"{name}: {min(timeit.repeat(part, number=20_000, repeat=3)) / 20_000 * 1e6:.1f} us")
    # whole ticks: the replay run on by 0.05 s (5 ticks, a turning point every 0.25-0.5 s), per tick
    seconds_per_run = min(timeit.repeat(lambda: replay.advance(model.time + 0.05), number=4_000, repeat=3)) / 4_000
    print(f"FinReplay.advance by 0.05 s, per tick: {seconds_per_run / 5 * 1e6:.1f} us")


def main() -> None:
    """Meter the replays, run the module named first with the remaining arguments, print the figures at exit."""
    if sys.argv[1:] == ["--tick"]:
        tick_parts()
        return
    for method in ("sighting", "command", "latch"):
        _meter(liveness.LivenessWatch, method, "liveness check")
    for method in ("motion", "fitted"):
        _meter(liveness_predictions.Predictions, method, "liveness predictions")
    for method in ("advance", "view"):
        _meter(shadow_fins.ShadowFins, method, "shadow replays")
    for method in ("advance", "command"):
        _meter(finreplay.FinReplay, method, "other replays", outside=("liveness check", "shadow replays"))
    _count("apply_firmware")
    _count("next_latch")
    start = time.process_time()

    def report() -> None:
        parts = [f"process CPU {time.process_time() - start:.2f} s"]
        parts += [f"{label} {seconds[label]:.2f} s ({calls[label]} calls)" for label in sorted(seconds)]
        parts += [f"replay ticks {calls['apply_firmware']}, fin rules run {calls['next_latch']} times"]
        print("; ".join(parts), file=sys.stderr)

    atexit.register(report)
    sys.argv = sys.argv[1:]
    runpy.run_module(sys.argv[0], run_name="__main__")


if __name__ == "__main__":
    main()
