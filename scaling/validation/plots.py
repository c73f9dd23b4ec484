"""Rendering of the averaged-model validation results (:mod:`pectoral_gym.scaling.validation.validate`).

The markdown report (:func:`write_report`, read with ``docs/scaling-validation.md``),
the stdout summary (:func:`summary_text`) and the PNG plots (matplotlib, Agg
backend). Degrees on the axes; radians and seconds in the data passed in.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (backend first)
import numpy as np  # noqa: E402

from pectoral_gym.model.kfunctions import K_NAMES, ScalingFunctions  # noqa: E402

__all__ = ["identification_points", "plot_k_surfaces", "plot_single_fin_errors", "plot_speed_sweep",
           "plot_trajectories", "summary_text", "write_report"]

FIG3_PERIOD = 1.0  # s, the paper's Fig. 3
FIG3_RATIO = 2.0


def identification_points(metadata: dict[str, Any]) -> dict[str, np.ndarray] | None:
    """Identified K values at the grid points, if the metadata carries them (``metadata["data"]``).

    Accepted: a table ``{"columns": [...], "rows": [[...], ...]}`` (as ``pectoral_gym.scaling.identification.identify``
        writes it,
    with optional ``usable_K_*`` flags), a list of records or a dict of columns, with ``bias_deg``/``bias`` (rad),
    ``amplitude_deg``/``amplitude`` (rad), ``period_s``/``period``, ``ratio`` and any of
    ``K_fx, K_fy, K_m`` (missing or ``None`` values: not identified). Anything else: ``None``.

    Returns:
        Columns ``bias, amplitude`` (rad), ``period, ratio`` and the K names present, as float arrays.
    """
    data = metadata.get("data")
    try:
        if isinstance(data, dict) and "columns" in data and "rows" in data:  # the identify pipeline's table
            data = {k: [row[i] for row in data["rows"]] for i, k in enumerate(data["columns"])}
            for name in K_NAMES:  # values flagged unusable (unidentifiable) are not shown
                if name in data and f"usable_{name}" in data:
                    data[name] = [v if ok else None for v, ok in zip(data[name], data[f"usable_{name}"], strict=True)]
        if isinstance(data, list):
            data = {k: [rec.get(k) for rec in data] for k in data[0]} if data and isinstance(data[0], dict) else None
        if not isinstance(data, dict):
            return None

        def column(name: str, deg: bool = False) -> np.ndarray:
            values = np.array([np.nan if v is None else v for v in data[name]], dtype=np.float64)
            return np.radians(values) if deg else values

        out = {
            "bias": column("bias_deg", True) if "bias_deg" in data else column("bias"),
            "amplitude": column("amplitude_deg", True) if "amplitude_deg" in data else column("amplitude"),
            "period": column("period_s") if "period_s" in data else column("period"),
            "ratio": column("ratio"),
        }
        out.update({k: column(k) for k in K_NAMES if k in data})
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    sizes = {v.shape for v in out.values()}
    return out if len(sizes) == 1 and len(out) > 4 else None


def plot_k_surfaces(scaling: ScalingFunctions, path: Path, low: np.ndarray, high: np.ndarray) -> Path:
    """Fig. 3: K_fx, K_fy, K_m over amplitude and bias at T_p = 1 s, zeta = 2 (identified points overlaid)."""
    bias = np.linspace(low[0], high[0], 31)
    amp = np.linspace(low[1], high[1], 31)
    bb, aa = np.meshgrid(bias, amp)
    values = np.array([[scaling.evaluate(b, a, FIG3_PERIOD, FIG3_RATIO) for b, a in zip(rb, ra, strict=True)]
                       for rb, ra in zip(bb, aa, strict=True)])
    points = identification_points(scaling.metadata)
    if points is not None:
        sel = np.isclose(points["period"], FIG3_PERIOD, atol=1e-6) & np.isclose(points["ratio"], FIG3_RATIO)
    fig = plt.figure(figsize=(15, 4.8))
    for k, name in enumerate(K_NAMES):
        ax = fig.add_subplot(1, 3, k + 1, projection="3d")
        ax.plot_surface(np.degrees(aa), np.degrees(bb), values[..., k], cmap="viridis", alpha=0.8)
        if points is not None and name in points and np.any(sel):
            ax.scatter(np.degrees(points["amplitude"][sel]), np.degrees(points["bias"][sel]), points[name][sel],
                       color="red", s=12, label="identified (NMPC)")
            ax.legend(loc="upper left", fontsize=8)
        ax.set_xlabel("amplitude gA [deg]")
        ax.set_ylabel("bias g0 [deg]")
        ax.set_title(name if name != "K_fy" or scaling.sway == "paper"
                     else "K_fy (x force magnitude; = paper's K_fy cos g0)")
    fig.suptitle(f"Scaling functions at T_p = {FIG3_PERIOD:g} s, zeta = {FIG3_RATIO:g} (paper Fig. 3)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_speed_sweep(rows: list[dict[str, Any]], path: Path) -> Path:
    """Fig. 4: steady forward speed against fin-beat frequency, full vs averaged."""
    freq = np.array([r["frequency"] for r in rows])
    fig, (ax, ax_err) = plt.subplots(2, 1, figsize=(7, 6), sharex=True, height_ratios=(3, 1))
    ax.plot(freq, [100 * r["speed_full"] for r in rows], "o-", label="full model")
    ax.plot(freq, [100 * r["speed_averaged"] for r in rows], "s--", label="averaged model")
    ax.set_ylabel("forward speed [cm/s]")
    ax.set_title("Forward swimming, both fins (95 deg, 15 deg, 1/f, 4) (paper Fig. 4)")
    ax.legend()
    ax.grid(alpha=0.3)
    err = [np.nan if r["speed_error"] is None else 100 * r["speed_error"] for r in rows]
    ax_err.bar(freq, err, width=0.15, color=["tab:blue" if r["in_range"] else "tab:gray" for r in rows])
    ax_err.axhline(2.0, color="red", lw=1, ls=":", label="2 % target")
    ax_err.set_xlabel("fin-beat frequency [Hz]")
    ax_err.set_ylabel("error [%]")
    ax_err.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_trajectories(full: np.ndarray, averaged: np.ndarray, labels: list[str], path: Path) -> Path:
    """Fig. 5: X-Y paths ``(n, k, 2)`` of both models from rest at the origin."""
    fig, ax = plt.subplots(figsize=(7, 7))
    for i, name in enumerate(labels):
        line, = ax.plot(full[i, :, 0], full[i, :, 1], "-", label=f"{name} full")
        ax.plot(averaged[i, :, 0], averaged[i, :, 1], "--", color=line.get_color(), label=f"{name} averaged")
    ax.plot(0, 0, "ko", ms=4)
    ax.set_aspect("equal")
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title("Circular trajectories from rest (paper Fig. 5)\nfull model solid, averaged model dashed")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_single_fin_errors(rows: list[dict[str, Any]], path: Path) -> Path:
    """Radius and period errors of the random single-fin patterns against amplitude and bias."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    amp = np.array([r["right"][1] for r in rows])
    bias = np.array([r["right"][0] for r in rows])
    for ax, key in zip(axes, ("radius_error", "period_error"), strict=True):
        err = np.array([math.nan if r[key] is None else 100 * r[key] for r in rows])
        sc = ax.scatter(amp, err, c=bias, cmap="coolwarm", s=18)
        ax.axhline(2.0, color="k", lw=1, ls=":")
        ax.axhline(5.0, color="red", lw=1, ls=":")
        ax.set_xlabel("amplitude gA [deg]")
        ax.set_title(key.replace("_", " "))
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("relative error [%]")
    fig.colorbar(sc, ax=axes, label="bias g0 [deg]")
    fig.suptitle("Random single-fin patterns (right fin, off the grid)")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.2f} %"


