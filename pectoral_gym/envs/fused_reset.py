"""The one-env reset after its draws, in one compiled call (what ``EnvCore.reset`` runs for a single env).

:meth:`pectoral_gym.envs.core.EnvCore.reset` of one env, with neither camera nor control timing nor
randomised parameters and a task that starts its episodes with the built-in ``tasks.start_states``, draws the
episode in Python (the env's generator) and hands the draws to :class:`FusedReset`, which runs, in one call
of :func:`reset_one` and in this order, what the general reset runs as separate calls:

1. ``tasks.start_states``: the targets into ``ep`` and the fish's start state (``TaskState.start``);
2. the model's rows at that state, fins at the start of the rest patterns, velocity integrals and
   forcing cache zero (``FishModel.reset``; the fin rows are the model's own, ``FishModel.start_rows``);
3. the commanded patterns at rest and ``tasks.observe_reset`` (``TaskState.observe_reset``);
4. with ``observe_fins``, the observation's fin block (``tasks.observe_fins``).

The same kernels on the same arrays in the same order: the same bits as the general reset
(``tests/test_fused_step.py``). The arrays are those the env's one-call step holds
(:class:`~pectoral_gym.envs.fused.StepArrays`); the call goes through its compiled entry point.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pectoral_gym.envs.fused import FusedStep
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model.jit import entry_point, njit

__all__ = ["FusedReset", "reset_one"]


@njit
def reset_one(a, draws, start, fins0, pending0, rest, action_code, index):
    """Start env ``index[0]``'s episode from ``draws`` ``(1, 8)`` on the arrays of ``a`` (module docstring).

    ``start`` ``(1, 6)`` receives the start state; ``fins0`` ``(2, FIN_FIELDS)`` and ``pending0`` ``(2, 4)`` are
    the model's rows at the start of the rest patterns, ``rest`` ``(2, 4)`` those patterns, ``action_code``
    ``(8,)`` their normalised action.
    """
    # the fields as plain arrays, read once (a reset is one call per episode: numba's reference counts on them
    # cost nothing to speak of, so no borrowed views as in the step)
    cfg, ep, beats, obs, out, fish = a.cfg, a.ep, a.beats, a.obs, a.out, a.fish
    state, fins, cache, pending, integral = a.state, a.fins, a.cache, a.pending, a.integral
    tk.start_states(index, draws, cfg, ep, start)
    i = index[0]
    state[i, :] = start[0]
    integral[i, :] = 0.0
    fins[i, :, :] = fins0
    pending[i, :, :] = pending0
    cache[i, :, :] = 0.0
    beats[i, :, :] = rest
    tk.observe_reset(index, state, ep, fish, obs, out, action_code)
    period = a.fin_period
    if period > 0.0:
        tk.observe_fins(fins, obs, period)


class FusedReset:
    """The reset of a one-env core after its draws, one compiled call (module docstring).

    Args:
        step: The core's :class:`~pectoral_gym.envs.fused.FusedStep` (its bound arrays are this reset's).
        fins0, pending0: The model's fin rows at the start of the rest patterns (``FishModel.start_rows``).
        rest: The rest patterns ``(2, 4)`` the commanded patterns are reset to.
        action_code: ``(8,)`` the normalised action of the rest patterns (``TaskState.action_code``).

    Pickles and deep-copies without its entry point (compiled code); a copy binds its own.
    """

    def __init__(self, step: FusedStep, fins0: np.ndarray, pending0: np.ndarray, rest: np.ndarray,
                 action_code: np.ndarray):
        self.step = step
        # C-contiguous float64 copies: the entry point's argument types, fixed once
        self.fins0, self.pending0, self.rest = (np.ascontiguousarray(x, dtype=np.float64)
                                                for x in (fins0, pending0, rest))
        self.action_code = np.ascontiguousarray(action_code, dtype=np.float64)
        self.draws = np.zeros((1, 8))
        self.start = np.zeros((1, 6))
        self.index = np.zeros(1, dtype=np.int64)
        self._call: Callable[..., Any] | None = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_call"] = None
        return state

    def __call__(self, draws: np.ndarray) -> None:
        """Start the episode of env 0 from its ``(8,)`` draws (``TaskState.draw``, pins applied)."""
        buffer = self.draws
        buffer[0] = draws  # float64, as start_states reads every draw
        args = (self.step.arrays(), buffer, self.start, self.fins0, self.pending0, self.rest, self.action_code,
                self.index)
        call = self._call
        if call is None:  # the arguments' types are fixed (arrays updated in place, never replaced)
            call = self._call = entry_point(reset_one, args)
        call(*args)
