"""The envs' groups of optional settings (``EnvConfig.sensing``, ``EnvConfig.timing``): how they are given, checked.

A group is a frozen dataclass of settings. :func:`coerce_group` turns what a user passes (``None``, ``True``, a
mapping of fields, an instance) into the dataclass or ``None``; :func:`level_range` checks one of its ``(low,
high)`` ranges. Errors name the group and the setting (``sensing['latency']``). Imports nothing of the package.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields
from typing import Any, TypeVar

__all__ = ["coerce_group", "level_range"]

Group = TypeVar("Group")


def coerce_group(cls: type[Group], option: str, value: Any) -> Group | None:
    """``value`` of the option group ``option`` as a ``cls`` instance, or ``None`` (off).

    ``None`` or ``False``: off; ``True``: the defaults; a mapping of ``cls``'s fields (``{}``: the defaults); a
    ``cls`` instance as it is.

    Raises:
        ValueError: For another value, an unknown key, or an invalid setting (``cls``'s own checks).
    """
    if value is None or value is False:
        return None
    if value is True:
        return cls()
    if isinstance(value, cls):
        return value
    names = [f.name for f in fields(cls)]
    if not isinstance(value, Mapping):
        raise ValueError(f"{option} must be None, True, or a mapping of {names}, got {value!r}")
    unknown = sorted(set(value) - set(names))
    if unknown:
        raise ValueError(f"{option}: unknown settings {unknown}; valid: {names}")
    return cls(**value)


def level_range(option: str, name: str, value: Any, upper: float | None = None) -> tuple[float, float]:
    """``value`` as a range ``(low, high)`` with finite ``0 <= low <= high`` (``<= upper`` if given).

    A number ``v`` means ``(v, v)``.

    Raises:
        ValueError: Naming ``option[name]`` and the value.
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (value, value)
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{option}[{name!r}] must be a number or a pair (low, high), got {value!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
        raise ValueError(f"{option}[{name!r}] needs finite 0 <= low <= high, got {value!r}")
    if upper is not None and high > upper:
        raise ValueError(f"{option}[{name!r}] must stay <= {upper}, got {value!r}")
    return low, high
