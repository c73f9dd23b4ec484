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

numba's own disk cache checks only the file of the function it caches, not the
files of the functions it calls or inlines (numba/numba#1833): after an edit of
``dynamics.py``, a cached kernel of ``stepping.py`` would keep the old code.
:func:`njit` therefore stamps every kernel's cache with a digest of its *source
tree* (:func:`source_tree_digest`): its own module and every module of the same
top-level package that it imports, directly or not, read from the ``import``
statements of the sources (the import graph, not a list kept by hand). An edit
of any of those files compiles the kernel afresh on its next call; the stale
entries are overwritten. What the digest does not see: files that are not
Python sources of the package (a data file read at import time and frozen into
a kernel as a global), and other installed packages (numba keys on its own version).

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

import ast
import functools
import hashlib
import importlib.util
import inspect
import os
import sys
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numba as nb
from numba.core.caching import CompileResultCacheImpl, FunctionCache, _CacheLocator
from numba.core.dispatcher import Dispatcher

__all__ = ["JIT", "PARALLEL_MIN_ITEMS", "KernelPair", "SourceTreeCache", "entry_point", "kernel_builds",
           "kernel_pair", "njit", "source_tree", "source_tree_digest"]

JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}

PARALLEL_MIN_ITEMS = 64  # below this many items (fish, envs), thread start-up costs more than it saves


def njit(function: Callable[..., Any] | None = None, /, **options: Any) -> Any:
    """``numba.njit`` with :data:`JIT` (updated by ``options``), its disk cache keyed on its source tree.

    Use as ``@njit``, ``@njit(inline="always")`` or ``njit(function, parallel=True)``.
    With ``cache=False`` it is ``numba.njit`` with the other options.

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


class SourceTreeCache(FunctionCache):
    """numba's per-function disk cache, its index stamped with :func:`source_tree_digest` instead of one file's hash.

    numba drops an index whose stamp differs from the current one (and then
    overwrites its data files), so a kernel compiles afresh after an edit of
    any file in its source tree.
    """

    class _Impl(CompileResultCacheImpl):
        def __init__(self, py_func: Callable[..., Any]) -> None:
            super().__init__(py_func)  # picks numba's locator: NUMBA_CACHE_DIR, __pycache__, user-wide, ...
            self._locator = _TreeStampLocator(self._locator, source_tree_digest(py_func))

    _impl_class = _Impl


class _TreeStampLocator(_CacheLocator):
    """numba's own cache locator for a function, with the digest of its source tree as the source stamp."""

    def __init__(self, inner: _CacheLocator, stamp: str) -> None:
        self._inner = inner
        self._stamp = stamp

    def ensure_cache_path(self) -> None:
        self._inner.ensure_cache_path()

    def get_cache_path(self) -> str:
        return self._inner.get_cache_path()

    def get_source_stamp(self) -> str:
        return self._stamp

    def get_disambiguator(self) -> str:
        return self._inner.get_disambiguator()


def source_tree_digest(py_func: Callable[..., Any]) -> str:
    """SHA-256 (hex) of the source files a kernel compiles from: :func:`source_tree` of the modules it uses.

    The roots are the function's own module, and the modules of the compiled functions it holds in
    its globals or closure at decoration time (for :func:`kernel_pair`'s loops: the item and the guard).

    Args:
        py_func: The Python function of a kernel (``dispatcher.py_func``).

    Returns:
        64 hex digits; a file that cannot be read (a frozen application) counts by its module name only.
    """
    roots = {(py_func.__module__, inspect.getfile(py_func))}
    cells = [c.cell_contents for c in (py_func.__closure__ or ()) if _filled(c)]
    for value in [*py_func.__globals__.values(), *cells]:
        if isinstance(value, Dispatcher):
            roots.add((value.py_func.__module__, inspect.getfile(value.py_func)))
    files: dict[str, Path | None] = {}
    for module, file in sorted(roots):
        files.update(source_tree(module, file))
    digest = hashlib.sha256()
    for module in sorted(files):
        path = files[module]
        digest.update(module.encode() + b"\0" + (_read(path).digest if path is not None else b"") + b"\0")
    return digest.hexdigest()


def source_tree(module: str, file: str | os.PathLike[str]) -> dict[str, Path | None]:
    """``module`` and every module of its top-level package that it imports, directly or not, with their files.

    Read from the ``import`` statements anywhere in the sources (also inside functions and
    ``if TYPE_CHECKING:``; a module imported for nothing compiled only costs a recompilation).
    ``from p import name`` counts ``p.name`` when that is a module, else ``p``; the packages'
    ``__init__`` files that an import runs on the way count only when names are taken from them.

    Args:
        module: Dotted module name, e.g. ``"pectoral_gym.model.stepping"``.
        file: Its source file.

    Returns:
        Module name to source file (``None`` where the file cannot be read), ``module`` included.
    """
    path = Path(file)
    base = _base(module, path)
    top = module.split(".")[0]
    tree: dict[str, Path | None] = {}
    todo = [(module, path)]
    while todo:
        name, source = todo.pop()
        if name in tree:
            continue
        readable = source is not None and source.is_file()
        tree[name] = source if readable else None
        if not readable:
            continue
        package = name if source.name == "__init__.py" else name.rpartition(".")[0]
        for choices in _imports_of(source, package):
            if choices[-1] != top and not choices[-1].startswith(top + "."):
                continue  # another package
            found = [(c, f) for c in choices if (f := _module_file(base, c)) is not None]
            imported, imported_file = found[0] if found else (choices[-1], None)
            if imported not in tree:
                todo.append((imported, imported_file))
    return tree


