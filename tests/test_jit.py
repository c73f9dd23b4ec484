"""The serial/parallel kernel-pair factory of ``pectoral_gym.model.jit``.

Reference values are written out by hand; the serial loop, the parallel loop
and the dispatcher must agree with them for batches on both sides of the
dispatch threshold.
"""

import numba as nb
import numpy as np
import pytest

from pectoral_gym.model.jit import JIT, PARALLEL_MIN_ITEMS, kernel_pair


@nb.njit(**JIT)
def _affine_one(i, x, out, gain):
    out[i] = gain[0] * x[i] + gain[1]


@nb.njit(**JIT)
def _first_negative(x, skip):
    for i in range(x.shape[0]):
        if not skip[i] and x[i] < 0.0:
            return i
    return -1


@nb.njit(**JIT)
def _square_one(i, x, out):
    out[i] = x[i] * x[i]


AFFINE = kernel_pair(_affine_one, "x, out, gain")
SQUARE = kernel_pair(_square_one, "x, skip, out", item_args="x, out", skip="skip",
                     guard=_first_negative, guard_args="x, skip")


@pytest.mark.parametrize("n", [3, PARALLEL_MIN_ITEMS, 3 * PARALLEL_MIN_ITEMS + 1])
@pytest.mark.parametrize("kernel", ["serial", "parallel", "run"])
def test_loops_apply_the_item_to_every_row_with_tuple_arguments(n, kernel):
    x = np.arange(n, dtype=np.float64)
    out = np.full(n, np.nan)
    result = getattr(AFFINE, kernel)(x, out, (2.0, -1.0))  # a tuple argument, as the K tables are
    assert result is None
    np.testing.assert_array_equal(out, 2.0 * x - 1.0)


@pytest.mark.parametrize("n", [5, 2 * PARALLEL_MIN_ITEMS])
@pytest.mark.parametrize("kernel", ["serial", "parallel", "run"])
def test_mask_and_guard(n, kernel):
    x = np.arange(n, dtype=np.float64)
    skip = np.zeros(n, dtype=np.bool_)
    skip[1] = True
    out = np.zeros(n)
    assert getattr(SQUARE, kernel)(x, skip, out) == -1  # the guard passed, the loop ran
    expected = x * x
    expected[1] = 0.0  # skipped
    np.testing.assert_array_equal(out, expected)
    x[3] = -1.0
    skip[:] = False
    out[:] = 7.0
    assert getattr(SQUARE, kernel)(x, skip, out) == 3  # the guard's value, nothing written
    np.testing.assert_array_equal(out, 7.0)


def test_bad_argument_names_are_refused():
    with pytest.raises(ValueError, match="not one of the kernel arguments"):
        kernel_pair(_square_one, "x, out", item_args="x, y")
    with pytest.raises(ValueError, match="identifiers"):
        kernel_pair(_square_one, "x, out[0]")


def _halve(x):
    return 0.5 * x


def test_a_kernel_is_made_at_its_first_call_and_stands_for_its_dispatcher():
    import copy
    import pickle

    from pectoral_gym.model import stepping
    from pectoral_gym.model.jit import Kernel, njit

    kernel = njit(_halve)
    assert isinstance(kernel, Kernel) and not kernel.built and kernel.__name__ == "_halve"
    assert kernel(3.0) == 1.5
    assert kernel.built and len(kernel.signatures) == 1  # the dispatcher's attributes
    assert copy.deepcopy(kernel) is kernel and copy.copy(kernel) is kernel
    module_kernel = stepping.advance_averaged_one
    assert pickle.loads(pickle.dumps(module_kernel)) is module_kernel  # by name, unbuilt or not
