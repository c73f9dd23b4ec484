"""What the virtual clock and its waits share: a lockstep thread's task, the run's failure, the scheduler's face.

:mod:`pectoral_gym.hardware.clock` (the :class:`~pectoral_gym.hardware.clock.VirtualClock`) and
:mod:`pectoral_gym.hardware.clockwaits` (its event, condition and thread look-alikes) both build on this module, so
that neither imports the other's module back: the waits reach the clock through :class:`Scheduler`.
"""

from __future__ import annotations

import collections
import threading
from typing import Protocol

__all__ = ["LockstepError", "Scheduler", "Task"]


class LockstepError(RuntimeError):
    """A lockstep run cannot progress: every thread waits with no time-out, the time stands still or passed a limit.

    Raised in every thread of the :class:`~pectoral_gym.hardware.clock.VirtualClock` at its next wait.
    """


class Task:
    """A thread taking part in the lockstep (its baton, state and wake-up bookkeeping)."""

    __slots__ = ("name", "cond", "token", "notified", "blocked", "done")

    def __init__(self, name: str, mutex: threading.Lock):
        self.name = name
        self.cond = threading.Condition(mutex)
        self.token = 0  # bumped at every block and wake-up: stale timer entries are skipped
        self.notified = False
        self.blocked = False
        self.done = False


class Scheduler(Protocol):
    """The virtual clock's scheduler as its waits use it (times in ticks; the clock's private side)."""

    _mutex: threading.Lock
    _ready: collections.deque[Task]

    def _checkpoint(self) -> None:
        """Where a thread may leave the lockstep: the run's failure, or a deferred signal in the main thread."""
        ...

    def _after(self, seconds: float) -> int | None:
        """The tick a wait of ``seconds`` (> 0) ends at; ``None`` for an infinite one."""
        ...

    def _count_stall(self) -> None:
        """A zero-length wait: counts towards the stall limit while the time stands still."""
        ...

    def _current(self) -> Task:
        """The calling thread's task (made at its first wait)."""
        ...

    def _wake(self, task: Task) -> None:
        """Make a blocked ``task`` runnable (it was notified); it runs after those woken before it."""
        ...

    def _suspend(self, task: Task, deadline: int | None) -> bool:
        """Block ``task`` until woken or ``deadline`` [ticks]; returns whether it was woken (not timed out)."""
        ...

    def _enter(self, task: Task) -> None:
        """A new thread's first act: wait for the baton."""
        ...

    def _leave(self) -> None:
        """A thread's last act: leave the lockstep and hand the baton on."""
        ...
