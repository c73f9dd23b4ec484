"""numba's worker threads, started to wait passively between parallel calls.

numba's parallel kernels run on a threading layer (``numba.threading_layer()``), by default
OpenMP (GNU libgomp) where it is installed. libgomp's threads spin after each parallel region
before they sleep, for a number of iterations fixed when the library loads (``GOMP_SPINCOUNT``;
by default a few milliseconds of CPU). The env steps are parallel regions separated by Python
work (the vector env's bookkeeping, the agent's policy): spinning threads take CPU time from
that work, and on a loaded machine from the step's own threads.

:func:`start_passive_threads` loads the threading layer with OpenMP's passive wait policy
(``OMP_WAIT_POLICY=PASSIVE``: sleep at once, wake on the next region) and leaves
``os.environ`` as it was, so neither other libraries nor child processes see the setting. It
does nothing when the threading layer has already been started (by any parallel kernel: the
policy is fixed then) or when the user set ``OMP_WAIT_POLICY`` or ``GOMP_SPINCOUNT``
(theirs applies). Only libgomp reads the variable; numba's other layers wait passively anyway.
"""

from __future__ import annotations

import os
import threading

import numba as nb
import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["start_passive_threads", "threads_started"]

_POLICY = "OMP_WAIT_POLICY"
_USER_SETTINGS = (_POLICY, "GOMP_SPINCOUNT")
_LOCK = threading.Lock()


def _touch(x):
    """A minimal parallel kernel: its first call starts numba's threading layer."""
    for i in nb.prange(x.shape[0]):
        x[i] = i


_START = njit(_touch, parallel=True)


def threads_started() -> bool:
    """Whether numba's threading layer has been started in this process (its wait policy is then fixed)."""
    try:
        nb.threading_layer()
    except ValueError:
        return False
    return True


def start_passive_threads() -> None:
    """Start numba's threading layer with passive waiting (module docstring), unless started or set by the user."""
    with _LOCK:
        if threads_started() or any(name in os.environ for name in _USER_SETTINGS):
            return
        os.environ[_POLICY] = "PASSIVE"
        try:
            _START(np.zeros(2))
        finally:
            os.environ.pop(_POLICY, None)
