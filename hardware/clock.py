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

Progress in lockstep: the virtual time is an integer count of nanoseconds (:data:`TICK`), and every wait of a
positive length lasts at least one tick, so a loop that waits for a time "a rounding step away" always gets
there (with float time, ``now + 2e-16 == now`` once ``now`` passes a few seconds, and such a loop never ended).
What still cannot progress ends the run with a :class:`LockstepError` raised in every lockstep thread at its next
wait (one line naming the threads): every thread waiting with no time-out, the time standing still over
:data:`STALL_LIMIT` baton passes or zero-length waits, or the time passing the clock's ``limit``. Ctrl-C and
SIGTERM in lockstep (:meth:`VirtualClock.defer_signals`) are taken where the main thread waits on the clock,
never inside the scheduler, so the run's ``finally`` blocks close it in lockstep; a second signal ends it at once.

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
import signal
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from pectoral_gym.hardware.clocktask import LockstepError, Task
from pectoral_gym.hardware.clockwaits import _Condition, _Event, _Thread
from pectoral_gym.hardware.signal_latch import end_as

__all__ = ["Clock", "REAL_CLOCK", "RealClock", "VirtualClock", "LockstepError", "TICK", "STALL_LIMIT"]

TICK = 1e-9  # s: the virtual clock's resolution (integer nanoseconds: exact sums, ~104 days before 2**53 ticks)
# Baton passes plus zero-length waits with the virtual time standing still before the run is declared stuck: far
# above what one instant of a deployment needs (tens), reached in about a second of wall time by a spinning loop.
STALL_LIMIT = 1_000_000
_PER_SECOND = 1_000_000_000  # ticks per second


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


def _ticks(seconds: float) -> int:
    """A wait of ``seconds`` > 0 in ticks: the nearest, and at least one (so that the time moves)."""
    return max(1, round(seconds * _PER_SECOND))


