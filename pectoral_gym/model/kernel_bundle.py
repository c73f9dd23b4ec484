"""The kernel bundle: compiled kernels shipped with the package, so a first step need not compile them.

numba compiles a kernel at its first call and keeps it in its disk cache; with an empty cache (a fresh
install, a CI run, a new machine) the first step of an env compiles for seconds. The package therefore
ships the kernels the envs' first reset and step call, compiled for any x86-64 processor (LLVM's
``generic`` CPU: the baseline instruction set, nothing of the build machine's), in
``pectoral_gym/data/kernels/`` (:data:`BUNDLE`), written by ``python -m pectoral_gym.tools.kernel_bundle``.

:class:`BundledCache`, the disk cache of every kernel (:func:`pectoral_gym.model.jit.njit`), looks a
kernel up in numba's cache first, then in the bundle; it takes a bundled kernel only for

* the same source tree (the stamp of :class:`~pectoral_gym.model.jit_cache.SourceTreeCache`: after
  an edit of any source a kernel compiles from, its bundled code is not used, it compiles as before),
* the same signature, bytecode, numba version, Python version and target triple (numba's own key,
  with the bundle's CPU in place of this machine's).

The arithmetic is the same: numba compiles without fast-math, so LLVM neither reorders nor fuses
floating-point operations for any CPU, and the generic code gives the same bits as code compiled for
this machine (``tests/test_kernel_bundle.py`` checks seeded episodes). ``PECTORAL_GYM_KERNEL_BUNDLE=0``
turns the bundle off (every kernel compiles for this machine, as without it); any other value names
another bundle folder.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from numba.core.caching import IndexDataCacheFile

from pectoral_gym.model.jit_cache import SourceTreeCache

__all__ = ["BUNDLE", "BUNDLE_CPU", "BUNDLE_SETTING", "MANIFEST", "BundledCache", "bundle_fits", "bundle_folder",
           "platform_key"]

#: The bundle shipped with the package: one folder per module, numba's index and data files inside.
BUNDLE = Path(__file__).resolve().parents[1] / "data" / "kernels"
#: The CPU the bundle is compiled for (``NUMBA_CPU_NAME``), with no extra CPU features.
BUNDLE_CPU = "generic"
#: Environment variable: ``0`` turns the bundle off, any other value is the folder of another bundle.
BUNDLE_SETTING = "PECTORAL_GYM_KERNEL_BUNDLE"


#: File in the bundle folder that names the platform it was built for (:func:`platform_key`).
MANIFEST = "manifest.json"


def platform_key() -> dict[str, str]:
    """What a bundled kernel must share with this process besides its source tree: numba, Python, target triple."""
    import numba
    from numba.core.registry import cpu_target

    return {"numba": numba.__version__, "python": f"{sys.version_info[0]}.{sys.version_info[1]}",
            "triple": cpu_target.target_context.codegen().magic_tuple()[0]}


def bundle_fits(folder: Path | None = None) -> bool:
    """Whether the bundle at ``folder`` (default: :func:`bundle_folder`) was built for this platform (its manifest)."""
    folder = bundle_folder() if folder is None else folder
    try:
        manifest = json.loads((folder / MANIFEST).read_text(encoding="utf-8")) if folder is not None else None
    except (OSError, ValueError):
        return False
    return manifest == platform_key()


def bundle_folder() -> Path | None:
    """The bundle in use: :data:`BUNDLE`, the folder :data:`BUNDLE_SETTING` names, or ``None`` when it is ``0``."""
    setting = os.environ.get(BUNDLE_SETTING, "")
    if setting == "0":
        return None
    return Path(setting) if setting else BUNDLE


class BundledCache(SourceTreeCache):
    """:class:`~pectoral_gym.model.jit_cache.SourceTreeCache` that falls back on the bundle (module docstring)."""

    def __init__(self, py_func: Callable[..., Any]) -> None:
        super().__init__(py_func)
        self._module = py_func.__module__

    def _bundle_file(self, folder: Path) -> IndexDataCacheFile:
        return IndexDataCacheFile(cache_path=str(folder / self._module), filename_base=self._impl.filename_base,
                                  source_stamp=self._impl.locator.get_source_stamp())

    def bundle_key(self, sig: Any, codegen: Any) -> tuple:
        """The numba index key of ``sig``, with the bundle's CPU (:data:`BUNDLE_CPU`, no features) for this one's."""
        signature, (triple, _cpu, _features), code = self._index_key(sig, codegen)
        return signature, (triple, BUNDLE_CPU, ""), code

    def _load_overload(self, sig: Any, target_context: Any) -> Any:
        data = super()._load_overload(sig, target_context)
        folder = bundle_folder()
        if data is None and self._enabled and folder is not None:
            payload = self._bundle_file(folder).load(self.bundle_key(sig, target_context.codegen()))
            if payload is not None:
                data = self._impl.rebuild(target_context, payload)
        return data

    def save_to_bundle(self, sig: Any, cres: Any, folder: Path) -> bool:
        """Write the compiled ``cres`` of ``sig`` into the bundle at ``folder``; ``False`` if numba cannot cache it.

        Raises:
            ValueError: If ``cres`` was not compiled for :data:`BUNDLE_CPU` (``NUMBA_CPU_NAME=generic``).
        """
        _triple, cpu, features = cres.codegen.magic_tuple()
        if (cpu, features) != (BUNDLE_CPU, ""):
            raise ValueError(f"a bundled kernel must be compiled for the {BUNDLE_CPU!r} CPU with no extra features "
                             f"(NUMBA_CPU_NAME={BUNDLE_CPU}), not {cpu!r}")
        if not self._impl.check_cachable(cres):
            return False
        (folder / self._module).mkdir(parents=True, exist_ok=True)
        self._bundle_file(folder).save(self.bundle_key(sig, cres.codegen), self._impl.reduce(cres))
        return True
