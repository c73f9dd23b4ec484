"""The report of :func:`pectoral_gym.agents.studies.seeds.run_seeds` as Markdown and a plot."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.training.results import save_figure

__all__ = ["plot_seeds", "to_markdown"]

_LABELS = ("averaged", "full", "full+rand")


def _num(value: float | None, digits: int = 2) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def _metric(run: dict[str, Any], label: str, name: str, digits: int = 2) -> str:
    m = run["evaluations"][label].get(name) or {}
    if m.get("mean") is None:
        return "-"
    if m.get("ci_low") is None:
        return _num(m["mean"], digits)
    return f"{m['mean']:.{digits}f} [{m['ci_low']:.{digits}f}, {m['ci_high']:.{digits}f}]"


def _wall(run: dict[str, Any]) -> str:
    values = [(run["evaluations"][label].get("wall") or {}).get("mean") for label in ("averaged", "full")]
    return " / ".join(_num(v) for v in values)


def _solve(run: dict[str, Any]) -> str:
    s = run.get("time_to_solve")
    if not s:
        return "-"
    if not s["solved"]:
        return f"not solved (best probe {_num(s['best_probe_success'])})"
    confirm = "" if s.get("confirm_success") is None else f", confirmed {s['confirm_success']:.2f}"
    return f"{s['time_to_solve_s']:.0f} s / {s['steps_to_solve']} steps (probe {s['probe_success']:.2f}{confirm})"


def to_markdown(report: dict[str, Any]) -> str:
    """Per-seed table, across-seed table (IQM [bootstrap CI], mean, min, median, max) and targets."""
    s = report["settings"]
    summary = report["summary"]
    level = round(100 * summary["confidence"])
    lines = ["# PPO across training seeds", "",
             f"`{s['command']}`", "",
             f"PPO trained on `{s['train_env']}` (task `goal`, {s['n_timesteps']} steps, overrides "
             f"`{s['overrides']}`) for seeds {s['seeds']}, {s['jobs']} at a time on {s['cpu_count']} cores; "
             f"{s['wall_time_s']:.0f} s in all. Each policy (best on its periodic evaluation, on "
             f"`{s.get('eval_env') or s['train_env']}`, episodes seed + 1000000 + k) is evaluated on "
             f"{s['episodes']} held-out episodes per setting (episode k reset with seed {s['eval_seed']} + k, the "
             "same for every training seed; deterministic policy). Success per seed: mean [95 % bootstrap interval "
             "over episodes].", "",
             "## Per seed", "",
             "| seed | success, averaged | success, full | success, full + randomisation | gap averaged - full "
             "| wall hits, averaged / full | time to goal, full [s] | best periodic evaluation | train time [s] "
             "| time to solve (full >= 0.95) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for run in report["per_seed"]:
        ev = run["evaluations"]
        gap = None
        if ev["averaged"]["success"]["mean"] is not None and ev["full"]["success"]["mean"] is not None:
            gap = ev["averaged"]["success"]["mean"] - ev["full"]["success"]["mean"]
        best = run.get("best_eval")
        best_text = "-" if not best else f"{best['success']:.2f} at {best['timesteps']}"
        lines.append(f"| {run['seed']} | {_metric(run, 'averaged', 'success')} | {_metric(run, 'full', 'success')} | "
                     f"{_metric(run, 'full+rand', 'success')} | {_num(gap, 2)} | {_wall(run)} | "
                     f"{_metric(run, 'full', 'time_to_goal', 1)} | {best_text} | {run['train_time_s']:.0f} | "
                     f"{_solve(run)} |")
    lines += ["", "## Across seeds", "",
              f"Interquartile mean (`scipy.stats.trim_mean(x, 0.25)`) with a {level} % percentile-bootstrap "
              f"interval over the {len(summary['seeds'])} seeds (`scipy.stats.bootstrap`); with few seeds the "
              "interval is coarse.", "",
              f"| figure | IQM [{level} % CI] | mean | min | median | max |", "|---|---|---|---|---|---|"]
    for name, a in summary["figures"].items():
        digits = 1 if "[s]" in name else 3
        centre = "-" if a["iqm"] is None else (f"{a['iqm']:.{digits}f} [{a['ci_low']:.{digits}f}, "
                                                f"{a['ci_high']:.{digits}f}]")
        lines.append(f"| {name} | {centre} | {_num(a['mean'], digits)} | {_num(a['min'], digits)} | "
                     f"{_num(a['median'], digits)} | {_num(a['max'], digits)} |")
    lines += ["", "## Targets", "", "| figure | target | seeds meeting it |", "|---|---|---|"]
    for name, t in summary["targets"].items():
        met = ", ".join(str(seed) for seed in t["seeds_met"]) or "none"
        lines.append(f"| {name} | {t['target']} | {len(t['seeds_met'])} of {t['n']} ({met}) |")
    return "\n".join(lines + [""])


def plot_seeds(report: dict[str, Any], path: str | Path) -> Path:
    """Success per setting: one dot per seed, the IQM with its bootstrap interval, the targets; time to solve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    per_seed = report["per_seed"]
    figures = report["summary"]["figures"]
    solving = "time to solve [s]" in figures
    eval_env = report["settings"].get("eval_env") or report["settings"]["train_env"]
    model = "full" if "Full" in eval_env else "averaged"
    fig, axes = plt.subplots(1, 3 if solving else 2, figsize=(16 if solving else 11, 4), squeeze=False)
    ax = axes[0][0]
    offsets = np.linspace(-0.15, 0.15, len(per_seed)) if len(per_seed) > 1 else np.zeros(1)
    for j, label in enumerate(_LABELS):
        values = [run["evaluations"][label]["success"]["mean"] for run in per_seed]
        ax.scatter(j + offsets, [np.nan if v is None else v for v in values], s=18, color="tab:blue", alpha=0.7,
                   label="one training seed" if j == 0 else None)
        a = figures[f"success {label}"]
        if a["iqm"] is not None:
            ax.errorbar(j + 0.3, a["iqm"], yerr=[[a["iqm"] - a["ci_low"]], [a["ci_high"] - a["iqm"]]], fmt="D",
                        color="black", capsize=4, label="IQM, bootstrap CI over seeds" if j == 0 else None)
    ax.hlines([0.95], 0.6, 1.4, colors="tab:red", linestyles="--", label="target")
    ax.hlines([0.90], 1.6, 2.4, colors="tab:red", linestyles="--")
    ax.set_xticks(range(len(_LABELS)), _LABELS)
    ax.set_ylabel("success rate")
    ax.set_ylim(min(0.5, ax.get_ylim()[0]), 1.02)
    ax.set_title(f"PPO, {len(per_seed)} training seeds")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    ax = axes[0][1]
    for k, run in enumerate(per_seed):
        colour = f"C{k % 10}"
        curve = run.get("training_evaluations") or []
        ax.plot([e["timesteps"] / 1e3 for e in curve], [e["success"] for e in curve], color=colour, lw=1,
                label=f"seed {run['seed']}: periodic eval ({model})")
        probes = [e for e in curve if "probe" in e]
        ax.plot([e["timesteps"] / 1e3 for e in probes], [e["probe"]["success"] for e in probes], color=colour, lw=1,
                ls="--", label="probe (full, held out)" if k == 0 else None)
    ax.set_xlabel("training steps [thousands]")
    ax.set_ylabel("success rate")
    ax.set_title("learning curves")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    if solving:
        ax = axes[0][2]
        seeds = [str(run["seed"]) for run in per_seed]
        times = [run["time_to_solve"]["time_to_solve_s"] for run in per_seed]
        solved = [t is not None for t in times]
        ax.bar(seeds, [t if t is not None else 0.0 for t in times], color=["tab:green" if k else "tab:gray"
                                                                         for k in solved])
        for i, k in enumerate(solved):
            if not k:
                ax.text(i, 0.0, "not\nsolved", ha="center", va="bottom", fontsize=8)
        ax.set_ylim(bottom=0.0, top=max([t for t in times if t is not None], default=1.0) * 1.1)
        ax.set_xlabel("training seed")
        ax.set_ylabel("training wall time to full >= 0.95 [s]")
        ax.set_title("time to solve")
        ax.grid(axis="y", alpha=0.3)
    return save_figure(fig, path)
