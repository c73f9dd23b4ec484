"""What :class:`pectoral_gym.hardware.env.HardwareFishEnv` writes to its run log, and in which order.

The records themselves are :class:`pectoral_gym.runlog.RunLogWriter`'s (``docs/run-log.md``); this
keeps the env's bookkeeping around them: episodes numbered from the first reset, a ``stop`` only while the fins
run, and the robot's latch reports kept to the episode they belong to and to the log's time order.
"""

from __future__ import annotations

import math
from typing import Any

from pectoral_gym.hardware.radio import protocol as pr

__all__ = ["RunRecorder"]


class RunRecorder:
    """The env's side of its run log; every method is a no-op while ``writer`` is ``None``.

    Args:
        writer: A :class:`pectoral_gym.runlog.RunLogWriter`, or ``None`` (settable any time).
    """

    def __init__(self, writer: Any = None):
        self.writer = writer
        self._episodes, self._fins_running = 0, False
        self._latch_start = self._latch_last = -math.inf  # this episode's start, its last latch report

    def record(self, kind: str, t: float, *args: Any, **fields: Any) -> None:
        """Write a ``kind`` record (a ``RunLogWriter`` method) at ``t`` [s]; a ``stop`` only while the fins run."""
        if self.writer is None or (kind == "stop" and not self._fins_running):
            return
        if kind in ("command", "stop"):
            self._fins_running = kind == "command"
        getattr(self.writer, kind)(t, *args, **fields)

    def episode(self, placed: float) -> None:
        """An episode starts at time ``placed`` [s] (the fish placed and seen); latch reports before it are not its."""
        self._latch_start = self._latch_last = placed
        if self.writer is not None:
            self.writer.episode(self._episodes, placed)
        self._episodes += 1

    def latch(self, t: float, latch: pr.Latch) -> None:
        """The robot's report ``latch`` of a fin latching at time ``t`` [s, the env's clock]."""
        if t < self._latch_start:
            return  # from before this episode's start: not this run's segment
        # the clock offset's estimate may shrink by a ms between reports: a log's records keep their order
        t = self._latch_last = max(t, self._latch_last)
        if self.writer is not None:
            self.writer.latch(t, latch.fin, latch.beat, latch.turn, latch.power, latch.uptime_ms, latch.boot)
