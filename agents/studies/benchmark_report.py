"""The benchmark report as Markdown, JSON and bar charts.

The report is the dict of :func:`pectoral_gym.agents.studies.benchmark.run_benchmark`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.training.results import json_default, save_figure

__all__ = ["plot_report", "to_markdown", "write_outputs"]

_GOAL_COLUMNS = (("success", "success", 1.0), ("time_to_goal", "time to goal [s]", 1.0),
                 ("path_length", "path [m]", 1.0), ("fin_work", "fin work [J]", 1.0),
                 ("swept_work", "swept work [J]", 1.0), ("wall", "wall hits", 1.0), ("return", "return", 1.0))
_TRACK_COLUMNS = (("tracking_error", "tracking error [cm]", 100.0), ("path_length", "path [m]", 1.0),
                  ("fin_work", "fin work [J]", 1.0), ("swept_work", "swept work [J]", 1.0), ("wall", "wall hits", 1.0),
                  ("return", "return", 1.0))


def _fmt(metric: dict[str, Any] | None, scale: float) -> str:
    if not metric or metric.get("mean") is None:
        return "-"
    mean, low, high = (metric.get(k) for k in ("mean", "ci_low", "ci_high"))
    if low is None or high is None:
        return f"{mean * scale:.3g}"
    return f"{mean * scale:.3g} [{low * scale:.3g}, {high * scale:.3g}]"


def to_markdown(report: dict[str, Any]) -> str:
    """The benchmark report as markdown (tables per task, solver times, throughput, settings)."""
    s = report["settings"]
    steps = s.get("max_episode_steps") or 240
    lines = ["# Benchmark", "",
             f"Episodes per cell: {s['episodes']} (NMPC: {s['nmpc_episodes']}), episodes of at most {steps} steps; "
             f"episode k is reset with seed {s['seed']} + k. Mean [95 % bootstrap CI].", ""]
    if any("robot" in c for c in report["cells"]):
        lines += [f"Robot-stack columns: {s.get('robot_episodes')} episodes per cell, at most "
                  f"{s.get('robot_max_steps') or steps} steps; see \"Robot stack\" below.", ""]
    for task, columns in (("goal", _GOAL_COLUMNS), ("track", _TRACK_COLUMNS)):
        cells = [c for c in report["cells"] if c["task"] == task]
        if not cells:
            continue
        lines += [f"## Task `{task}`", "",
                  "| controller | env | episodes | " + " | ".join(title for _, title, _ in columns) + " |",
                  "|---" * (3 + len(columns)) + "|"]
        for c in cells:
            values = [_fmt(c["metrics"].get(key), scale) for key, _, scale in columns]
            lines.append(f"| {c['controller']} | {c['env']} | {c['n_episodes']} | " + " | ".join(values) + " |")
        lines.append("")
    lines += _robot_lines([c for c in report["cells"] if "robot" in c])
    solver = [c for c in report["cells"] if c.get("solver")]
    if solver:
        lines += ["## NMPC solve times", "", "| env | task | solves | mean [ms] | p50 [ms] | p95 [ms] | max [ms] "
                  "| failures | late |", "|---|---|---|---|---|---|---|---|---|"]
        for c in solver:
            t = c["solver"]
            p50 = f"{t['p50_ms']:.0f}" if "p50_ms" in t else "-"  # reports written before p50 was recorded
            lines.append(f"| {c['env']} | {c['task']} | {t['solves']} | {t['mean_ms']:.0f} | {p50} | "
                         f"{t['p95_ms']:.0f} | {t['max_ms']:.0f} | {t['failures']} | {t.get('late', '-')} |")
        lines.append("")
    rates = report.get("env_throughput")
    training = report.get("training_throughput")
    if rates or training:
        lines += ["## Throughput", "", "| what | rate |", "|---|---|"]
        if rates:
            for env_id, rate in rates["single_env"].items():
                lines.append(f"| single env `{env_id}` | {_rate(rate)} steps/s |")
            for env_id, rate in rates["vector_env"].items():
                n_envs = rates["num_envs"][env_id]
                lines.append(f"| vector env `{env_id}` @ {n_envs} envs | {_rate(rate)} env-steps/s |")
        if training:
            lines.append(f"| SB3 PPO `learn()` on `{training['env_id']}` ({training['n_envs']} envs, "
                         f"{training['timesteps']} steps, 1 torch thread) | {_rate(training['steps_per_s'])} steps/s |")
        lines.append("")
    lines += _solve_lines(report.get("time_to_solve"))
    if report.get("errors"):
        lines += ["## Errors", ""] + [f"- `{k}`: {v}" for k, v in report["errors"].items()] + [""]
    return "\n".join(lines)


def _robot_lines(cells: list[dict[str, Any]]) -> list[str]:
    """The robot-stack table (cells of ``pectoral_gym.hardware.studies.deployment.robot_cell``), or nothing."""
    if not cells:
        return []
    lines = ["## Robot stack", "",
             "The controller through `python -m pectoral_gym.hardware.deploy --emulate --lockstep` (radio link and "
             "firmware rules, rendered camera, tracker, observer, safety supervisor; the emulated robot runs the full "
             "model), in simulated time. Path, tracking error and wall contacts from the robot's true pose "
             "after each step; a wall contact: an episode in which the outline (body, and a disc of the fin span "
             "around each fin pivot) crossed a wall line at a logged pose. Wall time per step depends on the "
             "machine's load; NMPC solve times are wall times (no budget in lockstep).", "",
             "| controller | env | task | episodes | safety stops | wall contacts | min clearance [cm] "
             "| wall time per step [ms] | NMPC solve p50 / p95 / max [ms] | conditions |",
             "|---" * 10 + "|"]
    for c in cells:
        r = c["robot"]
        stops = ", ".join(f"{n} {reason}" for reason, n in sorted(r["safety_stops"].items())) or "none"
        t = r.get("solver") or {}
        solve = " / ".join(f"{t[k]:.0f}" for k in ("p50_ms", "p95_ms", "max_ms")) if "p50_ms" in t else "-"
        per_step = "-" if r.get("wall_ms_per_step") is None else f"{r['wall_ms_per_step']:.0f}"
        conditions = _conditions(r.get("conditions") or {})
        lines.append(f"| {c['controller']} | {c['env']} | {c['task']} | {c['n_episodes']} | {stops} | "
                     f"{r['wall_contacts']} | {_fmt(c['metrics'].get('min_clearance'), 100.0)} | {per_step} | {solve} "
                     f"| {conditions} |")
    return lines + [""]


def _conditions(c: dict[str, Any]) -> str:
    """The deploy's recorded rig conditions (``RigConditions`` as a dict, SI units) in the CLI's units."""
    noise = c.get("pose_noise") or (0.0, 0.0)
    parts = [(c.get("radio_latency"), f"radio latency {1e3 * (c.get('radio_latency') or 0):.0f} ms"),
             (c.get("radio_jitter"), f"jitter {1e3 * (c.get('radio_jitter') or 0):.0f} ms"),
             (c.get("radio_loss"), f"radio loss {100 * (c.get('radio_loss') or 0):.0f} %"),
             (c.get("camera_latency"), f"camera latency {1e3 * (c.get('camera_latency') or 0):.0f} ms"),
             (c.get("camera_drop"), f"frame drops {100 * (c.get('camera_drop') or 0):.0f} %"),
             (any(noise), f"pose noise {1e3 * noise[0]:.0f} mm / {math.degrees(noise[1]):.0f} deg")]
    return ", ".join(text for value, text in parts if value) or "ideal"


def _solve_lines(solve: dict[str, Any] | None) -> list[str]:
    """The time-to-solve table (:func:`pectoral_gym.agents.studies.solve_time.measure_time_to_solve`), or nothing."""
    if not solve:
        return []
    s = solve["settings"]
    runs = solve["runs"]
    lines = ["## Time to solve", "",
             f"PPO as in `pectoral-demo` (trained on the averaged model, budget {s['n_timesteps']} steps), probed "
             f"on the full model after every {s['every']} periodic evaluation(s) (every {s['eval_freq']} steps) with "
             f"{s['probe_episodes']} episodes (seeds {s['probe_seed']} + k); solved at the first probe with success "
             f">= {s['threshold']}, then confirmed on {s['confirm_episodes']} other episodes (seeds "
             f"{s['confirm_seed']} + k). Best-model selection uses neither. Time: training wall time (periodic "
             f"evaluations included, probes left out), {s['jobs']} run(s) at once; it depends on the machine's "
             "load.", "",
             "| training seed | solved | time [s] | steps | probe success | confirmed success | best probe |",
             "|---|---|---|---|---|---|---|"]
    for r in runs:
        def num(value: float | None, digits: int = 2) -> str:
            return "-" if value is None else f"{value:.{digits}f}"

        lines.append(f"| {r['seed']} | {'yes' if r['solved'] else 'no'} | {num(r['time_to_solve_s'], 0)} | "
                     f"{r['steps_to_solve'] if r['steps_to_solve'] is not None else '-'} | {num(r['probe_success'])} | "
                     f"{num(r['confirm_success'])} | {num(r['best_probe_success'])} |")
    times = [r["time_to_solve_s"] for r in runs if r["solved"]]
    median = f"; median time of the solved runs {float(np.median(times)):.0f} s" if times else ""
    return lines + ["", f"Solved: {len(times)} of {len(runs)} seeds within the budget{median}.", ""]


def _rate(value: float | None) -> str:
    return "-" if value is None else f"{value:,.0f}"


def plot_report(report: dict[str, Any], path: str | Path) -> Path:
    """Bar charts: goal success and track tracking error per controller and env (with CIs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (("goal", "success", "goal: success rate", 1.0), ("track", "tracking_error", "track: tracking error [cm]",
                                                                100.0))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    names = report["controllers"]
    labels = report.get("envs") or list(dict.fromkeys(c["env"] for c in report["cells"]))
    width = 0.8 / max(len(labels), 1)
    for ax, (task, key, title, scale) in zip(axes, panels, strict=True):
        for j, label in enumerate(labels):
            means, errs = [], [[], []]
            for name in names:
                cell = next((c for c in report["cells"] if c["task"] == task and c["env"] == label
                             and c["controller"] == name), None)
                m = (cell or {}).get("metrics", {}).get(key) or {}
                mean = m.get("mean")
                mean = math.nan if mean is None else mean * scale
                means.append(mean)
                low = m.get("ci_low")
                high = m.get("ci_high")
                errs[0].append(0.0 if low is None or math.isnan(mean) else mean - low * scale)
                errs[1].append(0.0 if high is None or math.isnan(mean) else high * scale - mean)
            x = np.arange(len(names)) + (j - (len(labels) - 1) / 2) * width
            ax.bar(x, means, width, yerr=errs, capsize=2, label=label)
        ax.set_xticks(np.arange(len(names)), names, rotation=20)
        ax.set_title(title)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylim(0, 1.05)
    axes[0].legend(fontsize=8)
    return save_figure(fig, path)


def write_outputs(report: dict[str, Any], out: str | Path, plots: bool = True) -> list[Path]:
    """Write ``benchmark.json``, ``benchmark.md`` and (``plots``) ``benchmark.png`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "benchmark.json", out / "benchmark.md"]
    paths[0].write_text(json.dumps(report, indent=2, default=json_default) + "\n")
    paths[1].write_text(to_markdown(report) + "\n")
    if plots:
        paths.append(plot_report(report, out / "benchmark.png"))
    return paths
