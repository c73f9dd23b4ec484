"""Rendering of the fidelity benchmark (:mod:`~pectoral_gym.scaling.validation.fidelity`): markdown, summary, plots.

The summary goes to stdout, the plots are PNG.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (backend first)
import numpy as np  # noqa: E402

__all__ = ["plots", "summary_text", "write_markdown"]

_TITLE_MODELS = {"averaged model": "Averaged-model", "fast full model": "Fast full-model", "full model": "Full-model"}
_TITLES = {"constant": "constant patterns from rest", "every_4s": "patterns changed every 4 s",
           "every_0.5s": "patterns changed every 0.5 s"}


def _pct(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{100 * value:.{digits}f} %"


def _pair(res: dict[str, Any]) -> str:
    return f"{_pct(res['position']['median'])} / {_pct(res['position']['p90'])}"


def _deg(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} deg"


def _fast(results: dict[str, Any]) -> bool:
    """Whether the candidate is a full model (e.g. ``--candidate full-fast``) rather than the averaged model."""
    return results["spec"]["model"] == "full"


def _candidate(results: dict[str, Any]) -> str:
    """What the benchmark measured against the full model: ``"averaged model"`` or ``"fast full model"``."""
    if not _fast(results):
        return "averaged model"
    return "fast full model" if results["spec"]["integration"] == "fast" else "full model"


def _spec_text(results: dict[str, Any]) -> str:
    """``preset averaged (transitions on, ...)``: the candidate's preset and the options of the spec it ran."""
    spec = results["spec"]
    if _fast(results):
        options = [f"{spec['integration']} integration"]
    else:
        options = [f"transitions {'on' if spec['transitions'] else 'off'}",
                   f"ripple offsets {'on' if spec['ripple_offsets'] else 'off'}",
                   f"yaw damping {spec['yaw_damping']}", f"{spec['forcing']} forcing"]
    return f"preset {results['candidate']} ({', '.join(options)})"


def summary_text(results: dict[str, Any]) -> str:
    """A few lines for stdout: the targets table."""
    model = _candidate(results) + ", " + _spec_text(results) + (" against the reference integration"
                                                                  if _fast(results) else "")
    lines = [f"fidelity benchmark, seed set {results['seed_set']!r}, {model}"
             + (" (quick: not meaningful)" if results["quick"] else "")]
    for t in results["targets"]:
        mark = "ok  " if t["met"] else "MISS"
        lines.append(f"  {mark} {t['check']:42} {_pct(t['measured'], 2):>10}  (target <= {_pct(t['target'], 0)})")
    return "\n".join(lines)


