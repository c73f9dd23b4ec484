"""The result of an evaluation and its outputs: JSON file, Markdown table, trajectory plot.

:func:`pectoral_gym.agents.training.evaluate.evaluate` returns an :class:`EvaluationResult`; the
benchmark and the demo write it with these functions.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.training.metrics import MetricSummary, Trajectory

__all__ = ["EvaluationResult", "format_table", "json_default", "jsonable", "plot_trajectories", "save_figure",
           "write_json"]


@dataclass
class EvaluationResult:
    """Metrics of an evaluation (see :mod:`pectoral_gym.agents.training.metrics` for the definitions).

    Attributes:
        controller: Controller name.
        env_id: Environment id.
        task: ``"goal"`` or ``"track"``.
        seed: Episode ``k`` was reset with ``seed + k``.
        env_kwargs: Environment arguments (JSON-ready).
        metrics: Metric name -> mean and confidence interval.
        episodes: Per-episode metrics.
        trajectories: The episodes.
        wall_time: Seconds the evaluation took.
    """

    controller: str
    env_id: str
    task: str
    seed: int
    env_kwargs: dict[str, Any]
    metrics: dict[str, MetricSummary]
    episodes: list[dict[str, float]]
    trajectories: list[Trajectory] = field(repr=False)
    wall_time: float = 0.0

    @property
    def n_episodes(self) -> int:
        """Number of episodes."""
        return len(self.episodes)

    def to_dict(self, per_episode: bool = True) -> dict[str, Any]:
        """JSON-ready dict (NaN becomes ``None``)."""
        data: dict[str, Any] = {
            "controller": self.controller, "env_id": self.env_id, "task": self.task, "seed": self.seed,
            "n_episodes": self.n_episodes, "env_kwargs": self.env_kwargs, "wall_time_s": self.wall_time,
            "metrics": {k: v.as_dict() for k, v in self.metrics.items()},
        }
        if per_episode:
            data["episodes"] = [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in e.items()}
                                for e in self.episodes]
        return data


def write_json(result: EvaluationResult, path: str | Path, per_episode: bool = True) -> Path:
    """Write ``result.to_dict()`` to ``path`` (folders created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result.to_dict(per_episode), indent=2, default=json_default) + "\n")
    return path


def json_default(value: Any) -> Any:
    """``json.dumps(default=...)`` hook: numpy scalars and arrays as Python values, anything else as text."""
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON types (through :func:`json_default`)."""
    return json.loads(json.dumps(value, default=json_default))


def plot_trajectories(results: EvaluationResult | list[EvaluationResult], path: str | Path,
                      max_episodes: int = 12) -> Path:
    """Top view of the tank with the first episodes of one or more evaluations (one panel each); PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

    results = [results] if isinstance(results, EvaluationResult) else list(results)
    fig, axes = plt.subplots(len(results), 1, figsize=(7.5, 4.2 * len(results)), squeeze=False)
    for ax, result in zip(axes[:, 0], results, strict=True):
        ax.add_patch(plt.Rectangle((0, 0), TANK_LENGTH, TANK_WIDTH, fill=False, lw=2, color="0.3"))
        goal_radius = float(result.env_kwargs.get("goal_radius", 0.08))
        for k, traj in enumerate(result.trajectories[:max_episodes]):
            color = plt.cm.tab10(k % 10)
            style = "-" if traj.success or result.task == "track" else "--"
            ax.plot(traj.xy[:, 0], traj.xy[:, 1], style, color=color, lw=1.4)
            ax.plot(*traj.xy[0], "o", color=color, ms=4)
            if result.task == "goal":
                ax.add_patch(plt.Circle(traj.target[0], goal_radius, color=color, alpha=0.25))
                ax.plot(*traj.target[0], "x", color=color, ms=6)
            else:
                ax.plot(traj.target[:, 0], traj.target[:, 1], ":", color=color, lw=1)
        title = f"{result.controller} on {result.env_id} ({result.task}"
        title += ", randomised)" if result.env_kwargs.get("randomize") else ")"
        metric = result.metrics.get("success") or result.metrics.get("tracking_error")
        if metric is not None and not math.isnan(metric.mean):
            label = "success" if result.task == "goal" else "tracking error"
            unit = "" if result.task == "goal" else " m"
            title += f": {label} {metric.mean:.3g}{unit} [{metric.low:.3g}, {metric.high:.3g}]"
        ax.set_title(title, fontsize=9)
        ax.set_xlim(-0.05, TANK_LENGTH + 0.05)
        ax.set_ylim(-0.05, TANK_WIDTH + 0.05)
        ax.set_aspect("equal")
        ax.set_xlabel("X [m]")
        ax.set_ylabel("Y [m]")
    fig.text(0.01, 0.005, "o start, x goal (shaded: goal radius); dashed: goal not reached", fontsize=7)
    return save_figure(fig, path)


def save_figure(fig: Any, path: str | Path) -> Path:
    """Lay out a matplotlib figure, write it as a PNG at ``path`` (folders created), close it; returns the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def format_table(results: list[EvaluationResult]) -> str:
    """Markdown table of the main metrics (mean [CI]) of several evaluations."""
    columns = ("success", "time_to_goal", "tracking_error", "path_length", "fin_work", "swept_work", "return")
    shown = [c for c in columns if any(c in r.metrics for r in results)]
    lines = ["| controller | env | task | episodes | " + " | ".join(shown) + " |",
             "|---" * (4 + len(shown)) + "|"]
    for r in results:
        cells = []
        for c in shown:
            m = r.metrics.get(c)
            cells.append("-" if m is None or math.isnan(m.mean) else f"{m.mean:.3g} [{m.low:.3g}, {m.high:.3g}]")
        env = r.env_id + (" (randomised)" if r.env_kwargs.get("randomize") else "")
        lines.append(f"| {r.controller} | {env} | {r.task} | {r.n_episodes} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
