"""The numba options every compiled kernel uses, and the serial/parallel kernel-pair factory.

``JIT`` is the one set of options (:func:`njit` applies them): on-disk cache, no GIL,
numpy's error model (a division by zero gives ``inf``/``nan`` instead of an
exception, as in the numpy reference code); ``njit(function, parallel=True)``
compiles a ``prange`` kernel.

:func:`kernel_pair` builds, from a per-item kernel ``item(i, ...)``, a serial
and a ``prange`` loop over the items and a dispatcher that picks one by the
batch size (:data:`PARALLEL_MIN_ITEMS`). numba's ``prange`` kernels do not
accept ``*args`` holding tuples, so the two loops are generated as source with
the argument names spelled out (and cached on disk like hand-written kernels,
keyed on the source trees of the item's and the guard's modules).

The disk cache of every kernel is keyed on its *source tree*, every module of the
package it compiles from (:mod:`pectoral_gym.model.jit_cache`), not only on its own
file as numba's is: an edit of a function that a cached kernel calls or inlines
reaches the kernel.

Every kernel of the package is decorated with :func:`njit` (``@njit`` or
``@njit(inline="always")``), never with ``numba.njit(cache=True)`` directly.

Example (the model integrators, :mod:`pectoral_gym.model.stepping`)::

    advance_kernels = kernel_pair(advance_one, "state, fins, cache, pending, integral, coef, duration, ...")
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

import functools
import types
from collections.abc import Callable
from typing import Any, NamedTuple

import numba as nb
from numba.core.dispatcher import Dispatcher

from pectoral_gym.model.jit_cache import SourceTreeCache

__all__ = ["JIT", "PARALLEL_MIN_ITEMS", "KernelPair", "entry_point", "kernel_builds", "kernel_pair", "njit"]

JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}

PARALLEL_MIN_ITEMS = 64  # below this many items (fish, envs), thread start-up costs more than it saves


def njit(function: Callable[..., Any] | None = None, /, **options: Any) -> Any:
    """``numba.njit`` with :data:`JIT` (updated by ``options``), its disk cache keyed on its source tree.

    The cache is a :class:`~pectoral_gym.model.jit_cache.SourceTreeCache`. Use as ``@njit``,
    ``@njit(inline="always")`` or ``njit(function, parallel=True)``. With ``cache=False`` it is
    ``numba.njit`` with the other options.

    Args:
        function: The Python function to compile; without it, a decorator.
        **options: numba options over :data:`JIT`.

    Returns:
        The numba dispatcher (the function itself under ``NUMBA_DISABLE_JIT``), or a decorator.
    """
    if function is None:
        return functools.partial(njit, **options)
    merged = {**JIT, **options}
    cache = merged.pop("cache")
    dispatcher = nb.njit(**merged)(function)
    if cache and isinstance(dispatcher, Dispatcher):
        # What Dispatcher.enable_caching sets (numba.njit(cache=True)), with the source-tree stamp.
        dispatcher._cache = SourceTreeCache(dispatcher.py_func)
    return dispatcher


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
    for kind, loop, parallel in (("serial", "range", False), ("parallel", "nb.prange", True)):
        name = f"_{base}_{kind}"
        source = _TEMPLATE.format(
            name=name, args=", ".join(names), range=loop, first=names[0], item_args=", ".join(call),
            guard=(f"    bad = guard({', '.join(checked)})\n    if bad >= 0:\n        return bad\n" if guard else ""),
            skip=(f"        if {skip}[i]:\n            continue\n" if skip else ""),
            result=("    return -1\n" if guard else ""),
        )
        scope = {"nb": nb, "item": item, "guard": guard}
        # Compiled under the item's file name and module: the disk cache sits beside the item's own and is
        # keyed on the source trees of the item's and the guard's modules (jit_cache.source_tree_digest).
        exec(compile(source, py_item.__code__.co_filename, "exec"), scope)  # noqa: S102 - fixed template
        function = scope[name]
        function.__module__ = py_item.__module__
        function.__qualname__ = name
        kernels.append(njit(function, parallel=parallel))
    serial, parallel = kernels

    def run(*arrays: Any) -> Any:
        kernel = parallel if arrays[0].shape[0] >= PARALLEL_MIN_ITEMS else serial
        return kernel(*arrays)

    run.__doc__ = f"Run ``{base}`` over all items: serial below {PARALLEL_MIN_ITEMS} items, parallel from there."
    return KernelPair(serial, parallel, run)


def kernel_builds(
    function: Callable[..., Any],
    *,
    name: str | None = None,
    bindings: dict[str, Any] | None = None,
    cache: bool = True,
) -> KernelPair:
    """Serial and parallel builds of one kernel body written with ``numba.prange``, and their dispatcher.

    The body is compiled twice, as it is: with ``parallel=False`` (``prange`` is ``range``) and with
    ``parallel=True``; no source is generated. Each build is a copy of ``function`` under its own name
    (``<name>_serial``, ``<name>_parallel``), so their disk caches do not collide.

    Args:
        function: The Python function (module level) whose first argument's ``shape[0]`` is the batch size.
        name: Base name of the builds (default: the function's name).
        bindings: Globals of ``function`` to replace in the builds (e.g. the per-item kernel of a task
            registered at run time); such builds are not cached on disk unless ``cache``.
        cache: Keep the builds in numba's disk cache (keyed on the source tree, :func:`njit`).

    Returns:
        A :class:`KernelPair` (``run`` picks the parallel build from :data:`PARALLEL_MIN_ITEMS` items).
    """
    base = name or function.__name__
    scope = function.__globals__ if not bindings else {**function.__globals__, **bindings}
    builds = []
    for kind, parallel in (("serial", False), ("parallel", True)):
        copy = types.FunctionType(function.__code__, scope, f"{base}_{kind}", function.__defaults__,
                                  function.__closure__)
        copy.__qualname__ = f"{base}_{kind}"
        copy.__module__ = function.__module__
        copy.__doc__ = function.__doc__
        builds.append(njit(copy, parallel=parallel, cache=cache))
    serial, parallel = builds

    def run(first: Any, *rest: Any) -> Any:
        return (parallel if first.shape[0] >= PARALLEL_MIN_ITEMS else serial)(first, *rest)

    return KernelPair(serial, parallel, run)


def entry_point(kernel: Callable[..., Any], example: tuple) -> Callable[..., Any]:
    """The compiled entry point of ``kernel`` for the numba types of ``example`` (compiled or loaded here).

    Calling it skips numba's typing of the arguments (about 1 us for a structref argument), so it
    must be called with arguments of exactly those types. Where numba does not expose entry points
    (another version, ``NUMBA_DISABLE_JIT``), the dispatcher itself.
    """
    signature = tuple(nb.typeof(x) for x in example)
    try:
        kernel.compile(signature)
        return kernel.overloads[signature].entry_point
    except (AttributeError, KeyError):  # pragma: no cover - other numba versions: the dispatcher, same types
        return kernel
