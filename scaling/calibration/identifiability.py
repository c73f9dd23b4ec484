"""What the logs determine: standard errors and the parameter combinations they cannot tell apart.

From the logs' information about the log-parameters with the windows' starting states eliminated
(:mod:`~pectoral_gym.scaling.calibration.covariance`: the window-clustered sandwich, robust to residuals that
are correlated from frame to frame, or Gauss-Newton's ``S / s^2`` for independent ones). Its eigenvectors are
the parameter combinations the logs fix, each to ``1 / sqrt(eigenvalue)``; a combination known worse than the
field's ``identified_se`` is left to the prior (the regularisation of :mod:`~pectoral_gym.scaling.calibration.fit`).
The posterior covariance adds the prior's information ``I / prior_sigma^2``.

Some fields can never be told apart, whatever the logs, because the model sees only a product of them
(eq. 20 and eqs. 11, 13 of the paper): :data:`STRUCTURAL` says which.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.model.params import FishParams

__all__ = ["ADDITIVE_FIELDS", "ASYMMETRY_FIELDS", "COEFFICIENT", "COMBINATIONS", "STRUCTURAL", "UNCERTAIN_FIELDS",
           "Direction", "Identifiability", "analyse", "combinations", "common_scale", "field_unit"]

#: The FishParams fields a ruler cannot measure: what the calibration fits by default.
UNCERTAIN_FIELDS = ("added_mass_x", "added_mass_y", "added_inertia", "drag_coef", "lift_coef", "moment_coef",
                    "fin_force_coef")
#: The packed coefficient each uncertain field enters, eq. (20) and eqs. (11), (13).
COEFFICIENT = {
    "added_mass_x": "m1 = body_mass - added_mass_x",
    "added_mass_y": "m2 = body_mass - added_mass_y",
    "added_inertia": "J3 = body_inertia - added_inertia",
    "body_inertia": "J3 = body_inertia - added_inertia",
    "drag_coef": "c1 = rho wetted_area drag_coef / 2",
    "lift_coef": "c2 = rho wetted_area lift_coef / 2",
    "moment_coef": "c4 = moment_coef / J3",
    "fin_force_coef": "k = fin_force_coef rho fin_chord fin_span^3 / 6",
    "fin_force_scale_left": "k_left = fin_force_scale_left k: the left fin's force over the right one's",
    "fin_force_scale_right": "k_right = fin_force_scale_right k",
    "fin_angle_offset_right": "the right fin's actual angle = fin_angle_offset_right + commanded",
    "fin_angle_offset_left": "the left fin's actual angle = fin_angle_offset_left + commanded",
}
#: The asymmetry of a fish whose fins differ, as the calibration fits it (``--asymmetric``): the left fin's force
#: relative to the right one's (``fin_force_coef`` carries the right fin's, so this is the ratio of the two) and
#: each fin's servo offset. The servo scales are left out (name them in ``--fields`` to fit them): the logs fix
#: them, but a scale moves the forces much as the force factor does, so fitting both widens the force ratio's
#: standard error about tenfold (``docs/calibration.md``, "Fins that differ").
ASYMMETRY_FIELDS = ("fin_force_scale_left", "fin_angle_offset_right", "fin_angle_offset_left")
#: Fields fitted as ``prior + theta`` [rad] instead of ``prior x exp(theta)``: an offset may be zero or change sign,
#: so its standard error is absolute (rad), where the others' are relative.
ADDITIVE_FIELDS = ("fin_angle_offset_right", "fin_angle_offset_left")


def field_unit(name: str) -> str:
    """How a fitted field's standard error reads: ``"rad"`` (absolute, :data:`ADDITIVE_FIELDS`) or ``"relative"``."""
    return "rad" if name in ADDITIVE_FIELDS else "relative"

#: Fields the model sees only together: the logs can never separate them (one is fixed to its known value).
STRUCTURAL = (
    ("body_inertia", "added_inertia", "enter only as J3 = body_inertia - added_inertia (eq. 20)"),
    ("wetted_area", "drag_coef", "enter only as c1 = rho wetted_area drag_coef / 2 (and lift_coef as c2) (eq. 20)"),
    ("fin_force_coef", "fin_chord", "enter only as k = fin_force_coef rho fin_chord fin_span^3 / 6 (eqs. 11, 13)"),
    ("fin_force_scale_right", "fin_force_scale_left", "with fin_force_coef set the two fins' k only as "
     "fin_force_coef x fin_force_scale_right and fin_force_coef x fin_force_scale_left (three fields, two forces)"),
)