def write_markdown(results: dict[str, Any], path: Path) -> Path:
    """The benchmark report (markdown)."""
    sc, dec, st = results["scenarios"], results["decomposition"], results["steady"]
    first = next(iter(sc.values()))
    fast = _fast(results)
    model = (f"{_candidate(results)}, {_spec_text(results)}, against the full model's reference integration "
             "(docs/model.md 6): every error below is the candidate's against the reference"
             if fast else
             f"K from `{results['source']}`, averaged model, {_spec_text(results)} (docs/model.md 3.6-3.8)")
    model += f"; spec `{json.dumps(results['spec'])}`"
    lines = [
        f"# {_TITLE_MODELS[_candidate(results)]} fidelity benchmark: seed set `{results['seed_set']}`",
        "",
        f"Seed {results['seed']}, pectoral-gym {results['version']}, {model}"
        + (" — **quick run: figures not meaningful**" if results["quick"] else "") + ".", "",
        f"Open loop: {first['n']} fish from rest, {first['duration_s']:g} s, two-fin patterns uniform in the envs' "
        "default action ranges. Position error = end-position distance / max(full-model path, 0.25 m); heading "
        "error = end heading difference.", "",
        "## Targets", "", "| check | measured | target | met |", "|---|---|---|---|",
        *(f"| {t['check']} | {_pct(t['measured'], 2)} | <= {_pct(t['target'], 0)} | {'yes' if t['met'] else 'no'} |"
          for t in results["targets"]),
        "", "## Open-loop scenarios", "",
        "| scenario | position median | p90 | worst | heading median | p90 |", "|---|---|---|---|---|---|",
        *(f"| {_TITLES[k]} | {_pct(v['position']['median'])} | {_pct(v['position']['p90'])} | "
          f"{_pct(v['position']['worst'])} | {_deg(v['heading_deg']['median'])} | {_deg(v['heading_deg']['p90'])} |"
          for k, v in sc.items()),
        "", "## Decomposition of the constant-pattern error", "",
        "One fin beating (the other at rest) or two; from rest (the first command makes a transitional half-stroke "
        "from 90 deg to the pattern's turning point) or on the pattern (`reset(right=, left=)`: none).", "",
        "| fins | start | position median | p90 | heading median | p90 |", "|---|---|---|---|---|---|",
        *(f"| {k.split('_')[0]} | {'on the pattern' if v['on_pattern'] else 'from rest'} | "
          f"{_pct(v['position']['median'])} | {_pct(v['position']['p90'])} | {_deg(v['heading_deg']['median'])} | "
          f"{_deg(v['heading_deg']['p90'])} |" for k, v in sorted(dec.items())),
        "", "## Each scenario by fins", "",
        "The same schedules with the left fin at rest (one fin) or copying the right fin, mirrored (no net "
        "moment: both models keep heading 0, so what is left is surge and sway). Position error median / p90.", "",
        "| scenario | two fins | one fin | mirrored fins |", "|---|---|---|---|",
        *(f"| {_TITLES[k]} | {_pair(sc[k])} | {_pair(results['by_fins'][k]['one_fin'])} | "
          f"{_pair(results['by_fins'][k]['mirrored'])} |" for k in sc),
        "", "## Two-fin periodic steady states", "",
        f"{len(st['rows'])} patterns (periods from {st['periods']} s), {st['n_turning']} turning faster than "
        f"{st['min_turn_rate']} rad/s (radius and period are compared on those); turning the other way: "
        f"{st['flips']}.", "",
        "| quantity | median | p90 | worst | worst pattern |", "|---|---|---|---|---|",
        *(f"| {k} | {_pct(st[k]['median'], 2)} | {_pct(st[k]['p90'], 2)} | {_pct(st[k]['worst'], 2)} | "
          f"{st[k]['worst_pattern']} |" for k in ("speed", "radius", "period")),
        "", "## Single-fin held-out set and Table 4", "",
        "| set | radius median | worst | period median | worst |", "|---|---|---|---|---|",
        *(f"| {name} | {_pct(results[key]['radius']['median'], 2)} | {_pct(results[key]['radius']['worst'], 2)} | "
          f"{_pct(results[key]['period']['median'], 2)} | {_pct(results[key]['period']['worst'], 2)} |"
          for key, name in (("single_fin", "single fin, random off-grid"), ("table4", "Table 4 (left fin)"))),
        "", "## Plots", "", *(f"![{p}]({p})" for p in results.get("plots", [])), "",
        "Stage times: " + ", ".join(f"{k} {v:.1f} s" for k, v in results["timing_s"].items()) + ".", "",
    ]
    path.write_text("\n".join(lines))
    return path


def plots(results: dict[str, Any], out: Path, stem: str) -> list[str]:
    """Error distributions and overlaid trajectories, ``<stem>_errors.png``, ``<stem>_paths.png``; the file names."""
    files = [_errors(results, out / f"{stem}_errors.png"), _trajectories(results, out / f"{stem}_paths.png")]
    return [f.name for f in files]


def _errors(results: dict[str, Any], path: Path) -> Path:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, res in {**results["scenarios"], **{k: v for k, v in results["decomposition"].items()
                                                 if k != "two_fins_from_rest"}}.items():
        style = "-" if name in results["scenarios"] else ":"
        title = _TITLES.get(name, name.replace("_", " "))
        for ax, key, scale in ((axes[0], "position", 100.0), (axes[1], "heading_deg", 1.0)):
            x = np.sort(np.asarray(res["errors"][key]) * scale)
            ax.plot(np.maximum(x, 1e-3), np.linspace(0, 1, x.size, endpoint=False) + 0.5 / x.size, style,
                    label=title)
    for ax, xl in ((axes[0], "position error [% of path]"), (axes[1], "heading error [deg]")):
        ax.set_xscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel("share of fish")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{_candidate(results).capitalize()} vs full model, open loop (seed set {results['seed_set']}): "
                 "error distributions")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _trajectories(results: dict[str, Any], path: Path) -> Path:
    names = list(results["scenarios"])
    fig, axes = plt.subplots(1, len(names), figsize=(5 * len(names), 5))
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        paths = results["scenarios"][name]["paths"]
        for i, (full, avg) in enumerate(zip(paths["full"], paths["averaged"], strict=True)):
            full, avg = np.asarray(full), np.asarray(avg)
            line, = ax.plot(full[:, 0], full[:, 1], "-", label=f"fish {i} full")
            ax.plot(avg[:, 0], avg[:, 1], "--", color=line.get_color(), label=f"fish {i} {_candidate(results)}")
        ax.plot(0, 0, "ko", ms=4)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(_TITLES[name])
        ax.set_xlabel("X [m]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("Y [m]")
    np.atleast_1d(axes)[0].legend(fontsize=6)
    fig.suptitle(f"Full model solid, {_candidate(results)} dashed")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
