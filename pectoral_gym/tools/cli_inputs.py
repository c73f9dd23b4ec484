"""What the ``pectoral-fish`` subcommands read from their arguments: fin patterns and the model spec.

Also the steady-state result as ``steady --json`` prints it (one JSON object, :func:`steady_result`).
"""

from __future__ import annotations

from typing import Any

from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.spec import PRESETS

__all__ = ["FIN_HELP", "MODEL_CHOICES", "fin_label", "fin_text", "fin_tuple", "format_number", "model_inputs",
           "parse_fin", "steady_result"]

#: ``--model`` values: the two models (their reference specs), then every preset of ``PRESETS``.
MODEL_CHOICES = ("full", "averaged", *PRESETS)
FIN_HELP = "fin pattern G0,GA,TP,ZETA: bias [deg], amplitude [deg], period [s], ratio [-]; omitted: fin at rest"


def parse_fin(text: str | None, option: str) -> FinBeat | None:
    """Parse ``"G0,GA,TP,ZETA"`` (degrees, degrees, seconds, ratio) into a :class:`FinBeat`.

    Args:
        text: The option value, or ``None`` for a fin at rest.
        option: Option name for the error message (``"--right"``).

    Returns:
        The pattern, or ``None`` if ``text`` is ``None``.

    Raises:
        ValueError: With a one-line reason, for a malformed or invalid pattern.
    """
    if text is None:
        return None
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 4:
        raise ValueError(f"{option} needs 4 comma-separated numbers G0,GA,TP,ZETA, got {text!r}")
    try:
        return FinBeat.from_degrees(*values)
    except ValueError as exc:
        raise ValueError(f"{option} {text}: {exc}") from None


def fin_tuple(beat: FinBeat | None) -> list[float] | None:
    """The paper's tuple ``[g0 deg, gA deg, Tp s, zeta]`` (rounded against float noise), or ``None`` at rest."""
    return None if beat is None else [round(v, 12) for v in beat.degrees()]


def fin_text(beat: FinBeat | None) -> str:
    """``(g0 deg, gA deg, Tp s, zeta)`` for printing, or ``at rest``."""
    if beat is None:
        return "at rest"
    g0, ga, tp, zeta = beat.degrees()
    return f"({g0:g} deg, {ga:g} deg, {tp:g} s, {zeta:g})"


def format_number(value: float | None, spec: str) -> str:
    """``value`` formatted with ``spec``, or ``-`` for ``None``."""
    return "-" if value is None else format(value, spec)


def fin_label(right: FinBeat | None, left: FinBeat | None) -> str:
    """Both fins for a title: ``right (...), left (...)``."""
    return f"right {fin_text(right)}, left {fin_text(left)}"


def model_inputs(model: str, params_file: str | None, scaling: str | None = None, check: bool = True):
    """``(params, spec)`` of the command line's ``--model, --params, --scaling, --no-params-check``.

    ``"full"`` is :data:`~pectoral_gym.model.spec.FULL_REFERENCE`, ``"averaged"`` is
    :data:`~pectoral_gym.model.spec.AVERAGED`, any other name a preset of
    :data:`~pectoral_gym.model.spec.PRESETS`; an averaged model's K (with its richest yaw damping) is the
    spec's unless given, its forcing always the spec's (Taylor for ``averaged-paper``).

    Args:
        model: ``"full"``, ``"averaged"`` or a preset name.
        params_file: A parameters file (:func:`pectoral_gym.model.params.load_params`) or ``None`` (Table 1).
        scaling: ``"identified"`` (the shipped file), ``"none"`` (K = 1), a coefficients file path, or
            ``None`` (the spec's).
        check: Refuse a coefficients file identified for other parameters (averaged model).

    Raises:
        ValueError: For an unknown model, an averaged-only option given to the full model, an unreadable
            file or (``check``) K identified for other parameters.
        FileNotFoundError: If a file does not exist.
    """
    from pectoral_gym.model.params import FishParams, load_params
    from pectoral_gym.model.spec import AVERAGED, FULL_REFERENCE, PRESETS, AveragedSpec, env_spec

    spec = {"full": FULL_REFERENCE, "averaged": AVERAGED}.get(model) or PRESETS.get(model)
    if spec is None:
        raise ValueError(f"unknown model {model!r}: choose from {MODEL_CHOICES}")
    params = load_params(params_file) if params_file else FishParams()
    if not isinstance(spec, AveragedSpec):
        if scaling is not None:
            raise ValueError(f"--scaling applies to averaged models only, not to {model!r}")
        return params, spec
    if scaling is not None:
        held = env_spec("averaged", scaling=scaling, check_scaling_params=check)
        spec = spec.replace(scaling=held.scaling, yaw_damping=held.yaw_damping)
    spec = spec.replace(check_params=check)
    spec.scaling_functions(params)  # the parameter check, before any work
    return params, spec


def steady_result(model: str, right: FinBeat | None, left: FinBeat | None, params: Any = None,
                  spec: Any = None) -> dict[str, Any]:
    """Periodic steady state as the JSON object printed by ``steady --json``.

    Args:
        model: ``"full"`` or ``"averaged"`` (the name in the result).
        right, left: Fin patterns (``None``: at rest).
        params: Model parameters (``None``: Table 1).
        spec: The model's spec (:func:`model_inputs`); ``None``: the preset ``model`` names.

    Returns:
        A dict with ``vx, vy`` [m/s], ``omega`` [rad/s] (body frame, x forward,
        y left, ``omega > 0`` a left turn), ``speed`` [m/s], ``radius`` [m] and
        ``period`` [s] (``None`` when the fish does not turn), ``drift_angle``
        [rad], ``converged``, ``model``, ``right``, ``left`` (``[g0 deg, gA deg,
        Tp s, zeta]`` or ``None`` at rest).
    """
    from pectoral_gym.model.steady import steady_state

    s = steady_state(spec or model, right=right, left=left, params=params)
    return {
        "vx": s.vx, "vy": s.vy, "omega": s.omega, "speed": s.speed, "radius": s.radius, "period": s.period,
        "drift_angle": s.drift_angle, "converged": s.converged, "model": model,
        "right": fin_tuple(right), "left": fin_tuple(left),
    }