#: The force-to-inertia ratios the motion depends on (eq. 19 divided through): what the logs fix even when the
#: common scale of masses and force coefficients is left open. Name -> (formula, unit).
COMBINATIONS = {
    "c1/m1": ("surge drag per surge mass, eq. (19)", "1/m"),
    "c2/m2": ("lift per sway mass, eq. (19)", "1/(m rad)"),
    "c4": ("yaw damping C_M / J3, eq. (20)", "-"),
    "k/m1": ("fin force constant per surge mass, eqs. (13), (19)", "m"),
    "k C_p/J3": ("fin yaw moment constant per yaw inertia, eqs. (16), (19)", "m^2/(kg m^2) kg"),
    "m2/m1": ("sway to surge mass", "-"),
    "(m1-m2)/J3": ("Munk moment per yaw inertia, eq. (19)", "1/m^2"),
}


def combinations(p: FishParams) -> dict[str, float]:
    """The values of :data:`COMBINATIONS` for parameters ``p``."""
    k = p.fin_drag_constant
    return {"c1/m1": p.c1 / p.m1, "c2/m2": p.c2 / p.m2, "c4": p.c4, "k/m1": k / p.m1,
            "k C_p/J3": k * p.fin_offset / p.J3, "m2/m1": p.m2 / p.m1, "(m1-m2)/J3": (p.m1 - p.m2) / p.J3}


def _coefficient_gain(name: str, prior: FishParams) -> float:
    """``d log(coefficient) / d log|field|`` at the prior: 1 for a factor, ``|field| / m`` for an added mass."""
    if name == "added_mass_x":
        return -prior.added_mass_x / prior.m1
    if name == "added_mass_y":
        return -prior.added_mass_y / prior.m2
    if name == "added_inertia":
        return -prior.added_inertia / prior.J3
    if name == "body_inertia":
        return prior.body_inertia / prior.J3
    return 1.0


def _ratio_why(name: str, p: FishParams) -> str:
    """Why the logs fix the ratio ``name`` of :data:`COMBINATIONS` poorly, for the report."""
    if name == "(m1-m2)/J3" and abs(p.m1 - p.m2) < 0.25 * max(p.m1, p.m2):
        return (f"m1 - m2 = {p.m1 - p.m2:+.3f} kg is a difference of nearly equal masses (m1 = {p.m1:.3f} kg, "
                f"m2 = {p.m2:.3f} kg), so its relative error is {max(p.m1, p.m2) / abs(p.m1 - p.m2):.0f} times theirs")
    if name == "c2/m2":
        return "lift acts through the sideslip angle, which the camera's heading noise hides"
    return "the identification commands excite it too little for the camera to see"


@dataclass
class Direction:
    """One combination of log-parameters (an eigenvector of the information).

    Attributes:
        weights: Field name -> weight of its log (unit vector).
        data_se: How well the logs alone fix it: standard error of the combination [-, relative].
        identified: Whether ``data_se`` is within the fields' ``identified_se``.
        common_scale: Whether it moves every coefficient of eq. (20) and the fin's ``k`` together.
    """

    weights: dict[str, float]
    data_se: float
    identified: bool
    common_scale: bool

    def formula(self, top: int = 4) -> str:
        """``+0.71 log drag_coef - 0.70 log added_mass_x`` (the largest weights; an offset enters as itself, in rad)."""
        items = sorted(self.weights.items(), key=lambda kv: -abs(kv[1]))[:top]
        return " ".join(f"{'+' if w >= 0 else '-'}{abs(w):.2f} {'' if n in ADDITIVE_FIELDS else 'log '}{n}"
                        for n, w in items if abs(w) >= 0.05)


@dataclass
class Identifiability:
    """Standard errors and what the logs leave open.

    Attributes:
        std_error: Field -> posterior relative standard error (logs and prior).
        data_std_error: Field -> relative standard error from the logs alone (``inf``: not determined).
        identified: Field -> whether the logs alone fix it to ``identified_se``.
        directions: The combinations, best determined first.
        combination_se: :data:`COMBINATIONS` name -> relative standard error from the logs alone.
        variance: The residual's variance ``s^2`` (1 when the noise estimate is right).
        statements: Plain sentences for the report.
        covariance: How the standard errors were estimated (:mod:`~pectoral_gym.scaling.calibration.covariance`):
            ``"larger of window-sandwich and gauss-newton"`` (each standard error the larger of the two) or
            ``"gauss-newton"`` (too few windows for the sandwich).
        gauss_newton: For comparison, the Gauss-Newton standard errors alone (``std_error``, ``data_std_error``,
            ``combination_se``) when the sandwich took part; empty otherwise.
    """

    std_error: dict[str, float]
    data_std_error: dict[str, float]
    identified: dict[str, bool]
    directions: list[Direction]
    combination_se: dict[str, float]
    variance: float
    statements: list[str]
    covariance: str = "gauss-newton"
    gauss_newton: dict[str, dict[str, float]] = field(default_factory=dict)


