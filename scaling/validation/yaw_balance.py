"""Yaw balance of periodic steady states: where the averaged model's two-fin turning rate goes wrong.

``python -m pectoral_gym.scaling yaw-balance --from docs/validation/fidelity/fidelity_report.json`` takes the
two-fin steady-state patterns of a fidelity run (``python -m pectoral_gym.scaling fidelity``), drives the full
model to its periodic steady state, samples one window finely and splits the mean of the yaw row of
eq. (19)-(20) into its terms, each next to the averaged model's version of it at the same mean state:

===============  =============================================  ==========================================
term [rad/s^2]   full model (mean over the window)              averaged model (docs/model.md 3.4, 3.6)
===============  =============================================  ==========================================
``moment``       ``mean(tau) / J3`` (exact: K = 1 averages)     ``(K_m(R) taubar_R + K_m(L) taubar_L) / J3``
``munk``         ``(m1 - m2) / J3 mean(vx vy)``                 ``(m1 - m2) / J3 mean(vx) mean(vy)``
``damping``      ``c4 mean(omega |omega|)``                     ``c4 q(mean omega, A)``, ``A`` from the
                                                                phasors (relative phase averaged when
                                                                the periods differ)
===============  =============================================  ==========================================

At a periodic steady state the full model's terms balance (``moment + munk - damping = 0``, the
mean of ``d omega / dt`` over a period: a check, ``balance``). The averaged model's terms at the full
model's mean state give ``residual``: its yaw acceleration there, zero for a model that turns at the
full model's rate. ``--single`` adds each pattern's right fin beating alone, where K was identified.

Reading (docs/scaling.md, "Two fins"): ``K_m`` makes up, per fin, for the damping of the real,
skewed in-beat yaw-rate waveform that the sinusoid of section 3.6 misses; with two fins those
per-fin corrections do not add up.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

import numpy as np

from pectoral_gym.model.averaging import EXACT, averaged_fin_forcing
from pectoral_gym.model.dynamics import oscillating_square_mean
from pectoral_gym.model.kfunctions import ScalingFunctions, default_scaling_path
from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FishParams, body_coefficients, coefficient_vector

__all__ = ["TERMS", "add_parser", "main", "parse_pattern", "yaw_balance"]

TERMS = ("moment", "munk", "damping")
_PHASES = 64  # relative beat phases averaged over when the fins' periods differ
_PATTERN = re.compile(r"R\(([^)]*)\)\s*L\(([^)]*)\)")


def parse_pattern(label: str) -> np.ndarray:
    """``(2, 4)`` patterns (rad, rad, s, -) from a fidelity label ``R(b, a, T, z) L(b, a, T, z)`` (degrees)."""
    match = _PATTERN.fullmatch(label.strip())
    if match is None:
        raise ValueError(f"not a pattern label 'R(bias, amplitude, period, ratio) L(...)': {label!r}")
    fins = []
    for group in match.groups():
        values = [float(v) for v in group.split(",")]
        if len(values) != 4:
            raise ValueError(f"each fin needs 4 numbers (bias, amplitude, period, ratio): {label!r}")
        fins.append([math.radians(values[0]), math.radians(values[1]), values[2], values[3]])
    return np.array(fins)


def _model_damping(omega: float, right: np.ndarray, left: np.ndarray, scaling: ScalingFunctions, c4: float) -> float:
    """The averaged model's yaw damping at mean yaw rate ``omega`` (docs/model.md 3.6)."""
    if right[1] > 0 and left[1] > 0 and right[2] != left[2]:
        shifts = np.linspace(0.0, 2.0 * np.pi, _PHASES, endpoint=False)
    else:  # one fin, or equal periods started together: a fixed relative phase of 0
        shifts = np.zeros(1)
    phasors = []
    for beat, side in ((right, 1.0), (left, -1.0)):
        amplitude, phase = scaling.yaw_oscillation(*beat) if beat[1] > 0 else (0.0, 0.0)
        phasors.append(side * amplitude * np.exp(1j * phase))
    amplitudes = np.abs(phasors[0] + phasors[1] * np.exp(1j * shifts))
    return c4 * float(np.mean([oscillating_square_mean(omega, a) for a in amplitudes]))


