"""One clock for the whole robot stack: real time (the robot) or a virtual clock (lockstep emulation).

Every part of ``pectoral_gym.hardware`` that reads the time, sleeps, waits for an event or a condition or
starts a thread does it through a :class:`Clock`:

* :data:`REAL_CLOCK` (the default everywhere) is ``time.monotonic``, ``time.sleep``, ``threading.Event``,
  ``threading.Condition`` and ``threading.Thread`` themselves: on the robot nothing changes.
* :class:`VirtualClock` runs the same threads in *lockstep*, as a discrete-event scheduler (PX4 SITL's
  lockstep, ROS ``use_sim_time``): exactly one of its threads runs at a time (the one holding the
  baton); a thread gives the baton away only when it blocks on the clock (``sleep``, an event's or a
  condition's ``wait``, ``join``); the next one is the first that was woken (FIFO), and when no thread
  is runnable the clock jumps to the earliest pending wake-up. Time never passes while a thread
  computes, so a deployment runs as fast as the CPU allows, and the order in which threads run
  depends on the program alone, never on the operating system: the same seed gives the same run.

The rules for code that runs under a :class:`VirtualClock`: never block outside the clock (no
``time.sleep``, no ``select`` or socket waits, no ``threading`` primitives that a blocked clock thread
must release), and never wait on the clock while holding a lock another clock thread needs (waits on a
clock condition release their own lock, as ``threading.Condition`` does). Byte streams between clock
threads are :class:`pectoral_gym.hardware.radio.pipe.StreamPair` endpoints. What talks to the outside world
through a device or a socket (``OpenCVCamera``, ``NetworkCamera``/``FrameServer``, ``RadioProxy``, the emulator's
TCP and pty ports) runs in real time by nature; a lockstep emulation uses their in-process counterparts
(:mod:`pectoral_gym.hardware.emurig`).
"""

from __future__ import annotations

import collections
import heapq
import itertools
import math
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

__all__ = ["Clock", "REAL_CLOCK", "RealClock", "VirtualClock", "LockstepError"]


class Clock(Protocol):
    """What the robot stack needs of a clock (times in seconds)."""

    virtual: bool

    def monotonic(self) -> float:
        """Seconds on a clock that never goes back (``time.monotonic`` for real time)."""
        ...

    def sleep(self, seconds: float) -> None:
        """Block for ``seconds``."""
        ...

    def event(self) -> threading.Event:
        """A new event whose ``wait(timeout)`` counts ``timeout`` on this clock."""
        ...

    def condition(self, lock: Any = None) -> threading.Condition:
        """A new condition (over ``lock``, default a new ``RLock``) whose ``wait`` counts on this clock."""
        ...

    def thread(self, target: Callable[..., Any], name: str, args: tuple = (), daemon: bool = True) -> threading.Thread:
        """A new (not yet started) thread whose ``join(timeout)`` counts on this clock."""
        ...


class RealClock:
    """The wall clock: the ``time`` and ``threading`` functions themselves."""

    virtual = False
    monotonic = staticmethod(time.monotonic)
    sleep = staticmethod(time.sleep)

    @staticmethod
    def event() -> threading.Event:
        """``threading.Event()``."""
        return threading.Event()

    @staticmethod
    def condition(lock: Any = None) -> threading.Condition:
        """``threading.Condition(lock)``."""
        return threading.Condition(lock)

    @staticmethod
    def thread(target: Callable[..., Any], name: str, args: tuple = (), daemon: bool = True) -> threading.Thread:
        """``threading.Thread(target=target, name=name, args=args, daemon=daemon)``."""
        return threading.Thread(target=target, name=name, args=args, daemon=daemon)


REAL_CLOCK = RealClock()


class LockstepError(RuntimeError):
    """Every thread of a :class:`VirtualClock` waits with no timeout: nothing can ever run again."""


class _Task:
    """A thread taking part in the lockstep (its baton, state and wake-up bookkeeping)."""

    __slots__ = ("name", "cond", "token", "notified", "blocked", "done")

    def __init__(self, name: str, mutex: threading.Lock):
        self.name = name
        self.cond = threading.Condition(mutex)
        self.token = 0  # bumped at every block and wake-up: stale timer entries are skipped
        self.notified = False
        self.blocked = False
        self.done = False


