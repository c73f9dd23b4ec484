"""The calibration's report: JSON, Markdown and a plot of measured against simulated paths.

matplotlib is imported inside :func:`plot_paths` only: the model library and the fit never import it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.calibration.fit import Calibration
from pectoral_gym.scaling.calibration.heldout import HeldOutRun
from pectoral_gym.scaling.calibration.identifiability import COMBINATIONS, combinations, field_unit
from pectoral_gym.scaling.calibration.replay import simulate

__all__ = ["markdown", "not_converged_text", "plot_paths", "report_dict"]


def _held_out_summary(runs: list[HeldOutRun]) -> dict[str, Any]:
    errors = [r.error_percent for r in runs]
    return {"episodes": len(runs), "median_error_percent": float(np.median(errors)) if errors else None,
            "max_error_percent": float(np.max(errors)) if errors else None,
            "runs": [{"log": r.log, "episode": r.episode, "duration_s": r.duration, "path_m": r.path,
                      "end_error_m": r.end_error, "error_percent": r.error_percent} for r in runs]}


def report_dict(cal: Calibration, held_out: list[HeldOutRun] | None = None,
                prior_held_out: list[HeldOutRun] | None = None, truth: FishParams | None = None) -> dict[str, Any]:
    """Everything the calibration found, as plain values (``report.json``).

    Args:
        cal: The calibration.
        held_out: The calibrated model's held-out runs; ``prior_held_out``: the prior's, for comparison.
        truth: The true parameters when known (synthetic logs): adds the errors.
    """
    ident = cal.identifiability
    fields = {}
    for name in cal.fields:
        unit = field_unit(name)  # an offset's standard error and error are in rad, the others' relative
        entry = {"value": getattr(cal.params, name), "prior": getattr(cal.prior, name),
                 f"std_error_{unit}": ident.std_error[name], f"data_std_error_{unit}": ident.data_std_error[name],
                 "identified": ident.identified[name]}
        if truth is not None:
            entry["truth"] = getattr(truth, name)
            entry[f"error_{unit}"] = (getattr(cal.params, name) - getattr(truth, name) if unit == "rad"
                                      else getattr(cal.params, name) / getattr(truth, name) - 1.0)
        fields[name] = entry
    combos = {}
    fitted, true = combinations(cal.params), combinations(truth) if truth is not None else None
    for name, (meaning, unit) in COMBINATIONS.items():
        entry = {"meaning": meaning, "unit": unit, "value": fitted[name],
                 "data_std_error_relative": ident.combination_se[name]}
        if true is not None:
            entry["truth"] = true[name]
            entry["error_relative"] = fitted[name] / true[name] - 1.0
        combos[name] = entry
    out: dict[str, Any] = {
        "logs": [w.log.path for w in cal.windows], "logged_time_s": cal.duration,
        "windows": int(sum(len(w.window_t) for w in cal.windows)), "window_s": cal.settings.window,
        "frames": int(sum(len(w.sample_t) for w in cal.windows)), "model": cal.settings.spec.to_dict(),
        "fields": fields, "combinations": combos,
        "directions": [{"formula": d.formula(), "weights": d.weights, "data_std_error": d.data_se,
                        "identified": d.identified, "common_scale": d.common_scale} for d in ident.directions],
        "statements": ident.statements, "residual_variance": ident.variance, "covariance": ident.covariance,
        **({"gauss_newton": ident.gauss_newton} if ident.gauss_newton else {}),
        "rms_residual": {"x_m": float(cal.rms[0]), "y_m": float(cal.rms[1]), "psi_deg": math.degrees(cal.rms[2])},
        "camera_noise_estimate": {"position_m": float(np.mean(cal.sigma[:2])),
                                  "heading_deg": math.degrees(cal.sigma[2])},
        "prior_sigma": cal.settings.prior_sigma, "identified_se": cal.settings.identified_se,
        "nfev": cal.nfev, "wall_time_s": cal.wall_time, "optimiser": cal.message, "converged": cal.converged,
        "remaining_step_se": cal.remaining_step,
    }
    if held_out is not None:
        out["held_out"] = _held_out_summary(held_out)
    if prior_held_out is not None:
        out["held_out_prior"] = _held_out_summary(prior_held_out)
    return out


def not_converged_text(nfev: int, remaining: float) -> str:
    """What a fit that stopped at its evaluation limit means, and what to do (terminal and report.md)."""
    return (f"The fit did not converge: it stopped at its limit of {nfev} model evaluations, short of the optimum "
            f"(one more Gauss-Newton step would move a field by {remaining:.1f} standard errors), so the values and "
            "standard errors below are those of an unfinished fit. Run it again with more "
            f"evaluations (--max-evaluations {3 * nfev}); if it still stops there, try shorter windows (--window 3) "
            "or longer logs.")


def _percent(value: float) -> str:
    """A relative standard error in per cent: one decimal, two below 1 % (a force ratio fixed to 0.05 %)."""
    return f"{100 * value:.1f} %" if value >= 0.01 else f"{100 * value:.2f} %"


def markdown(report: dict[str, Any]) -> str:
    """``report.md``: the fitted values, standard errors, identifiability and the held-out check."""
    lines = ["# Calibration report", "",
             f"{len(report['logs'])} log(s), {report['logged_time_s']:.0f} s of logged robot time, "
             f"{report['frames']} poses in {report['windows']} windows of ~{report['window_s']:.0f} s; "
             f"{report['nfev']} model evaluations, {report['wall_time_s']:.1f} s.", "",
             *([f"**{not_converged_text(report['nfev'], report.get('remaining_step_se', math.nan))}**", ""]
               if not report.get("converged", True) else []),
             "## Fitted fields", "",
             "| field | value | prior | s.e. (logs + prior) | s.e. (logs alone) | identified |"
             + (" truth | error |" if any("truth" in f for f in report["fields"].values()) else ""),
             "|---|---|---|---|---|---|" + ("---|---|" if any("truth" in f for f in report["fields"].values()) else "")]
    for name, f in report["fields"].items():
        if "std_error_rad" in f:  # an offset: absolute, in degrees
            row = (f"| {name} | {f['value']:.5g} | {f['prior']:.5g} | {math.degrees(f['std_error_rad']):.2f} deg | "
                   f"{math.degrees(min(f['data_std_error_rad'], 9.99)):.2f} deg | "
                   f"{'yes' if f['identified'] else 'no'} |")
            if "truth" in f:
                row += f" {f['truth']:.5g} | {math.degrees(f['error_rad']):+.2f} deg |"
        else:
            row = (f"| {name} | {f['value']:.5g} | {f['prior']:.5g} | {_percent(f['std_error_relative'])} | "
                   f"{_percent(min(f['data_std_error_relative'], 9.99))} | {'yes' if f['identified'] else 'no'} |")
            if "truth" in f:
                row += f" {f['truth']:.5g} | {100 * f['error_relative']:+.1f} % |"
        lines.append(row)
    lines += ["", "## What the logs fix: force-to-inertia ratios", "",
              "| combination | meaning | value | s.e. (logs alone) |"
              + (" error |" if any("truth" in c for c in report["combinations"].values()) else ""),
              "|---|---|---|---|" + ("---|" if any("truth" in c for c in report["combinations"].values()) else "")]
    for name, c in report["combinations"].items():
        row = f"| {name} | {c['meaning']} | {c['value']:.5g} {c['unit']} | {100 * c['data_std_error_relative']:.2f} % |"
        if "truth" in c:
            row += f" {100 * c['error_relative']:+.2f} % |"
        lines.append(row)
    lines += ["", "## Identifiability", ""] + [f"- {s}" for s in report["statements"]]
    lines += ["", "Eigen-directions of the logs' information (log-parameters), best determined first:", ""]
    lines += [f"- {d['formula']}: +-{100 * min(d['data_std_error'], 9.99):.2f} %" for d in report["directions"]]
    lines += ["", f"Residual rms: {1000 * report['rms_residual']['x_m']:.2f} mm, "
              f"{1000 * report['rms_residual']['y_m']:.2f} mm, {report['rms_residual']['psi_deg']:.2f} deg; camera "
              f"noise estimated from the poses: {1000 * report['camera_noise_estimate']['position_m']:.2f} mm, "
              f"{report['camera_noise_estimate']['heading_deg']:.2f} deg. Standard errors: "
              f"{report.get('covariance', 'gauss-newton')} (docs/calibration.md, \"How far to trust the standard "
              "errors\")."]
    for key, title in (("held_out", "calibrated"), ("held_out_prior", "prior (before calibration)")):
        if key in report:
            h = report[key]
            lines += ["", f"## Held-out open-loop runs, {title}", ""]
            if not h["episodes"]:
                lines.append("No held-out episode long enough.")
                continue
            lines.append(f"Median end-position error {h['median_error_percent']:.2f} % of the path (worst "
                         f"{h['max_error_percent']:.2f} %) over {h['episodes']} episode(s).")
            lines += ["", "| log | episode | span [s] | path [m] | end error [m] | % of path |",
                      "|---|---|---|---|---|---|"]
            lines += [f"| {Path(r['log']).name} | {r['episode']} | {r['duration_s']:.1f} | {r['path_m']:.2f} | "
                      f"{r['end_error_m']:.3f} | {r['error_percent']:.2f} |" for r in h["runs"]]
    return "\n".join(lines) + "\n"


def plot_paths(cal: Calibration, held_out: list[HeldOutRun], path: str | Path, windows: int = 6) -> None:
    """Measured against simulated paths: a few fit windows (left) and the held-out runs (right), as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_fit, ax_held) = plt.subplots(1, 2, figsize=(12, 5))
    lw = cal.windows[0]
    sim = simulate(lw.track, [cal.params], lw.window_t, lw.starts[None], lw.sample_t, cal.settings.spec)[0]
    for w in range(min(windows, len(lw.window_t))):
        rows = lw.sample_window == w
        ax_fit.plot(*lw.observed[rows, :2].T, ".", ms=2, color="0.5", label="camera" if w == 0 else None)
        ax_fit.plot(*sim[rows, :2].T, "-", color="C0", label="calibrated model" if w == 0 else None)
    ax_fit.set_title(f"fit windows ({cal.settings.window:.0f} s, each started from its fitted state)")
    for k, run in enumerate(held_out):
        ax_held.plot(*run.observed[:, :2].T, ".", ms=1, color="0.5", label="camera" if k == 0 else None)
        ax_held.plot(*run.simulated[:, :2].T, "-", color=f"C{k % 10}",
                     label=f"model, ep. {run.episode}: {run.error_percent:.1f} % of path")
    ax_held.set_title("held-out runs, open loop")
    for ax in (ax_fit, ax_held):
        ax.set_xlabel("X [m]")
        ax.set_ylabel("Y [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
