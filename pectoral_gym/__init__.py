"""pectoral-gym: a robotic fish with two rowing pectoral fins, as models and Gymnasium environments.

Importing the package registers ``PectoralFish-Full-v2`` and ``PectoralFish-Averaged-v2`` (and their ``-v1``, ``-v0``),
and nothing more: the model's classes exported here are imported at their first use, numba when the first
kernel is called (:class:`pectoral_gym.model.jit.Kernel`).

The repository's folders ``agents/``, ``scaling/`` and ``hardware/`` are the subpackages
``pectoral_gym.agents``, ``.scaling`` and ``.hardware``: an install (wheel or editable) maps them through
setuptools' ``package-dir``; a checkout that is not installed (its root on ``sys.path``) through
:class:`CheckoutFinder`, which this module appends to ``sys.meta_path`` for the folders that sit beside
the package and that no install provides. Either way each module has one name.
"""

import importlib
import importlib.abc
import importlib.util
import os
import sys

#: The repository's top-level folders that are subpackages of ``pectoral_gym``.
APP_FOLDERS = ("agents", "scaling", "hardware")


class CheckoutFinder(importlib.abc.MetaPathFinder):
    """Finds ``pectoral_gym.<folder>`` in a checkout's top-level ``<folder>/`` (:data:`APP_FOLDERS`).

    As setuptools' editable finder does for an editable install, for the three mapped packages only;
    their submodules are then found through the package's ``__path__``. Appended after every other
    finder, so an install that provides the packages is asked first.

    Attributes:
        folders: Package name -> the checkout folder it is found in.
    """

    def __init__(self, folders: dict[str, str]) -> None:
        self.folders = dict(folders)

    def find_spec(self, fullname, path=None, target=None):
        """The spec of a mapped package (its folder's ``__init__.py``), else ``None``."""
        folder = self.folders.get(fullname)
        if folder is None:
            return None
        return importlib.util.spec_from_file_location(fullname, os.path.join(folder, "__init__.py"),
                                                      submodule_search_locations=[folder])


def _checkout_folders() -> dict[str, str]:
    """Package name -> folder of the :data:`APP_FOLDERS` that a checkout holds beside this package.

    Only packages that no finder provides yet (an install: inside this package for a wheel, through
    setuptools' editable finder for ``pip install -e``) and whose folder's ``__init__.py`` names the
    package it belongs to (its guard against a second name), so that an unrelated ``agents/`` beside a
    copy of this package is never taken for ours.
    """
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    found = {}
    for name in APP_FOLDERS:
        init = os.path.join(root, name, "__init__.py")
        if not os.path.isfile(init) or importlib.util.find_spec(f"pectoral_gym.{name}") is not None:
            continue
        with open(init, encoding="utf-8") as fh:
            if f'"pectoral_gym.{name}"' in fh.read():
                found[f"pectoral_gym.{name}"] = os.path.dirname(init)
    return found


if not any(isinstance(finder, CheckoutFinder) for finder in sys.meta_path):
    _folders = _checkout_folders()
    if _folders:
        sys.meta_path.append(CheckoutFinder(_folders))

from pectoral_gym.registration import register_envs  # noqa: E402 - the finder first, for the kernels' cache

__version__ = "0.2.0"

register_envs()

#: The names this package exports from its modules, imported at their first use (:func:`__getattr__`): importing
#: the package registers the envs and loads neither the model nor numba.
_LAZY = {
    "AveragedModel": "pectoral_gym.model.models",
    "FinBeat": "pectoral_gym.model.params",
    "FishModel": "pectoral_gym.model.models",
    "FishParams": "pectoral_gym.model.params",
    "FullModel": "pectoral_gym.model.models",
    "ScalingFunctions": "pectoral_gym.model.kfunctions",
}


def __getattr__(name: str):
    """The model's classes of :data:`__all__`, imported at their first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})


__all__ = ["AveragedModel", "FinBeat", "FishModel", "FishParams", "FullModel", "ScalingFunctions", "__version__"]
