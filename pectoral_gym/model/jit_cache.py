"""The kernels' disk cache, keyed on the source tree each kernel compiles from.

numba's own disk cache checks only the file of the function it caches, not the
files of the functions it calls or inlines (numba/numba#1833): after an edit of
``dynamics.py``, a cached kernel of ``stepping.py`` would keep the old code.
:class:`SourceTreeCache`, the cache :func:`pectoral_gym.model.jit.njit` gives every
kernel, therefore stamps it with a digest of the kernel's *source tree*
(:func:`source_tree_digest`): its own module and every module of the same
top-level package that it imports, directly or not, read from the ``import``
statements of the sources (:func:`source_tree`: the import graph, not a list kept
by hand). An edit of any of those files compiles the kernel afresh on its next
call; the stale entries are overwritten. What the digest does not see: files that
are not Python sources of the package (a data file read at import time and frozen
into a kernel as a global), and other installed packages (numba keys on its own version).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import inspect
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

from numba.core.caching import CompileResultCacheImpl, FunctionCache, _CacheLocator
from numba.core.dispatcher import Dispatcher

__all__ = ["SourceTreeCache", "source_tree", "source_tree_digest"]


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

    def __getattr__(self, name: str) -> Any:
        # The inner locator's other attributes (numba's warning that a kernel cannot be cached reads ``_py_file``).
        if name == "_inner":
            raise AttributeError(name)
        return getattr(self._inner, name)


def source_tree_digest(py_func: Callable[..., Any]) -> str:
    """SHA-256 (hex) of the source files a kernel compiles from: :func:`source_tree` of the modules it uses.

    The roots are the function's own module, and the modules of the compiled functions it holds in
    its globals or closure at decoration time (for :func:`~pectoral_gym.model.jit.kernel_pair`'s loops:
    the item and the guard).

    Args:
        py_func: The Python function of a kernel (``dispatcher.py_func``).

    Returns:
        64 hex digits; a file that cannot be read (a frozen application) counts by its module name only.
    """
    roots = {(py_func.__module__, inspect.getfile(py_func))}
    cells = [c.cell_contents for c in (py_func.__closure__ or ()) if _filled(c)]
    for value in [*py_func.__globals__.values(), *cells]:
        if _is_kernel(value):
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


@functools.cache
def _module_file(base: Path, module: str) -> Path | None:
    """The source file of ``module`` (``None`` if it is not a module, e.g. a name in one).

    Looked up below ``base`` package by package, as the import system would, also in the folder that
    the install maps a subpackage to where that is not the folder of its name (setuptools'
    ``package-dir``: ``pectoral_gym.agents`` is the checkout's ``agents/``). Found once per process: every
    kernel's digest walks the same modules, and a module added or removed while running is not imported
    by the running code either (the files' contents are still read at their current version).
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


def _is_kernel(value: Any) -> bool:
    """A numba dispatcher, or a :class:`pectoral_gym.model.jit.Kernel` (made or not).

    A kernel is known by its attributes: :mod:`pectoral_gym.model.jit` imports this module.
    """
    if isinstance(value, Dispatcher):
        return True
    attributes = getattr(value, "__dict__", None)
    return (isinstance(attributes, dict) and isinstance(attributes.get("targetoptions"), dict)
            and callable(attributes.get("py_func")))


def _filled(cell: Any) -> bool:
    try:
        cell.cell_contents  # noqa: B018 - an empty cell raises
    except ValueError:
        return False
    return True
