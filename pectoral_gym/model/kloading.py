"""Loading scaling functions K for the averaged model: the one K loader and the yaw-damping section it keeps.

A coefficients file (:mod:`pectoral_gym.model.kfunctions`) may hold a yaw-damping section
(``docs/model.md`` 3.6); a model uses it or not, as its ``yaw_damping`` names (:data:`YAW_DAMPINGS`),
and an unused section is dropped. :func:`load_scaling` reads a file for a model of given parameters (with the
check that the file was identified for them), :func:`select_yaw_damping` keeps the section a model needs in
memory and :func:`held_yaw_damping` names the richest damping K holds. The model specs
(:mod:`pectoral_gym.model.spec`) and :class:`~pectoral_gym.model.models.AveragedModel` load K here.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

from pectoral_gym.model.kfile import WAVEFORM_TAG
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams

__all__ = ["YAW_DAMPINGS", "check_yaw_damping", "held_yaw_damping", "load_scaling", "select_yaw_damping"]

#: The averaged model's yaw damping (docs/model.md 3.6) and the coefficients-file section it needs:
#: ``"none"`` eq. (20)'s damping alone, ``"sinusoid"`` oscillation-averaged with the ``yaw_oscillation``
#: section's sinusoid.
YAW_DAMPINGS = {"none": None, "sinusoid": "yaw_oscillation"}


def check_yaw_damping(yaw_damping: str) -> None:
    """Raise ``ValueError`` unless ``yaw_damping`` is one of :data:`YAW_DAMPINGS` (the one check of the name)."""
    if yaw_damping == "waveform":
        raise ValueError(f"yaw_damping='waveform' was an experiment that left the package (kept at the git tag "
                         f"{WAVEFORM_TAG}); use one of {tuple(YAW_DAMPINGS)}")
    if yaw_damping not in YAW_DAMPINGS:
        raise ValueError(f"yaw_damping must be one of {tuple(YAW_DAMPINGS)}, got {yaw_damping!r}")


def load_scaling(scaling: str | os.PathLike = "identified", params: FishParams | None = None, check: bool = True,
                 yaw_damping: str = "sinusoid") -> ScalingFunctions:
    """Read a coefficients file (``"identified"``: the shipped one) for a model of ``params``.

    Args:
        scaling: ``"identified"`` or the path of a coefficients file.
        params: The parameters the model runs with (``None``: no check).
        check: Refuse a file identified for other parameters than ``params``.
        yaw_damping: Which yaw-damping section to keep (:data:`YAW_DAMPINGS`); the others are dropped.

    Raises:
        ValueError: A parameter mismatch, or a file without the section ``yaw_damping`` needs.
    """
    path = None if scaling == "identified" else os.fspath(scaling)
    k = ScalingFunctions.load_for(params, path, check=check and params is not None)
    where = "the shipped coefficients file" if path is None else f"coefficients file {path}"
    return select_yaw_damping(k, yaw_damping, where)


def select_yaw_damping(k: ScalingFunctions, yaw_damping: str, where: str = "the scaling functions") \
        -> ScalingFunctions:
    """``k`` with only the yaw-damping section ``yaw_damping`` needs (:data:`YAW_DAMPINGS`); ``k`` itself if no other.

    Raises:
        ValueError: If ``k`` lacks that section (``where`` names it in the message).
    """
    check_yaw_damping(yaw_damping)
    has = {"sinusoid": k.has_oscillation}
    if yaw_damping != "none" and not has[yaw_damping]:
        raise ValueError(f"{where} has no {YAW_DAMPINGS[yaw_damping]} section, which yaw_damping="
                         f"{yaw_damping!r} needs; pick yaw_damping from what it holds ("
                         f"{[name for name, held in has.items() if held] + ['none']})")
    drop: dict[str, Any] = {}
    if yaw_damping != "sinusoid" and k.has_oscillation:
        drop.update(oscillation_knots=(), oscillation_table=None)
    return dataclasses.replace(k, **drop) if drop else k


def held_yaw_damping(k: ScalingFunctions | None) -> str:
    """The richest yaw damping scaling functions hold (``"none"`` for ``None``, K = 1)."""
    if k is None:
        return "none"
    return "sinusoid" if k.has_oscillation else "none"
