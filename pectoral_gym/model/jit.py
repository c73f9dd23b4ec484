"""The numba options every compiled kernel uses, the kernels made at their first use, and the kernel factories.

``JIT`` is the one set of options (:func:`njit` applies them): on-disk cache, no GIL,
numpy's error model (a division by zero gives ``inf``/``nan`` instead of an
exception, as in the numpy reference code); ``njit(function, parallel=True)``
compiles a ``prange`` kernel.

:func:`njit` returns a :class:`Kernel`, which makes its numba dispatcher (and imports numba) at its
first call, or when a kernel that calls it compiles: importing a module of kernels imports no numba
and compiles nothing, and a run compiles only what it calls. :func:`kernel_variant` compiles a copy of
a function with some of its globals bound to other values; numba takes globals as constants and
prunes the branches they rule out before it types them (one body, a kernel per model:
:mod:`pectoral_gym.model.stepping`).

:func:`kernel_pair` builds, from a per-item kernel ``item(i, ...)``, a serial
and a ``prange`` loop over the items and a dispatcher that picks one by the
batch size (:data:`PARALLEL_MIN_ITEMS`). numba's ``prange`` kernels do not
accept ``*args`` holding tuples, so the two loops are generated as source with
the argument names spelled out (and cached on disk like hand-written kernels,
keyed on the source trees of the item's and the guard's modules).

The disk cache of every kernel is keyed on its *source tree*, every module of the
package it compiles from (:mod:`pectoral_gym.model.jit_cache`), not only on its own
file as numba's is: an edit of a function that a cached kernel calls or inlines
reaches the kernel. Behind numba's cache, the kernels shipped compiled with the package
(:mod:`pectoral_gym.model.kernel_bundle`).

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
import importlib
import threading
import types
from collections.abc import Callable
from typing import Any, NamedTuple

__all__ = ["JIT", "PARALLEL_MIN_ITEMS", "Kernel", "KernelPair", "entry_point", "kernel_builds", "kernel_pair",
           "kernel_variant", "njit"]

JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}

PARALLEL_MIN_ITEMS = 64  # below this many items (fish, envs), thread start-up costs more than it saves

_BUILD_LOCK = threading.RLock()  # one numba dispatcher per kernel, also when threads call it first together


class Kernel:
    """A numba kernel that becomes a numba dispatcher at its first use; numba is imported only then.

    :func:`njit` returns one. Importing a module of kernels therefore costs no numba import and no
    compilation; what a run calls (from Python, or from a kernel being compiled) is made and
    compiled then, and nothing else. It stands for its dispatcher everywhere:

    * called from Python, it calls the dispatcher (about 0.1 us more than calling it directly;
      the env step calls the compiled entry point, :func:`entry_point`);
    * numba types it as its dispatcher when a kernel that calls it compiles (``_numba_type_``),
      and inlines its Python function there when made with ``inline="always"`` (numba reads
      ``targetoptions`` and ``py_func`` for that; such a kernel is never compiled on its own);
    * any other attribute (``signatures``, ``overloads``, ``compile``, ...) is the dispatcher's.

    Copies are the kernel itself, as for a dispatcher (its compiled code is shared, not copied);
    a kernel of a module pickles by its name.

    Attributes:
        py_func: The Python function.
        targetoptions: The numba options it is compiled with (:data:`JIT` without ``cache``, with the
            decorator's options).
        cached: Whether its compiled code is kept in the disk cache keyed on its source tree.
    """

    def __init__(self, py_func: Callable[..., Any], targetoptions: dict[str, Any], cached: bool,
                 prepare: Callable[[], None] | None = None) -> None:
        functools.update_wrapper(self, py_func)
        self.py_func = py_func
        self.targetoptions = dict(targetoptions)
        self.cached = bool(cached)
        self._prepare = prepare  # binds names the function reads at compile time (numba itself: kernel_pair)
        self._dispatcher: Any = None

    @property
    def dispatcher(self) -> Any:
        """The numba dispatcher, made (numba imported) at the first access; the function under ``NUMBA_DISABLE_JIT``."""
        dispatcher = self._dispatcher
        return dispatcher if dispatcher is not None else self._build()

    @property
    def built(self) -> bool:
        """Whether the dispatcher has been made (it compiles at its first call, or when a caller compiles)."""
        return self._dispatcher is not None

    def _build(self) -> Any:
        with _BUILD_LOCK:
            if self._dispatcher is None:
                import numba as nb
                from numba.core.dispatcher import Dispatcher

                from pectoral_gym.model.kernel_bundle import BundledCache

                if self._prepare is not None:
                    self._prepare()
                dispatcher = nb.njit(**self.targetoptions)(self.py_func)
                if self.cached and isinstance(dispatcher, Dispatcher):
                    # What Dispatcher.enable_caching sets (numba.njit(cache=True)), with the source-tree stamp
                    # and the kernels shipped with the package behind it (model.kernel_bundle).
                    dispatcher._cache = BundledCache(dispatcher.py_func)
                self._dispatcher = dispatcher
            return self._dispatcher

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """Call the dispatcher (compiled for these argument types at the first such call)."""
        dispatcher = self._dispatcher
        if dispatcher is None:
            dispatcher = self._build()
        return dispatcher(*args, **kwargs)

    @property
    def _numba_type_(self) -> Any:
        """The numba type of the dispatcher: how a compiling kernel sees this one (``numba.typeof``)."""
        return self.dispatcher._numba_type_

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("_dispatcher", "_prepare", "py_func", "targetoptions", "cached"):
            raise AttributeError(name)  # not set yet (unpickling), or not the dispatcher's to give
        return getattr(self.dispatcher, name)

    def __copy__(self) -> Kernel:
        return self

    def __deepcopy__(self, memo: dict[int, Any]) -> Kernel:
        return self

    def __reduce__(self) -> Any:
        if _kernel_named(self.__module__, self.__qualname__, strict=False) is self:
            return _kernel_named, (self.__module__, self.__qualname__)
        return self.dispatcher.__reduce__()  # a generated kernel: numba pickles its dispatcher

    def __repr__(self) -> str:
        state = "built" if self.built else "not built"
        return f"<pectoral_gym kernel {self.__module__}.{self.__qualname__} ({state})>"


def _kernel_named(module: str, qualname: str, strict: bool = True) -> Any:
    """The object ``module.qualname`` (a kernel defined at module level); ``None`` if absent and not ``strict``."""
    try:
        value: Any = importlib.import_module(module)
        for part in qualname.split("."):
            value = getattr(value, part)
    except (ImportError, AttributeError):
        if strict:
            raise
        return None
    return value


def njit(function: Callable[..., Any] | None = None, /, **options: Any) -> Any:
    """A :class:`Kernel`: ``numba.njit`` with :data:`JIT` (updated by ``options``) at its first use.

    Its disk cache is a :class:`~pectoral_gym.model.kernel_bundle.BundledCache`, keyed on its source tree.
    Use as ``@njit``, ``@njit(inline="always")`` or ``njit(function, parallel=True)``. With
    ``cache=False`` it is ``numba.njit`` with the other options.

    Args:
        function: The Python function to compile; without it, a decorator.
        **options: numba options over :data:`JIT`.

    Returns:
        The :class:`Kernel`, or a decorator.
    """
    if function is None:
        return functools.partial(njit, **options)
    merged = {**JIT, **options}
    cache = merged.pop("cache")
    return Kernel(function, merged, cache)


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
        scope = {"nb": None, "item": item, "guard": guard}  # numba itself bound when the loop is first built
        # Compiled under the item's file name and module: the disk cache sits beside the item's own and is
        # keyed on the source trees of the item's and the guard's modules (jit_cache.source_tree_digest).
        exec(compile(source, py_item.__code__.co_filename, "exec"), scope)  # noqa: S102 - fixed template
        function = scope[name]
        function.__module__ = py_item.__module__
        function.__qualname__ = name
        options = {**JIT, "parallel": parallel}
        kernels.append(Kernel(function, options, options.pop("cache"), functools.partial(_bind_numba, scope)))
    serial, parallel = kernels

    def run(*arrays: Any) -> Any:
        kernel = parallel if arrays[0].shape[0] >= PARALLEL_MIN_ITEMS else serial
        return kernel(*arrays)

    run.__doc__ = f"Run ``{base}`` over all items: serial below {PARALLEL_MIN_ITEMS} items, parallel from there."
    return KernelPair(serial, parallel, run)


def _bind_numba(scope: dict[str, Any]) -> None:
    import numba

    scope["nb"] = numba


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
    builds = [kernel_variant(function, f"{base}_{kind}", bindings, parallel=parallel, cache=cache)
              for kind, parallel in (("serial", False), ("parallel", True))]
    serial, parallel = builds

    def run(first: Any, *rest: Any) -> Any:
        return (parallel if first.shape[0] >= PARALLEL_MIN_ITEMS else serial)(first, *rest)

    return KernelPair(serial, parallel, run)


def kernel_variant(function: Callable[..., Any], name: str, bindings: dict[str, Any] | None = None,
                   **options: Any) -> Kernel:
    """A kernel (:func:`njit` with ``options``) of a copy of ``function`` named ``name``, globals ``bindings`` replaced.

    numba takes a function's globals as compile-time constants and prunes a branch on one (``if AVERAGED:``)
    before it inlines or types what the branch calls, so a variant compiles only the code its constants reach.

    Args:
        function: The Python function (module level).
        name: The copy's name (and qualified name): its disk cache's, distinct from every other kernel's of the module.
        bindings: Globals of ``function`` to replace in the copy (e.g. a constant, or a kernel it calls).
        **options: As for :func:`njit`.
    """
    scope = function.__globals__ if not bindings else {**function.__globals__, **bindings}
    copy = types.FunctionType(function.__code__, scope, name, function.__defaults__, function.__closure__)
    copy.__qualname__ = name
    copy.__module__ = function.__module__
    copy.__doc__ = function.__doc__
    return njit(copy, **options)


def entry_point(kernel: Callable[..., Any], example: tuple) -> Callable[..., Any]:
    """The compiled entry point of ``kernel`` for the numba types of ``example`` (compiled or loaded here).

    Calling it skips numba's typing of the arguments (about 1 us for a structref argument), so it
    must be called with arguments of exactly those types. Where numba does not expose entry points
    (another version, ``NUMBA_DISABLE_JIT``), the dispatcher itself.
    """
    import numba as nb

    signature = tuple(nb.typeof(x) for x in example)
    try:
        kernel.compile(signature)
        return kernel.overloads[signature].entry_point
    except (AttributeError, KeyError):  # pragma: no cover - other numba versions: the dispatcher, same types
        return kernel
