"""Physical plausibility of a robot's description: bounds on every :class:`FishParams` field and on its K.

:class:`FishParams` itself checks only what the equations need (finite, positive, ``m1, m2, J3 > 0``): a
simulation may study any fish. A description that drives a **robot** (``pectoral-deploy --params``,
``--emulate-params``, ``--scaling``) must describe a robot that can exist, because the geofence's stopping
distance and the fish's outline come from it. :func:`params_problems` lists every field outside the bounds
below and :func:`k_problems` every implausible K; the argument for each bound is in
``docs/calibration.md``, "Plausibility bounds". Each bound is a physical limit or at least an order of
magnitude away from Table 1's robot, so a calibrated robot (fitted within a factor 3 of Table 1,
``scaling.calibration.fit``) always passes, and only a description no robot can have fails.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from pectoral_gym.model.params import FishParams
from pectoral_gym.model.tank import TANK_WIDTH

__all__ = ["K_BOUNDS", "check_k", "check_params", "k_problems", "params_problems"]

_TABLE1 = FishParams()


def _ratios(p: FishParams) -> dict[str, tuple[float, float, float, str]]:
    """Each dimensionless group: ``(value, low, high, what)`` (``docs/calibration.md``, "Plausibility bounds")."""
    box = p.water_density * p.body_length * (2.0 * p.fin_offset) * p.body_height  # mass of water in the body's box
    table_cm = _TABLE1.moment_coef / (_TABLE1.water_density * _TABLE1.body_length ** 5)
    table_lambda = _TABLE1.fin_force_coef
    return {
        "water_density": (p.water_density, 990.0, 1030.0, "water's density, fresh to sea water, 0-40 C [kg/m^3]"),
        "body_length": (p.body_length, 0.05, TANK_WIDTH / 2, "body length [m] (a fish that turns in the tank)"),
        "fill": (p.body_mass / box, 0.3, 1.5, "body_mass / (water density x body_length x 2 fin_offset x "
                                                "body_height): a neutrally buoyant fish displaces its mass of water"),
        "gyration": (math.sqrt(p.body_inertia / p.body_mass) / p.body_length, 0.04, 0.5,
                     "radius of gyration sqrt(body_inertia / body_mass) / body_length"),
        "added_x": (-p.added_mass_x / p.body_mass, 0.0, 1.0, "-added_mass_x / body_mass (a sphere: 0.5)"),
        "added_y": (-p.added_mass_y / p.body_mass, 0.0, 2.0, "-added_mass_y / body_mass (a circular cylinder: 1)"),
        "added_j": (-p.added_inertia / p.body_inertia, 0.0, 2.0, "-added_inertia / body_inertia"),
        "wetted": (p.wetted_area / (2 * (p.body_length * 2 * p.fin_offset + p.body_length * p.body_height
                                         + 2 * p.fin_offset * p.body_height)), 0.2, 1.2,
                   "wetted_area / the surface of the body's box"),
        "drag_coef": (p.drag_coef, 0.004, 3.0, "drag coefficient on the wetted area"),
        "lift_coef": (p.lift_coef, 0.0, 2 * math.pi, "lift slope [1/rad] (thin-airfoil theory: 2 pi)"),
        "moment_coef": (p.moment_coef / (p.water_density * p.body_length ** 5) / table_cm, 1 / 30, 30.0,
                        "moment_coef / (water density x body_length^5), against Table 1's"),
        "fin_force_coef": (p.fin_force_coef / table_lambda, 0.1, 3.0, "fin_force_coef against Table 1's"),
        "fin_span": (p.fin_span / p.body_length, 0.1, 1.0, "fin_span / body_length"),
        "fin_chord": (p.fin_chord / p.body_length, 0.05, 0.5, "fin_chord / body_length"),
        "fin_offset": (p.fin_offset / p.body_length, 0.05, 0.5, "fin_offset / body_length"),
        "fin_mass": (p.fin_mass / p.body_mass, 0.0, 0.25, "fin_mass / body_mass"),
        "fin_effective_mass": (p.fin_effective_mass / p.body_mass, 0.0, 0.25, "fin_effective_mass / body_mass"),
        "body_height": (p.body_height / p.body_length, 0.1, 1.0, "body_height / body_length"),
        **{f"fin_force_{side}": (p.fin_force_coef * getattr(p, f"fin_force_scale_{side}") / table_lambda, 0.1, 3.0,
                                 f"fin_force_coef x fin_force_scale_{side} against Table 1's fin_force_coef")
           for side in ("right", "left")},
        **{f"fin_angle_offset_{side}": (getattr(p, f"fin_angle_offset_{side}"), -0.35, 0.35,
                                        f"fin_angle_offset_{side} [rad] (a horn set 20 deg off is a mounting error)")
           for side in ("right", "left")},
        **{f"fin_angle_scale_{side}": (getattr(p, f"fin_angle_scale_{side}"), 0.5, 1.5,
                                       f"fin_angle_scale_{side} (a servo turning its fin 1.5 times the command)")
           for side in ("right", "left")},
    }


def params_problems(params: FishParams) -> list[str]:
    """Every bound ``params`` breaks, as ``"what = value, outside [low, high]"`` (empty: plausible)."""
    out = []
    for value, low, high, what in _ratios(params).values():
        if not low <= value <= high:
            out.append(f"{what} = {value:.4g}, outside [{low:.4g}, {high:.4g}]")
    return out


def check_params(params: FishParams, where: str = "params") -> None:
    """``ValueError`` (one line, the first broken bound and how many) unless ``params`` is a plausible robot."""
    problems = params_problems(params)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ValueError(f"{where}: not a plausible robot: {problems[0]}{more} (docs/calibration.md, "
                         "\"Plausibility bounds\")")


#: K's bounds over the action envelope: ``K_fx`` and ``K_m`` correct the averaged model's thrust and moment
#: towards the full model's of the same fish: both models share the same forces, so the correction keeps their
#: sign and stays within a factor 10 (the shipped K: 0.62-1.24 and 0.27-1.09 over the env's envelope); ``K_fy``
#: corrects a sway force that is itself a small residual and may change sign (shipped: -0.87 to 0.71): |K_fy| <= 3.
K_BOUNDS = {"K_fx": (0.1, 10.0), "K_fy": (-3.0, 3.0), "K_m": (0.1, 10.0)}


def k_problems(k: Any, ranges: tuple[tuple[float, float], ...], points: int = 5, spline: bool = True) -> list[str]:
    """Why the K ``k`` (a ``ScalingFunctions``) cannot be a robot's (empty: plausible).

    ``k`` is evaluated over ``ranges`` (bias, amplitude, period, ratio) sampled on a ``points``-per-axis grid. With
    ``spline``, a robot's K comes from ``pectoral-scaling identify``, which always writes the spline section: a file
    without it (the bare polynomial of the paper) is not an identified robot's.
    """
    from pectoral_gym.model.kfunctions import K_NAMES

    out = []
    if spline and not k.has_spline:
        out.append("no spline section (pectoral-scaling identify writes one)")
    grid = [np.linspace(lo, hi, points) for lo, hi in ranges]
    values = np.array([k.evaluate(*map(float, beat)) for beat in itertools.product(*grid)])
    for i, name in enumerate(K_NAMES):
        low, high = K_BOUNDS[name]
        column = values[:, i]
        if not np.all(np.isfinite(column)):
            out.append(f"{name} is not finite over the action envelope")
        elif column.min() < low or column.max() > high:
            out.append(f"{name} spans [{column.min():.4g}, {column.max():.4g}] over the action envelope, outside "
                       f"[{low:g}, {high:g}]")
    return out


def check_k(k: Any, ranges: tuple[tuple[float, float], ...], where: str = "K", spline: bool = True) -> None:
    """``ValueError`` (one line) unless the K ``k`` is plausible over ``ranges`` (:func:`k_problems`)."""
    problems = k_problems(k, ranges, spline=spline)
    if problems:
        raise ValueError(f"{where}: not a plausible robot's K: {'; '.join(problems)} (docs/calibration.md, "
                         "\"Plausibility bounds\")")
