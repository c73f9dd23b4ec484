"""The numba options every compiled kernel uses, and the serial/parallel kernel-pair factory.

``JIT`` is the one set of options (``@nb.njit(**JIT)``): on-disk cache, no GIL,
numpy's error model (a division by zero gives ``inf``/``nan`` instead of an
exception, as in the numpy reference code). ``PARALLEL_JIT`` adds
``parallel=True`` for ``prange`` kernels.

:func:`kernel_pair` builds, from a per-item kernel ``item(i, ...)``, a serial
and a ``prange`` loop over the items and a dispatcher that picks one by the
batch size (:data:`PARALLEL_MIN_ITEMS`). numba's ``prange`` kernels do not
accept ``*args`` holding tuples, so the two loops are generated as source with
the argument names spelled out (and cached on disk like hand-written kernels,
keyed on the item's module file, so editing that module recompiles them).

numba's disk cache checks only the file of the function it caches, not the
files of the functions it calls: after editing, say, ``dynamics.py``, the
cached kernels of ``stepping.py`` keep the old code until ``stepping.py``
changes too or the cache is cleared (``find pectoral_gym -name '*.nb[ic]' -delete``).
:mod:`pectoral_gym.envs.fused`, whose step kernel inlines most of the package, closes over a
digest of those sources instead, so its cache follows them.

Example (the model integrators, :mod:`pectoral_gym.stepping`)::

    advance_kernels = kernel_pair(_advance_one, "state, fins, cache, pending, integral, coef, duration, ...")
    advance_kernels.run(state, fins, ...)   # serial below 64 fish, parallel from 64

Example with a mask, a guard and a result (``envs.tasks._apply_serial/_apply_parallel``)::

    apply_kernels = kernel_pair(
        _apply_one, "actions, skip, cfg, beats, obs, out, ep",
        item_args="actions, cfg, beats, obs, out, ep",   # what item(i, ...) takes after i
        skip="skip",                                     # items with skip[i] are left out
        guard=_first_non_finite, guard_args="actions, skip",
    )
    bad = apply_kernels.run(actions, skip, cfg, beats, obs, out, ep)  # guard's value if >= 0, else -1

and ``kernel_pair(_reward_one, "state, skip, cfg, ep, obs, out", item_args="state, cfg, ep, obs, out",
skip="skip")`` for ``_reward_serial/_reward_parallel``. ``serial`` and ``parallel`` are the
compiled loops themselves, for callers that choose once (e.g. per env core).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numba as nb

__all__ = ["JIT", "PARALLEL_JIT", "PARALLEL_MIN_ITEMS", "KernelPair", "kernel_pair"]

JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
PARALLEL_JIT: dict[str, Any] = {**JIT, "parallel": True}

PARALLEL_MIN_ITEMS = 64  # below this many items (fish, envs), thread start-up costs more than it saves


class KernelPair(NamedTuple):
    """A serial and a parallel compiled loop over the items of a batch, and the dispatcher between them.

    Attributes:
        serial: ``serial(*args)``, a plain loop.
        parallel: ``parallel(*args)``, the same loop over ``numba.prange``.
        run: ``run(*args)``: ``parallel`` when the first argument has at least
            :data:`PARALLEL_MIN_ITEMS` rows, else ``serial``.
    """

    serial: Callable[..., Any]
    parallel: Callable[..., Any]
    run: Callable[..., Any]


_TEMPLATE = """
def {name}({args}):
{guard}    for i in {range}({first}.shape[0]):
{skip}        item(i, {item_args})
{result}"""


def _names(spec: str) -> list[str]:
    names = [a.strip() for a in spec.split(",") if a.strip()]
    if not all(n.isidentifier() for n in names):
        raise ValueError(f"argument names must be identifiers separated by commas, got {spec!r}")
    return names


def kernel_pair(
    item: Callable[..., Any],
    args: str,
    *,
    item_args: str | None = None,
    skip: str | None = None,
    guard: Callable[..., Any] | None = None,
    guard_args: str | None = None,
) -> KernelPair:
    """Serial and ``prange`` loops ``for i in range(args[0].shape[0]): item(i, ...)`` and their dispatcher.

    Args:
        item: The compiled per-item kernel, ``item(i, *item_args)``; it writes
            its results into the arrays it is given (the loops return nothing
            of it). It must not allocate or take views, which would serialise the threads.
        args: The kernels' argument names, comma separated; the first one's
            ``shape[0]`` is the number of items.
        item_args: The names ``item`` takes after ``i`` (default: all of ``args``).
        skip: Name of a boolean mask among ``args``; items with ``skip[i]`` are left out.
        guard: Optional compiled check ``guard(*guard_args) -> int`` run before
            the loop: a value ``>= 0`` is returned at once without looping;
            with a guard the kernels return ``-1`` after the loop.
        guard_args: The names ``guard`` takes (default: all of ``args``).

    Returns:
        A :class:`KernelPair`.

    Raises:
        ValueError: For names that are not identifiers or not among ``args``.
    """
    names = _names(args)
    call = _names(item_args) if item_args is not None else names
    checked = _names(guard_args) if guard_args is not None else names
    for name in call + checked + ([skip] if skip else []):
        if name not in names:
            raise ValueError(f"{name!r} is not one of the kernel arguments {names}")
    py_item = getattr(item, "py_func", item)
    base = py_item.__name__.lstrip("_").removesuffix("_one")
    kernels = []
    for kind, loop, options in (("serial", "range", JIT), ("parallel", "nb.prange", PARALLEL_JIT)):
        name = f"_{base}_{kind}"
        source = _TEMPLATE.format(
            name=name, args=", ".join(names), range=loop, first=names[0], item_args=", ".join(call),
            guard=(f"    bad = guard({', '.join(checked)})\n    if bad >= 0:\n        return bad\n" if guard else ""),
            skip=(f"        if {skip}[i]:\n            continue\n" if skip else ""),
            result=("    return -1\n" if guard else ""),
        )
        scope = {"nb": nb, "item": item, "guard": guard}
        # Compiled under the item's file name: numba's disk cache then sits beside the item's own and is
        # invalidated when that module changes.
        exec(compile(source, py_item.__code__.co_filename, "exec"), scope)  # noqa: S102 - fixed template
        function = scope[name]
        function.__module__ = py_item.__module__
        function.__qualname__ = name
        kernels.append(nb.njit(**options)(function))
    serial, parallel = kernels

    def run(*arrays: Any) -> Any:
        kernel = parallel if arrays[0].shape[0] >= PARALLEL_MIN_ITEMS else serial
        return kernel(*arrays)

    run.__doc__ = f"Run ``{base}`` over all items: serial below {PARALLEL_MIN_ITEMS} items, parallel from there."
    return KernelPair(serial, parallel, run)
