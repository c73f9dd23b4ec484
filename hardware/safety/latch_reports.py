"""The robot's latch reports (LATCH, ``docs/protocol.md``): to the liveness check, then to the run log.

The link keeps the reports of our session and boot (``RadioLink.drain_latches``, on its clock). The supervisor's
thread takes them every round, before the frame, and gives them to the liveness check's replays
(:meth:`pectoral_gym.hardware.safety.liveness.LivenessWatch.latch`); the env takes them from here for the run log.
Taken in the supervisor's thread, a report meets the replays at the same point among the sightings on every run of
a lockstep episode.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

__all__ = ["LatchReports"]


class LatchReports:
    """The link's latch reports, stamped in experiment time, fed to a liveness check and kept for :meth:`drain`.

    Args:
        link: The radio link (a stand-in without ``drain_latches`` has no reports).
        stamp: Maps the link's clock [s] to experiment time [s].
    """

    def __init__(self, link: Any, stamp: Callable[[float], float]):
        self._drain = getattr(link, "drain_latches", None)
        self._stamp = stamp
        self._kept: list[tuple[float, Any]] = []
        self._lock = threading.Lock()

    def take(self, liveness: Any | None) -> None:
        """Take the link's new reports; each to ``liveness`` if given (armed)."""
        if self._drain is None:
            return
        with self._lock:  # whole: taken from two threads, the reports stay in order
            for t_link, latch in self._drain():
                t = self._stamp(t_link)
                if liveness is not None:
                    liveness.latch(t, latch.fin, latch.beat, latch.turn, latch.power)
                self._kept.append((t, latch))

    def drain(self) -> list[tuple[float, Any]]:
        """The reports taken since the last call: ``(experiment time of the latch [s], report)``, in order."""
        with self._lock:
            out, self._kept = self._kept, []
        return out
