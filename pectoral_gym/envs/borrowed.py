"""Borrowed array views for compiled code: :func:`borrow`, a view that holds no reference to its array.

Used inside the one-call env step (:mod:`pectoral_gym.envs.fused`), whose kernels would otherwise count
references atomically at every inlined call that takes an array.
"""

from __future__ import annotations

import numpy as np
from numba.core import cgutils, ir_utils, types
from numba.extending import intrinsic, overload

__all__ = ["borrow"]


def borrow(array: np.ndarray) -> np.ndarray:
    """A view of ``array`` that holds no reference to it (its meminfo is null), for use inside one call.

    numba counts references to an array atomically at every call or inlined function that takes
    it (tens per fish and step in the model's kernels), and the threads of a parallel build share
    those counts. A borrowed view's counting is a null check. It must not outlive the call that
    borrowed it: there the :class:`~pectoral_gym.envs.fused.StepArrays` argument holds the arrays for the whole
    step.
    A store through the view is a store into ``array``: numba's alias analysis is told so (:func:`_view_aliases`),
    wherever the store is made (straight-line code, a loop, a callee inlined with ``inline="always"``).
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


@overload(borrow)
def _borrow_overload(array):
    return lambda array: _borrowed(array)


def _view_aliases(lhs: str, args: list, alias_map: dict[str, set[str]], arg_aliases: set[str]) -> None:
    """For numba's alias analysis: the variable ``lhs`` assigned a borrowed view aliases the array it views.

    Without it numba takes the view for a new array of its own, and its dead-code removal drops a store through
    the view that nothing in the function reads afterwards (the array's owner does).
    """
    viewed = args[0].name
    if viewed in arg_aliases:
        arg_aliases.add(lhs)
        return
    alias_map.setdefault(viewed, set()).add(lhs)
    alias_map.setdefault(lhs, set()).add(viewed)


for _name in ("borrow", "_borrowed"):  # the call, and the intrinsic in the overload's own body
    ir_utils.alias_func_extensions[(_name, __name__)] = _view_aliases