class _Source(NamedTuple):
    digest: bytes  # SHA-256 of the file's bytes
    tree: ast.Module | None  # None for a file that is not valid Python


def _read(path: Path) -> _Source:
    stat = path.stat()
    return _read_version(path, stat.st_mtime_ns, stat.st_size)


@functools.cache
def _read_version(path: Path, mtime_ns: int, size: int) -> _Source:
    """The file's digest and syntax tree; keyed on its time and size, so an edit while running is read again."""
    data = path.read_bytes()
    try:
        tree = ast.parse(data)
    except (SyntaxError, ValueError):
        tree = None
    return _Source(hashlib.sha256(data).digest(), tree)


def _imports_of(path: Path, package: str) -> tuple[tuple[str, ...], ...]:
    """:func:`_imports` of the file's current version (walked once per version: every kernel's digest reads them)."""
    stat = path.stat()
    return _imports_of_version(path, stat.st_mtime_ns, stat.st_size, package)


@functools.cache
def _imports_of_version(path: Path, mtime_ns: int, size: int, package: str) -> tuple[tuple[str, ...], ...]:
    return tuple(_imports(_read_version(path, mtime_ns, size).tree, package))


def _imports(tree: ast.Module | None, package: str) -> Iterator[tuple[str, ...]]:
    """Per imported name, the modules it may come from, likeliest first.

    ``from p import name`` gives ``("p.name", "p")``: a submodule, or a name defined in ``p``.
    """
    for node in ast.walk(tree) if tree is not None else ():
        if isinstance(node, ast.Import):
            yield from ((alias.name,) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: ``from . import x`` in package ``package``
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                source = ".".join(anchor + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                yield (source,) if alias.name == "*" else (f"{source}.{alias.name}", source)


def _base(module: str, path: Path) -> Path:
    """The folder that holds the top-level package of ``module``, whose source file is ``path``.

    The file's folders when they spell the module's name; else (a subpackage that the install maps to a
    folder of another name, as ``pectoral_gym.agents`` to the checkout's ``agents/``) the folder that the
    import system finds the top-level package in (found, not imported).
    """
    parts = module.split(".")
    folder = path.parent
    for name in reversed(parts if path.name == "__init__.py" else parts[:-1]):
        if folder.name != name:
            spec = importlib.util.find_spec(parts[0])
            locations = list(spec.submodule_search_locations or ()) if spec is not None else []
            return Path(locations[0]).parent if locations else path.parent
        folder = folder.parent
    return folder


def _module_file(base: Path, module: str) -> Path | None:
    """The source file of ``module`` (``None`` if it is not a module, e.g. a name in one).

    Looked up below ``base`` package by package, as the import system would, also in the folder that
    the install maps a subpackage to where that is not the folder of its name (setuptools'
    ``package-dir``: ``pectoral_gym.agents`` is the checkout's ``agents/``).
    """
    parent, _, leaf = module.rpartition(".")
    folders = _package_folders(base, parent) if parent else (base,)
    for folder in folders:
        stem = folder / leaf
        for candidate in (stem.with_suffix(".py"), stem / "__init__.py"):
            if candidate.is_file():
                return candidate
    for folder in _mapped_folders(module, folders) if parent and folders else ():
        if (folder / "__init__.py").is_file():
            return folder / "__init__.py"
    return None


def _package_folders(base: Path, package: str) -> tuple[Path, ...]:
    """The folder of the submodules of ``package`` (none if it is not a package)."""
    init = _module_file(base, package)
    return (init.parent,) if init is not None and init.name == "__init__.py" else ()


@functools.cache
def _mapped_folders(package: str, parent_folders: tuple[Path, ...]) -> tuple[Path, ...]:
    """The folders a finder of ``sys.meta_path`` (an editable install's) maps ``package`` to; imports nothing."""
    for finder in sys.meta_path:
        find_spec = getattr(finder, "find_spec", None)
        spec = find_spec(package, [os.fspath(f) for f in parent_folders]) if find_spec is not None else None
        if spec is not None:
            return tuple(Path(f) for f in spec.submodule_search_locations or ())
    return ()


def _filled(cell: Any) -> bool:
    try:
        cell.cell_contents  # noqa: B018 - an empty cell raises
    except ValueError:
        return False
    return True


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
        # keyed on the source trees of the item's and the guard's modules (source_tree_digest).
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
