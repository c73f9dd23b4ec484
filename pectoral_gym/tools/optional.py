"""Optional dependencies: import one, or say which extra of the distribution brings it."""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["require"]


def require(module: str, extra: str = "plots") -> ModuleType:
    """Import ``module`` (e.g. ``"matplotlib.figure"``), which the core dependencies do not bring.

    Args:
        module: Dotted module name.
        extra: The extra that installs it (``plots``: matplotlib and tqdm).

    Returns:
        The module.

    Raises:
        ModuleNotFoundError: If its distribution is not installed, naming the extra to install.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as error:
        top = module.split(".")[0]
        if error.name != top:
            raise
        raise ModuleNotFoundError(f"{top} is not installed; it comes with the extra {extra!r}: "
                                  f"pip install 'pectoral-gym[{extra}]'", name=top) from error