#: The field that carries each coefficient of the common scale (eq. 20, eqs. 11, 13), first choice first.
_SCALE_CARRIERS = (("added_mass_x",), ("added_mass_y",), ("added_inertia", "body_inertia"), ("drag_coef",),
                   ("lift_coef",), ("moment_coef",), ("fin_force_coef", "fin_chord"))


def common_scale(fields: tuple[str, ...], params: FishParams) -> np.ndarray | None:
    """The unit move of the log-parameters that multiplies ``m1, m2, J3, c1, c2, C_M`` and ``k`` by one factor.

    ``None`` unless ``fields`` carry all seven: then the logs can fix the scale in principle.
    """
    move = np.zeros(len(fields))
    for carriers in _SCALE_CARRIERS:
        name = next((n for n in carriers if n in fields), None)
        if name is None:
            return None
        move[fields.index(name)] = 1.0 / _coefficient_gain(name, params)
    return move / np.linalg.norm(move)


def _standard_errors(info: np.ndarray, prior_sigma: float, grads: np.ndarray,
                     scale: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """Posterior and data-alone standard errors of the log-parameters, and of the combinations of gradient ``grads``.

    ``scale``: the common scale (:func:`common_scale`), whose information from the logs is discarded for the fields
    (eq. 19 divided through does not depend on it, so what the logs seem to say about it is model error: on
    robot-stack logs they claimed it to a fraction of a per cent while missing it by several) and which the ratios
    do not depend on.
    """
    p = len(info)
    eigval, eigvec = np.linalg.eigh(info)
    eigval = np.maximum(eigval, 1e-300)
    order = np.argsort(eigval)[::-1]
    eigval, eigvec = eigval[order], eigvec[:, order]
    combo_se = np.sqrt(np.sum((grads @ eigvec) ** 2 / eigval, axis=1))
    if scale is not None:
        keep = np.eye(p) - np.outer(scale, scale)
        info = keep @ info @ keep
        eigval, eigvec = np.linalg.eigh(0.5 * (info + info.T))
        eigval = np.maximum(eigval, 1e-300)
        order = np.argsort(eigval)[::-1]
        eigval, eigvec = eigval[order], eigvec[:, order]
    if scale is None:
        data_se = np.sqrt(np.sum(eigvec**2 / eigval, axis=1))
    else:
        # The scale is exactly unfixed: a field that moves it is unfixed too; one that does not (a fin's force ratio,
        # an offset) is fixed in the rest, whose inverse is the pseudo-inverse. (The eigen-sum above would mix the
        # scale's near-zero eigenvalue into every field through rounding-sized eigenvector components.)
        cov = np.linalg.pinv(0.5 * (info + info.T), rcond=1e-12, hermitian=True)
        data_se = np.where(np.abs(scale) > 1e-9, np.inf, np.sqrt(np.maximum(np.diag(cov), 0.0)))
    posterior = np.sqrt(np.diag(np.linalg.inv(info + np.eye(p) / prior_sigma**2)))
    return posterior, data_se, combo_se, eigval, eigvec


def analyse(info: np.ndarray, variance: float, fields: tuple[str, ...], prior: FishParams,
            prior_sigma: float, identified_se: float, theta: np.ndarray,
            params_of: Callable[[np.ndarray], FishParams],
            sandwich_info: np.ndarray | None = None) -> Identifiability:
    """Standard errors and identifiability of the fitted log-parameters (module docstring).

    Each standard error is the larger of the Gauss-Newton one and, where given, the window sandwich's: the sandwich
    holds when the model misses the camera by an error lasting many frames, Gauss-Newton when the residuals are
    independent, where the sandwich's own sampling error (about ``sqrt(1 / (2 G))`` relative for ``G`` windows)
    makes it come out too small about half the time.

    Args:
        info: ``(p, p)`` the logs' information about the log-parameters for independent residuals, starting states
            eliminated (:func:`~pectoral_gym.scaling.calibration.covariance.gauss_newton_information`).
        sandwich_info: The same from the window-clustered sandwich
            (:func:`~pectoral_gym.scaling.calibration.covariance.window_sandwich_information`), or ``None``.
        variance: The residual's variance ``s^2`` (reported).
        fields: Their names.
        prior: The prior parameters (for the coefficient gains of the added masses).
        prior_sigma: The prior's standard deviation of each log-parameter.
        identified_se: Relative standard error below which the logs identify a field or combination.
        theta: The fitted log-parameters.
        params_of: The parameters of log-parameters (for the :data:`COMBINATIONS`' gradients).
    """
    p = len(fields)
    base = {n: math.log(abs(v)) for n, v in combinations(params_of(theta)).items()}
    grads = np.zeros((len(base), p))
    for i in range(p):
        moved = combinations(params_of(theta + 1e-6 * np.eye(p)[i]))
        grads[:, i] = [(math.log(abs(moved[n])) - base[n]) / 1e-6 for n in base]
    scale = common_scale(fields, params_of(theta))
    posterior, data_se, combo_se, eigval, eigvec = _standard_errors(info, prior_sigma, grads, scale)
    gauss_newton: dict[str, dict[str, float]] = {}
    covariance = "gauss-newton"
    if sandwich_info is not None:
        gauss_newton = {"std_error": dict(zip(fields, posterior.tolist(), strict=True)),
                        "data_std_error": dict(zip(fields, data_se.tolist(), strict=True)),
                        "combination_se": dict(zip(base, combo_se.tolist(), strict=True))}
        robust = _standard_errors(sandwich_info, prior_sigma, grads, scale)
        posterior, data_se, combo_se = (np.maximum(a, b) for a, b in zip((posterior, data_se, combo_se), robust[:3],
                                                                          strict=True))
        # the directions: of the sandwich's information where its variance is the larger, else of Gauss-Newton's
        if np.sum(1.0 / robust[3]) > np.sum(1.0 / eigval):
            eigval, eigvec = robust[3], robust[4]
        covariance = "larger of window-sandwich and gauss-newton"
    gains = np.array([_coefficient_gain(n, prior) for n in fields])
    directions = []
    for k in range(p):
        v = eigvec[:, k] * (1.0 if eigvec[np.argmax(np.abs(eigvec[:, k])), k] >= 0 else -1.0)
        se = 1.0 / math.sqrt(eigval[k])
        coef = v * gains  # the same move in the coefficients' logs
        scale = bool(np.linalg.norm(coef) > 0 and abs(coef.sum()) / (np.linalg.norm(coef) * math.sqrt(p)) > 0.8)
        directions.append(Direction({n: float(w) for n, w in zip(fields, v, strict=True)}, se,
                                    se <= identified_se, scale))
    identified = {n: bool(s <= identified_se) for n, s in zip(fields, data_se, strict=True)}
    statements = []
    for d in directions:
        if d.identified:
            continue
        why = ("it moves every coefficient the fitted fields enter (" +
               ", ".join(sorted({COEFFICIENT[n].split(' =')[0] for n in fields
                                 if any(n in carriers for carriers in _SCALE_CARRIERS)})) +
               ") by the same factor: the motion depends on forces divided by masses, so the logs fix the "
               "ratios and not the common scale; only the fins' own inertia (m_p S_p / 2, eq. 15, known) breaks "
               "the tie, too weakly to see" if d.common_scale else
               "the identification commands excite it too little for the camera to see")
        statements.append(f"The logs cannot fix the combination {d.formula()} (to +-{100 * min(d.data_se, 9.99):.0f} "
                          f"% from the logs alone): {why}. It is held at the prior (Table 1 or the known values, "
                          f"+-{100 * prior_sigma:.0f} % in each log) by the regularisation.")
    for n in fields:
        if not identified[n]:
            se = min(data_se[fields.index(n)], 9.99)
            shown = f"{math.degrees(se):.1f} deg" if n in ADDITIVE_FIELDS else f"{100 * se:.1f} %"
            statements.append(f"{n} ({COEFFICIENT.get(n, n)}) is not identified: +-{shown} "
                              "from the logs alone; its value leans on the prior.")
    fitted = params_of(theta)
    for (name, (meaning, _)), se in zip(COMBINATIONS.items(), combo_se, strict=True):
        if se > identified_se:
            statements.append(f"The ratio {name} ({meaning}) is fixed only to +-{100 * min(se, 9.99):.1f} % by the "
                              f"logs: {_ratio_why(name, fitted)}.")
    for a, b, why in STRUCTURAL:
        if a in fields and b in fields:
            statements.append(f"{a} and {b} {why}: fit one of them and give the other as known.")
    return Identifiability(
        {n: float(posterior[i]) for i, n in enumerate(fields)},
        {n: float(s) for n, s in zip(fields, data_se, strict=True)},
        identified, directions, {n: float(v) for n, v in zip(base, combo_se, strict=True)}, float(variance),
        statements, covariance, gauss_newton)
