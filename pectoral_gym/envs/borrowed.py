"""Borrowed array views for compiled code: :func:`borrow`, a view that holds no reference to its array.

Used inside the one-call env step (:mod:`pectoral_gym.envs.fused`), whose kernels would otherwise count
references atomically at every inlined call that takes an array.
"""

from __future__ import annotations

import numpy as np
from numba.core import cgutils, types
from numba.extending import intrinsic, overload

__all__ = ["borrow"]


def borrow(array: np.ndarray) -> np.ndarray:
    """A view of ``array`` that holds no reference to it (its meminfo is null), for use inside one call.

    numba counts references to an array atomically at every call or inlined function that takes
    it (tens per fish and step in the model's kernels), and the threads of a parallel build share
    those counts. A borrowed view's counting is a null check. It must not outlive the call that
    borrowed it: there the :class:`~pectoral_gym.envs.fused.StepArrays` argument holds the arrays for the whole
    step.
    Write through a borrowed view only inside a loop (or a call made in one), as the step does: a store made
    through one in straight-line code, in the borrowing function or in a call it inlines there, was seen dropped
    by the compiler (numba 0.68, ``tests/test_borrowed_views.py`` holds the loop's way).
    In Python (``NUMBA_DISABLE_JIT``) it is ``array`` itself.
    """
    return array


@intrinsic
def _borrowed(typingctx, array):
    if not isinstance(array, types.Array):
        return None

    def codegen(context, builder, signature, args):
        view = context.make_array(array)(context, builder, value=args[0])
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()

    return array(array), codegen


@overload(borrow, inline="always")
def _borrow_overload(array):
    return lambda array: _borrowed(array)
