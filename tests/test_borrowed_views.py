"""Borrowed views (``envs.borrowed.borrow``): every store through one reaches the array it views.

The fused step reads each field of its structref once as a borrowed view and writes through it in the calls and
loops it makes (``envs.fused.step_body``). A store that nothing in the function reads afterwards is what numba's
dead-code removal drops unless it knows the view aliases the array (``borrow``'s alias extension), wherever the
store is: straight-line code, a loop, a callee inlined in either (whose parameter bound to the view is visited
before the view's definition when ``borrow`` itself is inlined: it is not).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.experimental import structref

from pectoral_gym.envs.borrowed import borrow


@structref.register
class _HolderType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class _Holder(structref.StructRefProxy):
    pass


structref.define_proxy(_Holder, _HolderType, ["fins", "state"])


@njit(cache=False)
def _new_holder(fins, state):
    return _Holder(fins, state)


@njit(cache=False, inline="always")
def _write_row(x, row, i):
    x[i, :] = row


@njit(cache=False)
def _write_in_callee_in_loop(holder, row, n):
    state = borrow(holder.state)
    for i in range(n):
        _write_row(state, row + i, i)


@njit(cache=False)
def _write_in_callee_straight(holder, row, i):
    _write_row(borrow(holder.state), row, i)


@njit(cache=False)
def _write_in_callee_straight_plain(state, row, i):
    view = borrow(state)
    _write_row(view, row, i)


@njit(cache=False)
def _write_straight(holder, value, row, i):
    fins, state = borrow(holder.fins), borrow(holder.state)
    fins[i, 0, 0] = value
    state[i, :] = row


@njit(cache=False)
def _write_in_loop(holder, value, n):
    fins, state = borrow(holder.fins), borrow(holder.state)
    for i in range(n):
        fins[i, 0, 0] = value + i
        state[i, 1] = -(value + i)


def test_writes_through_borrowed_views_in_callees_and_loops_reach_the_arrays():
    fins, state = np.zeros((3, 2, 4)), np.zeros((3, 6))
    holder = _new_holder(fins, state)
    _write_in_callee_in_loop(holder, np.arange(6.0), 2)
    assert np.array_equal(state[:2], [np.arange(6.0), np.arange(6.0) + 1.0]) and not state[2].any()
    _write_in_loop(holder, 5.0, 3)
    assert np.array_equal(fins[:, 0, 0], [5.0, 6.0, 7.0])
    assert np.array_equal(state[:, 1], [-5.0, -6.0, -7.0])


def test_a_store_in_straight_line_code_through_a_borrowed_view_reaches_the_array():
    fins, state = np.zeros((3, 2, 4)), np.zeros((3, 6))
    _write_straight(_new_holder(fins, state), 5.0, np.arange(6.0), 2)
    assert fins[2, 0, 0] == 5.0 and np.count_nonzero(fins) == 1
    assert np.array_equal(state[2], np.arange(6.0)) and not state[:2].any()


def test_a_store_in_a_callee_inlined_in_straight_line_code_reaches_the_array():
    fins, state = np.zeros((3, 2, 4)), np.zeros((3, 6))
    _write_in_callee_straight(_new_holder(fins, state), np.arange(6.0), 1)
    assert np.array_equal(state[1], np.arange(6.0)) and np.count_nonzero(state) == 5 and not fins.any()
    plain = np.zeros((3, 6))
    _write_in_callee_straight_plain(plain, np.arange(6.0) + 1.0, 2)
    assert np.array_equal(plain[2], np.arange(6.0) + 1.0) and not plain[:2].any()
