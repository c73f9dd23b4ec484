"""``threading`` look-alikes on a :class:`pectoral_gym.hardware.clock.VirtualClock`: event, condition, thread.

Each blocks through the clock's scheduler (its baton and its virtual time) instead of the operating system's;
:meth:`VirtualClock.event`, :meth:`VirtualClock.condition` and :meth:`VirtualClock.thread` make them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from pectoral_gym.hardware.clocktask import LockstepError, Scheduler, Task

__all__: list[str] = []  # made by VirtualClock only


class _Event:
    """``threading.Event`` on a :class:`VirtualClock`."""

    def __init__(self, clock: Scheduler):
        self._clock = clock
        self._flag = False
        self._waiters: list[Task] = []

    def is_set(self) -> bool:
        return self._flag

    def set(self) -> None:
        with self._clock._mutex:
            self._flag = True
            for task in self._waiters:
                self._clock._wake(task)
            self._waiters.clear()

    def clear(self) -> None:
        self._flag = False

    def wait(self, timeout: float | None = None) -> bool:
        """Whether the flag is set, waiting up to ``timeout`` simulated seconds (``None``: until it is)."""
        clock = self._clock
        clock._checkpoint()
        if self._flag:
            return True
        if timeout is not None and not timeout > 0:
            clock._count_stall()
            return self._flag
        with clock._mutex:
            if not self._flag:
                task = clock._current()
                self._waiters.append(task)
                try:
                    clock._suspend(task, None if timeout is None else clock._after(timeout))
                finally:
                    if task in self._waiters:
                        self._waiters.remove(task)
        clock._checkpoint()
        return self._flag


class _Condition:
    """``threading.Condition`` on a :class:`VirtualClock` (``wait`` releases the lock as the original does)."""

    def __init__(self, clock: Scheduler, lock: Any = None):
        self._clock = clock
        self._lock = threading.RLock() if lock is None else lock
        self.acquire, self.release = self._lock.acquire, self._lock.release
        self._waiters: list[Task] = []

    def __enter__(self) -> bool:
        return self._lock.__enter__()

    def __exit__(self, *exc) -> None:
        return self._lock.__exit__(*exc)

    def _release_save(self) -> Any:
        save = getattr(self._lock, "_release_save", None)
        if save is not None:
            return save()
        self._lock.release()
        return None

    def _acquire_restore(self, state: Any) -> None:
        restore = getattr(self._lock, "_acquire_restore", None)
        if restore is not None:
            restore(state)
        else:
            self._lock.acquire()

    def wait(self, timeout: float | None = None) -> bool:
        """Release the lock, wait up to ``timeout`` simulated s for a notify, take the lock again; True if notified."""
        clock = self._clock
        clock._checkpoint()
        if timeout is not None and not timeout > 0:
            clock._count_stall()
            return False
        released, saved = False, None
        try:
            with clock._mutex:
                task = clock._current()
                self._waiters.append(task)
                saved, released = self._release_save(), True
                try:
                    notified = clock._suspend(task, None if timeout is None else clock._after(timeout))
                finally:
                    if task in self._waiters:
                        self._waiters.remove(task)
        finally:
            if released:  # the caller's lock again, outside the scheduler's (also when the run failed)
                self._acquire_restore(saved)
        clock._checkpoint()
        return notified

    def wait_for(self, predicate: Callable[[], Any], timeout: float | None = None) -> Any:
        """Wait until ``predicate()`` is true or ``timeout`` simulated s pass; returns the last value."""
        end = None if timeout is None else self._clock.monotonic() + timeout
        result = predicate()
        while not result:
            if end is None:
                self.wait()
            else:
                remaining = end - self._clock.monotonic()
                if remaining <= 0:
                    break
                self.wait(remaining)
            result = predicate()
        return result

    def notify(self, n: int = 1) -> None:
        with self._clock._mutex:
            for task in self._waiters[:n]:
                self._clock._wake(task)
            del self._waiters[:n]

    def notify_all(self) -> None:
        self.notify(len(self._waiters))


class _Thread(threading.Thread):
    """``threading.Thread`` in lockstep: runnable from :meth:`start`, ``join`` counts simulated time."""

    def __init__(self, clock: Scheduler, target: Callable[..., Any], name: str, args: tuple, daemon: bool):
        super().__init__(name=name, daemon=daemon)
        self._clock, self._job, self._job_args = clock, target, args
        self._task = Task(name, clock._mutex)
        self._finished = _Event(clock)

    def start(self) -> None:
        if self._started.is_set():
            raise RuntimeError("threads can only be started once")
        clock = self._clock
        with clock._mutex:  # runnable now, so the time cannot pass before it runs
            self._task.blocked = False
            clock._ready.append(self._task)
        super().start()

    def run(self) -> None:
        try:
            self._clock._enter(self._task)
            self._job(*self._job_args)
        except LockstepError:
            pass  # the run's failure, recorded in the clock: the thread that started the run reports it
        finally:
            self._finished.set()
            self._clock._leave()

    def join(self, timeout: float | None = None) -> None:
        if not self._started.is_set():
            raise RuntimeError("cannot join thread before it is started")
        if self is threading.current_thread():
            raise RuntimeError("cannot join current thread")
        self._finished.wait(timeout)
