"""The results of a sweep (:mod:`~pectoral_gym.agents.studies.sweep`): one row per trial, tables and a plot of curves.

Tables as CSV and Markdown.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

__all__ = ["TABLE_COLUMNS", "format_markdown", "plot_results", "result_rows", "write_tables"]

TABLE_COLUMNS = ("status", "timesteps", "evaluations", "success", "mean_return", "best_success", "best_mean_return",
                 "env_ready_s", "train_s")


def result_rows(grid: Any, keys: list[str], metric: str) -> list[dict[str, Any]]:
    """One row per trial of a Tune ``ResultGrid``: the trial's values of ``keys``, status and figures.

    ``status`` is ``done`` (trained to ``n_timesteps``), ``stopped`` (the scheduler stopped it) or
    ``error``; ``success``/``mean_return`` are the last evaluation's, ``best_*`` the best over
    its evaluations; ``curve`` holds ``(timesteps, metric)`` of every evaluation and ``label`` the
    trial's values as text (for the plot).
    """
    rows = []
    for result in grid:
        frame = result.metrics_dataframe
        history = [] if frame is None or frame.empty else frame.to_dict("records")
        last = history[-1] if history else {}
        row: dict[str, Any] = {"trial": (result.metrics or {}).get("trial_id", Path(result.path).name)}
        row.update({key: result.config.get(key) for key in keys})
        if result.error is not None:
            status = "error"
        elif last and last.get("timesteps", 0) < last.get("n_timesteps", math.inf):
            status = "stopped"
        else:
            status = "done" if last else "error"
        row.update({
            "status": status,
            "timesteps": int(last.get("timesteps", 0)),
            "evaluations": len(history),
            "success": last.get("success", math.nan),
            "mean_return": last.get("mean_return", math.nan),
            "best_success": max((h.get("success", math.nan) for h in history), default=math.nan),
            "best_mean_return": max((h.get("mean_return", math.nan) for h in history), default=math.nan),
            "env_ready_s": last.get("env_ready_s", math.nan),
            "train_s": last.get("elapsed_s", math.nan),
            **{key: last[key] for key in ("final_success", "final_mean_return", "final_tracking_error")
               if key in last},
            "path": str(result.path),
            "curve": [(h["timesteps"], h.get(metric, math.nan)) for h in history if "timesteps" in h],
            "label": ", ".join(f"{key}={_text(result.config.get(key))}" for key in keys) or row["trial"],
        })
        rows.append(row)
    return rows


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    """Every row's keys in first-seen order, without the plot's ``curve`` and ``label``, and ``path``."""
    return [c for c in dict.fromkeys(k for row in rows for k in row) if c not in ("curve", "label", "path")]


def _text(value: Any) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.4g}"
    return "" if value is None else str(value)


def format_markdown(rows: list[dict[str, Any]]) -> str:
    """A Markdown table of the rows (without ``curve``, ``label`` and ``path``)."""
    if not rows:
        return "(no trials)\n"
    columns = _columns(rows)
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_text(row.get(c)) for c in columns) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def write_tables(rows: list[dict[str, Any]], folder: str | Path) -> None:
    """Write ``results.csv`` (every column but ``curve`` and ``label``) and ``results.md`` into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    columns = [*_columns(rows), "path"] if rows else ["trial"]
    with open(folder / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    (folder / "results.md").write_text(format_markdown(rows))


def plot_results(rows: list[dict[str, Any]], path: str | Path, metric: str) -> None:
    """Plot ``metric`` against environment steps, one line per trial (a cross where a trial was stopped)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for row in rows:
        if not row["curve"]:
            continue
        steps, values = zip(*row["curve"], strict=True)
        (line,) = ax.plot(steps, values, marker=".", label=f"{row['trial']}: {row['label']}")
        if row["status"] == "stopped":
            ax.plot(steps[-1], values[-1], "x", color=line.get_color(), markersize=10)
    ax.set_xlabel("environment steps")
    ax.set_ylabel(f"evaluation {metric}")
    ax.set_title("sweep trials (x: stopped by the scheduler)")
    if len(rows) <= 12:
        ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