class VirtualClock:
    """Simulated time for threads in lockstep (see the module docstring).

    The thread that creates the clock takes part and holds the baton; threads made by :meth:`thread` take
    part from their start; any other thread takes part from its first wait on the clock.

    Args:
        start: Time the clock reads at first [s].

    Attributes:
        switches: Times the baton passed from one thread to another (a measure of the scheduling work).
    """

    virtual = True

    def __init__(self, start: float = 0.0):
        if not math.isfinite(start):
            raise ValueError(f"start must be a finite number of seconds, got {start!r}")
        self._mutex = threading.Lock()
        self._now = float(start)
        self._ready: collections.deque[_Task] = collections.deque()
        self._timers: list[tuple[float, int, _Task, int]] = []  # (deadline, order, task, task token)
        self._order = itertools.count()
        self._tasks: dict[int, _Task] = {}  # thread ident -> task
        self.switches = 0
        me = _Task(threading.current_thread().name, self._mutex)
        self._tasks[threading.get_ident()] = me
        self._running: _Task | None = me

    # ------------------------------------------------------------ the Clock protocol
    def monotonic(self) -> float:
        """Simulated seconds."""
        return self._now

    def sleep(self, seconds: float) -> None:
        """Give the baton away until the clock reads ``seconds`` later (``<= 0``: return at once)."""
        if not seconds > 0:
            return
        with self._mutex:
            self._suspend(self._current(), self._now + float(seconds))

    def event(self) -> _Event:
        """A new :class:`threading.Event` look-alike on this clock."""
        return _Event(self)

    def condition(self, lock: Any = None) -> _Condition:
        """A new :class:`threading.Condition` look-alike on this clock."""
        return _Condition(self, lock)

    def thread(self, target: Callable[..., Any], name: str, args: tuple = (), daemon: bool = True) -> _Thread:
        """A new :class:`threading.Thread` that runs in lockstep from its start."""
        return _Thread(self, target, name, args, daemon)

    # ------------------------------------------------------------ scheduler (call with the mutex held)
    def _current(self) -> _Task:
        task = self._tasks.get(threading.get_ident())
        if task is None:  # a thread that joins at its first wait
            task = _Task(threading.current_thread().name, self._mutex)
            self._tasks[threading.get_ident()] = task
        return task

    def _wake(self, task: _Task) -> None:
        """Make a blocked ``task`` runnable (it was notified); it runs after those woken before it."""
        if task.blocked:
            task.blocked, task.notified = False, True
            task.token += 1
            self._ready.append(task)

    def _suspend(self, task: _Task, deadline: float | None) -> bool:
        """Block ``task`` until woken or ``deadline``; returns whether it was woken (not timed out)."""
        task.token += 1
        task.blocked, task.notified = True, False
        if deadline is not None:
            heapq.heappush(self._timers, (deadline, next(self._order), task, task.token))
        if self._running is task or self._running is None:
            self._switch()
        while self._running is not task:
            task.cond.wait()
        return task.notified

    def _switch(self) -> None:
        """Hand the baton to the next runnable task, advancing the time to the earliest wake-up if none is."""
        while not self._ready:
            while self._timers and self._timers[0][2].token != self._timers[0][3]:
                heapq.heappop(self._timers)  # woken before its time, or finished
            if not self._timers:
                self._running = None
                waiting = sorted(t.name for t in self._tasks.values() if t.blocked)
                raise LockstepError(f"every lockstep thread waits with no timeout: {', '.join(waiting)}")
            deadline, _, task, _ = heapq.heappop(self._timers)
            self._now = max(self._now, deadline)
            task.blocked = False
            task.token += 1
            self._ready.append(task)
        task = self._ready.popleft()
        if task is not self._running:
            self.switches += 1
        self._running = task
        task.cond.notify()

    def _enter(self, task: _Task) -> None:
        """A new thread's first act: wait for the baton."""
        with self._mutex:
            self._tasks[threading.get_ident()] = task
            while self._running is not task:
                task.cond.wait()

    def _leave(self) -> None:
        """A thread's last act: leave the lockstep and hand the baton on."""
        with self._mutex:
            task = self._tasks.pop(threading.get_ident(), None)
            if task is None:
                return
            task.done, task.blocked = True, False
            task.token += 1
            if self._running is task:
                try:
                    self._switch()
                except LockstepError:
                    pass  # the last thread left: nothing is left to run


class _Event:
    """``threading.Event`` on a :class:`VirtualClock`."""

    def __init__(self, clock: VirtualClock):
        self._clock = clock
        self._flag = False
        self._waiters: list[_Task] = []

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
        with clock._mutex:
            if self._flag or (timeout is not None and not timeout > 0):
                return self._flag
            task = clock._current()
            self._waiters.append(task)
            try:
                clock._suspend(task, None if timeout is None else clock._now + float(timeout))
            finally:
                if task in self._waiters:
                    self._waiters.remove(task)
            return self._flag


class _Condition:
    """``threading.Condition`` on a :class:`VirtualClock` (``wait`` releases the lock as the original does)."""

    def __init__(self, clock: VirtualClock, lock: Any = None):
        self._clock = clock
        self._lock = threading.RLock() if lock is None else lock
        self.acquire, self.release = self._lock.acquire, self._lock.release
        self._waiters: list[_Task] = []

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
        if timeout is not None and not timeout > 0:
            return False
        clock = self._clock
        with clock._mutex:
            task = clock._current()
            self._waiters.append(task)
            saved = self._release_save()
            try:
                notified = clock._suspend(task, None if timeout is None else clock._now + float(timeout))
            finally:
                if task in self._waiters:
                    self._waiters.remove(task)
        self._acquire_restore(saved)
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

    def __init__(self, clock: VirtualClock, target: Callable[..., Any], name: str, args: tuple, daemon: bool):
        super().__init__(name=name, daemon=daemon)
        self._clock, self._job, self._job_args = clock, target, args
        self._task = _Task(name, clock._mutex)
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
        self._clock._enter(self._task)
        try:
            self._job(*self._job_args)
        finally:
            self._finished.set()
            self._clock._leave()

    def join(self, timeout: float | None = None) -> None:
        if not self._started.is_set():
            raise RuntimeError("cannot join thread before it is started")
        if self is threading.current_thread():
            raise RuntimeError("cannot join current thread")
        self._finished.wait(timeout)
