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
policy is fixed then); when the user set ``OMP_WAIT_POLICY`` or ``GOMP_SPINCOUNT`` it starts the
layer with theirs. Only libgomp reads the variable; numba's other layers wait passively anyway.
:func:`pin_torch_threads` starts the layer before it sets torch's thread count, which the layer's
start would otherwise reset.
"""

from __future__ import annotations

import os
import threading

import numba as nb
import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["pin_torch_threads", "start_passive_threads", "threads_started"]

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
    """Start numba's threading layer with passive waiting (module docstring), or the user's policy if they set one."""
    with _LOCK:
        if threads_started():
            return
        if any(name in os.environ for name in _USER_SETTINGS):
            _START(np.zeros(2))  # started all the same (see :func:`pin_torch_threads`), with the user's policy
            return
        os.environ[_POLICY] = "PASSIVE"
        try:
            _START(np.zeros(2))
        finally:
            os.environ.pop(_POLICY, None)


def pin_torch_threads(n: int) -> None:
    """``torch.set_num_threads(n)`` that lasts: numba's threading layer is started first.

    torch and numba share GNU OpenMP's thread-count setting in this process: when numba's layer starts (at the
    first parallel env step) it sets it to numba's thread count, undoing a ``torch.set_num_threads`` made before
    (seen: 1 torch thread when ``PPO.learn`` starts, one per core after it). Starting the layer first keeps ``n``.
    """
    import torch

    start_passive_threads()
    torch.set_num_threads(int(n))