class VirtualClock:
    """Simulated time for threads in lockstep (see the module docstring).

    The thread that creates the clock takes part and holds the baton; threads made by :meth:`thread` take
    part from their start; any other thread takes part from its first wait on the clock.

    Args:
        start: Time the clock reads at first [s].
        limit: Time [s] past which the run counts as stuck (:class:`LockstepError`); ``None``: no limit.

    Attributes:
        switches: Times the baton passed from one thread to another (a measure of the scheduling work).
        failure: The :class:`LockstepError` that ended the run, or ``None``.
    """

    virtual = True

    def __init__(self, start: float = 0.0, limit: float | None = None):
        if not math.isfinite(start):
            raise ValueError(f"start must be a finite number of seconds, got {start!r}")
        if limit is not None and not (math.isfinite(limit) and limit > start):
            raise ValueError(f"limit must be a finite time after start [s] or None, got {limit!r}")
        self._mutex = threading.Lock()
        self._now = round(float(start) * _PER_SECOND)  # ticks
        self._limit = None if limit is None else round(float(limit) * _PER_SECOND)
        self._ready: collections.deque[Task] = collections.deque()
        self._timers: list[tuple[int, int, Task, int]] = []  # (deadline [ticks], order, task, task token)
        self._order = itertools.count()
        self._tasks: dict[int, Task] = {}  # thread ident -> task
        self.switches = 0
        self._stalled = 0  # baton passes and zero-length waits since the time last moved
        self.failure: LockstepError | None = None
        self._signal: int | None = None  # a deferred signal, taken at the main thread's next wait
        self._signal_stops: list[Callable[[], object]] = []  # newest last
        self._signal_depth = 0  # defer_signals() calls not undone yet
        self._signal_handler: Any = None
        self._signal_previous: dict[int, Any] = {}
        me = Task(threading.current_thread().name, self._mutex)
        self._tasks[threading.get_ident()] = me
        self._running: Task | None = me

    # ------------------------------------------------------------ the Clock protocol
    def monotonic(self) -> float:
        """Simulated seconds."""
        return self._now / _PER_SECOND

    def sleep(self, seconds: float) -> None:
        """Give the baton away until the clock reads ``seconds`` later (``<= 0``: return at once)."""
        self._checkpoint()
        if not seconds > 0:
            self._count_stall()
            return
        with self._mutex:
            self._suspend(self._current(), self._after(seconds))
        self._checkpoint()

    def event(self) -> _Event:
        """A new :class:`threading.Event` look-alike on this clock."""
        return _Event(self)

    def condition(self, lock: Any = None) -> _Condition:
        """A new :class:`threading.Condition` look-alike on this clock."""
        return _Condition(self, lock)

    def thread(self, target: Callable[..., Any], name: str, args: tuple = (), daemon: bool = True) -> _Thread:
        """A new :class:`threading.Thread` that runs in lockstep from its start."""
        return _Thread(self, target, name, args, daemon)

    @property
    def limit(self) -> float | None:
        """Time [s] past which the run counts as stuck (:class:`LockstepError`), or ``None`` (settable)."""
        return None if self._limit is None else self._limit / _PER_SECOND

    @limit.setter
    def limit(self, seconds: float | None) -> None:
        if seconds is not None and not (math.isfinite(seconds) and seconds > 0):
            raise ValueError(f"limit must be a finite number of seconds > 0 or None, got {seconds!r}")
        self._limit = None if seconds is None else round(float(seconds) * _PER_SECOND)

    # ------------------------------------------------------------ signals
    def defer_signals(self, stop: Callable[[], object] | None = None) -> Callable[[], None]:
        """Take SIGINT and SIGTERM at the main thread's next wait on this clock; returns a function that undoes it.

        The handler only records the signal: run inside the scheduler (which holds a lock the stop's own writes
        need) or mid-way through its bookkeeping, anything more could deadlock the run. At the main thread's next
        wait on the clock (it waits every frame) ``stop`` is called (every one registered, newest first), then
        the handler installed before runs; if that was the default, SIGINT raises ``KeyboardInterrupt`` and
        SIGTERM ``SystemExit(143)``, as :func:`pectoral_gym.hardware.safety.rules.install_stop_handlers` does.
        A second signal before the first was taken does that at once. Calls nest (each registers its ``stop``);
        outside the main thread nothing is installed.
        """
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        if stop is not None:
            self._signal_stops.append(stop)
        if self._signal_depth == 0:
            previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

            def handler(signum: int, frame: Any) -> None:
                if self._signal is None:
                    self._signal = signum  # no lock, no I/O: taken at the next wait
                else:  # a second one: the operator insists
                    self._signal = None
                    self._raise_signal(signum)

            for sig in previous:
                signal.signal(sig, handler)
            self._signal_handler, self._signal_previous = handler, previous
        self._signal_depth += 1
        undone = False

        def restore() -> None:
            nonlocal undone
            if undone:
                return
            undone = True
            if stop is not None and stop in self._signal_stops:
                self._signal_stops.remove(stop)
            self._signal_depth -= 1
            if self._signal_depth == 0:
                for sig, old in self._signal_previous.items():
                    if signal.getsignal(sig) is self._signal_handler:  # not if someone installed theirs on top
                        signal.signal(sig, old)
                if self._signal is not None:  # came after the main thread's last wait: taken now, not lost
                    signum, self._signal = self._signal, None
                    self._raise_signal(signum)

        return restore

    def record_signal(self, signum: int) -> None:
        """Take ``signum`` as if it had just arrived (a caller's handler that deferred it before this clock's)."""
        self._signal = signum

    def _raise_signal(self, signum: int) -> None:
        """Stop, then end as the handler before ours would (call outside the scheduler's lock)."""
        try:
            for stop in reversed(self._signal_stops):
                stop()
        finally:
            end_as(signum, self._signal_previous.get(signum))

    def _checkpoint(self) -> None:
        """Where a thread may leave the lockstep: the run's failure, or a deferred signal in the main thread."""
        if self.failure is not None:
            raise self.failure
        if self._signal is not None and threading.current_thread() is threading.main_thread():
            signum, self._signal = self._signal, None
            self._raise_signal(signum)

    # ------------------------------------------------------------ scheduler (call with the mutex held)
    def _after(self, seconds: float) -> int | None:
        """The tick a wait of ``seconds`` (> 0) ends at; ``None`` for an infinite one."""
        return self._now + _ticks(float(seconds)) if math.isfinite(seconds) else None

    def _count_stall(self) -> None:
        """A zero-length wait: counts towards :data:`STALL_LIMIT` while the time stands still."""
        self._stalled += 1
        if self._stalled > STALL_LIMIT:
            with self._mutex:
                self._fail(f"the simulated time stands still at {self.monotonic():.9f} s: {STALL_LIMIT} waits of "
                           f"length zero (a thread polling without waiting)")

    def _current(self) -> Task:
        task = self._tasks.get(threading.get_ident())
        if task is None:  # a thread that joins at its first wait
            task = Task(threading.current_thread().name, self._mutex)
            self._tasks[threading.get_ident()] = task
        return task

    def _wake(self, task: Task) -> None:
        """Make a blocked ``task`` runnable (it was notified); it runs after those woken before it."""
        if task.blocked:
            task.blocked, task.notified = False, True
            task.token += 1
            self._ready.append(task)

    def _fail(self, message: str) -> None:
        """End the run: every thread raises :class:`LockstepError` at its next wait (this one now)."""
        if self.failure is None:
            self.failure = LockstepError(message)
        self._running = None
        for task in self._tasks.values():
            task.cond.notify_all()
        raise self.failure

    def _suspend(self, task: Task, deadline: int | None) -> bool:
        """Block ``task`` until woken or ``deadline`` [ticks]; returns whether it was woken (not timed out)."""
        if self.failure is not None:
            raise self.failure
        task.token += 1
        task.blocked, task.notified = True, False
        if deadline is not None:
            heapq.heappush(self._timers, (deadline, next(self._order), task, task.token))
        if self._running is task or self._running is None:
            self._switch()
        while self._running is not task:
            if self.failure is not None:
                raise self.failure
            task.cond.wait()
        return task.notified

    def _switch(self) -> None:
        """Hand the baton to the next runnable task, advancing the time to the earliest wake-up if none is."""
        while not self._ready:
            while self._timers and self._timers[0][2].token != self._timers[0][3]:
                heapq.heappop(self._timers)  # woken before its time, or finished
            if not self._timers:
                waiting = sorted(t.name for t in self._tasks.values() if t.blocked)
                if not waiting:  # the last thread left: nothing is left to run
                    self._running = None
                    return
                self._fail(f"every lockstep thread waits with no timeout: {', '.join(waiting)}")
            deadline, _, task, _ = heapq.heappop(self._timers)
            if deadline > self._now:
                if self._limit is not None and deadline > self._limit:
                    self._fail(f"the simulated time passed its limit of {self.limit:.1f} s (threads still "
                               f"waiting: {', '.join(sorted(t.name for t in self._tasks.values() if t.blocked))})")
                self._now, self._stalled = deadline, 0
            task.blocked = False
            task.token += 1
            self._ready.append(task)
        task = self._ready.popleft()
        if task is not self._running:
            self.switches += 1
            self._stalled += 1
            if self._stalled > STALL_LIMIT:
                self._fail(f"the simulated time stands still at {self.monotonic():.9f} s: {STALL_LIMIT} baton passes "
                           f"without a wait that lets it move (threads: "
                           f"{', '.join(sorted(t.name for t in self._tasks.values()))})")
        self._running = task
        task.cond.notify()

    def _enter(self, task: Task) -> None:
        """A new thread's first act: wait for the baton."""
        with self._mutex:
            self._tasks[threading.get_ident()] = task
            while self._running is not task:
                if self.failure is not None:
                    raise self.failure
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
                    pass  # recorded in self.failure: the other threads raise it
