"""A latch for SIGINT and SIGTERM whose exception the interpreter may lose: ``pectoral-deploy --lockstep``'s."""

from __future__ import annotations

import signal
import sys
import threading

__all__ = ["SignalLatch", "end_as"]


def end_as(signum: int, previous=signal.SIG_DFL) -> None:
    """End as the handler ``previous`` (the one before ours) would for ``signum``.

    A function is called; ``SIG_IGN`` does nothing; anything else raises what Python's default does:
    ``KeyboardInterrupt`` for SIGINT, ``SystemExit(128 + signum)`` otherwise (the shell's exit status).
    """
    if callable(previous):
        previous(signum, None)
    elif previous != signal.SIG_IGN:
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise SystemExit(128 + signum)


class SignalLatch:
    """SIGINT and SIGTERM end a lockstep run even when their exception is lost (a context manager).

    Python raises a signal's exception in whatever code runs when it arrives; in a weakref callback or a
    finaliser (a lockstep rig's garbage, collected between episodes) the interpreter prints "Exception ignored"
    and goes on: a Ctrl-C to a ``--lockstep --jobs 1`` run was swallowed that way 2 times in 9. The handler
    installed here also latches the signal, and so does an unraisable-exception hook for a ``KeyboardInterrupt``
    or ``SystemExit`` the interpreter could not raise (silently: the run is ending anyway); :meth:`check`, called
    after every episode, raises it again in ordinary code. The rigs' own handlers (``VirtualClock.defer_signals``)
    chain to this one. Handlers: main thread only.
    """

    def __enter__(self) -> SignalLatch:
        self.signum: int | None = None
        self._previous: dict = {}
        self._hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.getsignal(sig)
                if self._previous[sig] != signal.SIG_IGN:
                    signal.signal(sig, self._handler)
        return self

    def _unraisable(self, unraisable) -> None:
        if unraisable.exc_type is KeyboardInterrupt:
            self.signum = self.signum or signal.SIGINT
        elif unraisable.exc_type is SystemExit:
            self.signum = self.signum or signal.SIGTERM
        else:
            self._hook(unraisable)

    def _handler(self, signum: int, frame) -> None:
        self.signum = signum
        self._raise(signum)

    @staticmethod
    def _raise(signum: int) -> None:
        end_as(signum)

    def check(self) -> None:
        """Raise the latched signal's exception (none latched: nothing)."""
        if self.signum is not None:
            self._raise(self.signum)

    def __exit__(self, *exc) -> None:
        if sys.unraisablehook == self._unraisable:
            sys.unraisablehook = self._hook
        for sig, old in self._previous.items():
            if signal.getsignal(sig) == self._handler:
                signal.signal(sig, old)