def _fmt(value: float | None, scale: float = 1.0, digits: int = 4) -> str:
    return "-" if value is None else f"{scale * value:.{digits}g}"


def _params_line(differ: list[str] | None) -> str:
    if differ is None:
        return "The coefficients file records no model parameters."
    if not differ:
        return "K was identified with the model parameters validated here."
    return f"**K was identified with different model parameters**: {', '.join(differ)}."


def _summary_table(sections: dict[str, dict[str, Any]]) -> list[str]:
    lines = ["| Quantity | n | Median | 90th pct | Worst | Worst pattern |", "|---|---|---|---|---|---|"]
    for name, s in sections.items():
        lines.append(f"| {name} | {s['n']} | {_pct(s['median'])} | {_pct(s['p90'])} | {_pct(s['worst'])} "
                     f"| {s['worst_pattern'] or '-'} |")
    return lines


def write_report(results: dict[str, Any], path: Path) -> None:
    """Write the markdown report (how to read it: ``docs/scaling-validation.md``)."""
    t4, single, sweep, two = (results[k] for k in ("table4", "single_fin", "sweep", "two_fin"))
    ex = results["exclusions"]
    lines = [
        "# Averaged model against full model", "",
        f"K functions: `{results['source']}` (status: {results['metadata_status'] or '-'}; "
        f"K = 1 everywhere: {results['is_unit']}). pectoral-gym {results['version']}, seed {results['seed']}"
        f"{', **quick mode** (small sizes, figures not meaningful)' if results['quick'] else ''}.",
        "Relative error = |averaged - full| / |full| of the cycle-averaged periodic steady state (eq. 29).",
        _params_line(results["params_differ"]), "",
        "## Targets", "", "| Check | Measured | Target | Met |", "|---|---|---|---|",
    ]
    for t in results["targets"]:
        met = "met" if t["met"] else "**missed**"
        lines.append(f"| {t['check']} | {_pct(t['measured'])} | <= {100 * t['target']:g} % | {met} |")
    lines += ["", "Two-fin patterns have no target; their figures are in section 4.", "",
              "## 1. Table 4 patterns (left fin, right fin at rest)", "",
              "K is identified on the right fin; running the table on the left fin, as the paper writes it, "
              "also tests the mirror symmetry. Paper columns: the paper's own errors, for reference.", "",
              "| Left fin (g0, gA, Tp, zeta) | R full [m] | R avg [m] | R error | paper | "
              "T_b full [s] | T_b avg [s] | T_b error | paper |", "|---|---|---|---|---|---|---|---|---|"]
    for r in t4["rows"]:
        lines.append(f"| {tuple(round(v, 4) for v in r['left'])} | {_fmt(r['full']['radius'])} | "
                     f"{_fmt(r['averaged']['radius'])} | {_pct(r['radius_error'])} | {_pct(r['paper_radius_error'])} | "
                     f"{_fmt(r['full']['period'])} | {_fmt(r['averaged']['period'])} | {_pct(r['period_error'])} | "
                     f"{_pct(r['paper_period_error'])} |")
    lines += [""] + _summary_table({"radius": t4["radius"], "period": t4["period"]}) + _flip_lines(t4)
    box = single["box"]
    lines += ["", "## 2. Random single-fin patterns (right fin, off the grid)", "",
              f"{single['radius']['n']} seeded patterns drawn uniformly from bias {box['low'][0]:.4g}-"
              f"{box['high'][0]:.4g} deg, amplitude {box['low'][1]:.4g}-{box['high'][1]:.4g} deg, period "
              f"{box['low'][2]:.4g}-"
              f"{box['high'][2]:.4g} s, ratio {box['low'][3]:.4g}-{box['high'][3]:.4g} ({box['source']}). "
              f"Excluded (negligible forcing, the fish barely moves): amplitude < {ex['min_amplitude_deg']:g} deg "
              f"or ratio < {ex['min_ratio']:g}. "
              + ("Every pattern was checked to be off the identification grid."
                 if single["grid_checked"] else "No grid in the metadata: continuous draws are off-grid almost "
                 "surely."), ""]
    lines += _summary_table({"radius": single["radius"], "period": single["period"]}) + _flip_lines(single)
    lines += ["", "Per-pattern values: `validation.json` (`single_fin.rows`).", "",
              "## 3. Forward swimming sweep (Fig. 4: both fins, g0 = 95 deg, gA = 15 deg, zeta = 4)", "",
              "| f [Hz] | T_p [s] | inside identified period range | speed full [cm/s] | speed avg [cm/s] | error |",
              "|---|---|---|---|---|---|"]
    for r in sweep["rows"]:
        lines.append(f"| {r['frequency']:g} | {r['period']:.3g} | {'yes' if r['in_range'] else 'no'} | "
                     f"{100 * r['speed_full']:.3f} | {100 * r['speed_averaged']:.3f} | {_pct(r['speed_error'])} |")
    lines += [""] + _summary_table({"speed, all": sweep["speed"], "speed, inside range": sweep["speed_in_range"]})
    lines += ["", "## 4. Random two-fin patterns (different left and right settings)", "",
              f"{len(two['rows'])} seeded patterns; each fin drawn as in section 2 with periods from "
              f"{two['periods']} s (so both fins share a short averaging window). Radius and period errors "
              f"only for the {two['n_turning']} patterns whose full model turns at >= {ex['two_fin_min_turn_rate']:g} "
              f"rad/s (slower turns have huge, meaningless radii). Position error: distance between the two models' "
              f"positions after {two['duration']:g} s from rest, same start pose; relative to the full model's path "
              "length.", ""]
    lines += _summary_table({"radius": two["radius"], "period": two["period"], "speed": two["speed"],
                             "position / path length": two["position_rel"]}) + _flip_lines(two)
    pos = two["position_m"]
    lines += ["", f"Position error after {two['duration']:g} s: median {100 * pos['median']:.1f} cm, 90th pct "
              f"{100 * pos['p90']:.1f} cm, worst {100 * pos['worst']:.1f} cm ({pos['worst_pattern']}).", ""]
    if results["plots"]:
        lines += ["## Figures", ""] + [f"![{name}]({name})" for name in results["plots"]] + [""]
    lines += ["## Timing", "", " | ".join(f"{k}: {v:.1f} s" for k, v in results["timing_s"].items()), ""]
    path.write_text("\n".join(lines))