def yaw_balance(beats: np.ndarray, scaling: ScalingFunctions, params: FishParams | None = None,
                settle: float = 240.0, window: float = 32.0, dt: float = 0.002) -> dict[str, np.ndarray]:
    """The yaw-row terms of ``n`` fish driven by ``beats (n, 2, 4)`` (module docstring).

    Args:
        beats: Right and left fin patterns per fish (rad, rad, s, -).
        scaling: The averaged model's scaling functions.
        params: Model parameters (default: Table 1).
        settle: Time [s] the full model runs before sampling (to its periodic steady state).
        window: Sampled time [s]; a multiple of both periods keeps the means exact.
        dt: Sampling step [s].

    Returns:
        ``full_<term>`` and ``model_<term>`` for each of :data:`TERMS`, ``balance``, ``residual`` and
        ``omega`` (the full model's mean yaw rate), arrays of ``n``.
    """
    params = params or FishParams()
    beats = np.asarray(beats, dtype=np.float64)
    m1, m2, j3, _, _, c4 = body_coefficients(params)
    coef = coefficient_vector(params)
    model = FullModel(beats.shape[0], params)
    model.reset(right=beats[:, 0], left=beats[:, 1])
    model.advance(settle)
    samples = []
    for _ in range(max(1, round(window / dt))):
        model.advance(dt)
        samples.append(model.state[:, 3:6].copy())
    vx, vy, omega = np.moveaxis(np.array(samples), 2, 0)  # each (t, n)
    unit, tables = ScalingFunctions.unit().kernel_arrays(), scaling.kernel_arrays()

    def moment(i: int, k_tables) -> float:
        return sum(averaged_fin_forcing(*beats[i, f], side, coef, EXACT, k_tables)[2]
                   for f, side in ((0, 1.0), (1, -1.0)) if beats[i, f, 1] > 0) / j3

    n = beats.shape[0]
    out = {"omega": omega.mean(axis=0),
           "full_moment": np.array([moment(i, unit) for i in range(n)]),
           "full_munk": (m1 - m2) / j3 * np.mean(vx * vy, axis=0),
           "full_damping": c4 * np.mean(omega * np.abs(omega), axis=0),
           "model_moment": np.array([moment(i, tables) for i in range(n)]),
           "model_munk": (m1 - m2) / j3 * vx.mean(axis=0) * vy.mean(axis=0)}
    out["model_damping"] = np.array([_model_damping(out["omega"][i], beats[i, 0], beats[i, 1], scaling, c4)
                                     for i in range(n)])
    out["balance"] = out["full_moment"] + out["full_munk"] - out["full_damping"]
    out["residual"] = out["model_moment"] + out["model_munk"] - out["model_damping"]
    return out


def _table(labels: list[str], res: dict[str, np.ndarray]) -> list[str]:
    lines = ["| pattern | omega [rad/s] | moment full / model | munk full / model | damping full / model "
             "| residual | balance |", "|---|---|---|---|---|---|---|"]
    for i, name in enumerate(labels):
        cells = [f"{res[f'full_{t}'][i]:.4f} / {res[f'model_{t}'][i]:.4f}" for t in TERMS]
        lines.append(f"| {name} | {res['omega'][i]:.4f} | " + " | ".join(cells)
                     + f" | {res['residual'][i]:+.4f} | {res['balance'][i]:.1e} |")
    return lines


def add_parser(sub) -> None:
    """The ``yaw-balance`` subcommand of ``pectoral-scaling``."""
    from pectoral_gym.tools.cli_common import examples

    example = "docs/validation/fidelity/fidelity_report.json"
    p = sub.add_parser("yaw-balance", help="split two-fin steady states' yaw balance into terms, full vs averaged",
                       description=__doc__.split("\n\n")[0],
                       epilog=examples(f"pectoral-scaling yaw-balance --from {example}",
                                       f"pectoral-scaling yaw-balance --from {example} --single --out yaw.md"))
    p.add_argument("--from", dest="source", required=True,
                   help="a fidelity JSON (pectoral-scaling fidelity): its two-fin steady-state patterns")
    p.add_argument("--coefficients", default=None, help="coefficients file (default: the shipped one)")
    p.add_argument("--single", action="store_true", help="also each pattern's right fin alone")
    p.add_argument("--out", default=None, help="write the markdown table (and a JSON next to it) here")
    p.add_argument("--settle", type=float, default=240.0, help="seconds before sampling (default 240)")
    p.add_argument("--window", type=float, default=32.0, help="sampled seconds (default 32)")


def main(args: argparse.Namespace) -> int:
    """Run ``python -m pectoral_gym.scaling yaw-balance``; prints the markdown table."""
    try:
        rows = json.loads(Path(args.source).read_text())["steady"]["rows"]
        labels = [row["pattern"] for row in rows]
        beats = np.array([parse_pattern(label) for label in labels])
        scaling = ScalingFunctions.load(args.coefficients or default_scaling_path())
    except (OSError, KeyError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.single:
        alone = beats.copy()
        alone[:, 1] = [math.pi / 2, 0.0, 1.0, 1.0]  # left fin at rest
        beats = np.concatenate([beats, alone])
        labels = labels + [label.split(" L(")[0] + " alone" for label in labels]
    res = yaw_balance(beats, scaling, settle=args.settle, window=args.window)
    lines = _table(labels, res)
    text = "\n".join(lines)
    print(text)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        command = (f"python -m pectoral_gym.scaling yaw-balance --from {args.source}"
                   + (" --single" if args.single else "")
                   + (f" --coefficients {args.coefficients}" if args.coefficients else "") + f" --out {args.out}")
        out.write_text(f"# Yaw balance of two-fin steady states\n\n`{command}`\n\n{text}\n")
        out.with_suffix(".json").write_text(json.dumps(
            {"patterns": labels, **{k: v.tolist() for k, v in res.items()}}, indent=1) + "\n")
    return 0