def _flip_lines(section: dict[str, Any]) -> list[str]:
    flips = section.get("flips")
    if not flips:
        return []
    if not flips["count"]:
        return ["", f"Turn direction: the averaged model turns the same way as the full model on all {flips['n']} "
                "patterns."]
    return ["", f"**Turn direction: on {flips['count']} of {flips['n']} patterns the averaged model settles on a turn "
            f"in the other direction** ({'; '.join(flips['patterns'])}). The radius and period errors above do not "
            "see this (they have no sign); docs/scaling.md explains the cause."]


def summary_text(results: dict[str, Any], out: Path) -> str:
    """A few lines for stdout: each target, met or missed, and where the report is."""
    lines = [f"averaged vs full model, K from {results['source']} ({results['timing_s']['total']:.1f} s)"]
    for t in results["targets"]:
        measured = "n/a" if t["measured"] is None else f"{100 * t['measured']:.2f} %"
        met = "met   " if t["met"] else "MISSED"
        lines.append(f"  {met} {t['check']}: {measured} (target <= {100 * t['target']:g} %)")
    two = results["two_fin"]
    for key in ("radius", "period", "speed"):
        if two[key]["median"] is not None:
            lines.append(f"  two-fin {key} error: median {100 * two[key]['median']:.2f} %, "
                         f"worst {100 * two[key]['worst']:.2f} %")
    pos = two["position_m"]
    lines.append(f"  two-fin position error after {two['duration']:g} s: median {100 * pos['median']:.1f} cm, "
                 f"worst {100 * pos['worst']:.1f} cm")
    lines.append(f"report: {out / 'report.md'}")
    return "\n".join(lines)
