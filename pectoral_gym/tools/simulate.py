"""Trajectory simulation, CSV export and plots for one fish in the tank.

A thin layer over :class:`~pectoral_gym.model.models.FullModel` and
:class:`~pectoral_gym.model.models.AveragedModel` used by the ``pectoral-fish``
command line (``simulate`` and ``demo``)::

    from pectoral_gym import FinBeat
    from pectoral_gym.tools.simulate import simulate, write_csv, plot_trajectories

    traj = simulate("full", right=FinBeat.from_degrees(90, 20, 1.0, 4), duration=30.0)
    write_csv(traj, "out/trajectory.csv")
    plot_trajectories([traj], "out/trajectory.png")

Units are SI (m, s, rad) everywhere except the fin-angle columns of the CSV
and the plot labels, which are in degrees. Plots use matplotlib's
object-oriented API with the Agg canvas, so no GUI backend is needed and the
global pyplot state is left alone.
"""

from __future__ import annotations

import contextlib
import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FinBeat, FishParams
from pectoral_gym.model.spec import MODELS, ModelSpec, make_model
from pectoral_gym.tools.optional import require

__all__ = [
    "CSV_COLUMNS",
    "MODELS",
    "TANK_LENGTH",
    "TANK_WIDTH",
    "Trajectory",
    "make_model",
    "plot_panels",
    "plot_trajectories",
    "simulate",
    "write_csv",
]

CSV_COLUMNS = ("t", "X", "Y", "psi", "vx", "vy", "omega", "gamma_right_deg", "gamma_left_deg")


@dataclass(frozen=True)
class Trajectory:
    """A sampled run of one fish.

    Attributes:
        model: ``"full"`` or ``"averaged"``.
        t: ``(N,)`` sample times [s], starting at 0.
        state: ``(N, 6)`` ``X, Y, psi, vx, vy, omega`` (m, m, rad, m/s, m/s, rad/s);
            ``X, Y, psi`` in the tank frame, velocities in the body frame.
        fin_angles: ``(N, 2)`` fin angles, right fin first [rad].
        right: Right-fin pattern.
        left: Left-fin pattern.
    """

    model: str
    t: np.ndarray
    state: np.ndarray
    fin_angles: np.ndarray
    right: FinBeat
    left: FinBeat


def simulate(
    model: str | ModelSpec = "full",
    right: FinBeat | None = None,
    left: FinBeat | None = None,
    duration: float = 60.0,
    x0: float = TANK_LENGTH / 2,
    y0: float = TANK_WIDTH / 2,
    heading: float = 0.0,
    sample: float = 0.05,
    params: FishParams | None = None,
    scaling: ScalingFunctions | str | None = "spec",
    forcing: str | None = None,
    progress: bool = False,
) -> Trajectory:
    """Simulate one fish from rest with constant fin patterns.

    The fish starts at ``(x0, y0)`` with heading ``heading`` and zero velocity,
    both fins at the start of a power stroke. There are no walls: the tank
    only frames the plots.

    Args:
        model: A model spec (:mod:`pectoral_gym.model.spec`), a preset name, ``"full"`` or ``"averaged"``.
        right, left: Fin patterns; ``None`` holds that fin at rest.
        duration: Simulated time [s], > 0.
        x0, y0: Initial position in the tank frame [m].
        heading: Initial heading ``psi`` [rad] from the tank X axis.
        sample: Sampling interval of the output [s], > 0; the last sample
            lands exactly on ``duration``.
        params: Model parameters (default: Table 1).
        scaling, forcing: Replace the averaged spec's K and forcing (:func:`make_model`; the defaults keep the spec's).
        progress: Show a tqdm progress bar (on a terminal only; tqdm comes with the extra ``plots``).

    Returns:
        The sampled :class:`Trajectory`, ``t[0] = 0`` is the initial state.

    Raises:
        ValueError: For a non-positive duration or sample, or an unknown model.
    """
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be a finite number > 0 s, got {duration!r}")
    if not (sample > 0 and math.isfinite(sample)):
        raise ValueError(f"sample must be a finite number > 0 s, got {sample!r}")
    right = right or FinBeat.rest()
    left = left or FinBeat.rest()
    fish = make_model(model, 1, params, scaling, forcing)
    fish.reset(state=np.array([x0, y0, heading, 0.0, 0.0, 0.0]), right=right, left=left)

    steps = max(1, math.ceil(duration / sample - 1e-9))
    t = np.minimum(np.arange(steps + 1) * sample, duration)
    state = np.empty((steps + 1, 6))
    angles = np.empty((steps + 1, 2))
    state[0] = fish.state[0]
    angles[0] = fish.fin_angles()[0][0]

    bar = require("tqdm.auto").tqdm(total=steps, desc=f"{model} model", unit="sample", disable=None, leave=False) \
        if progress else None
    with bar or contextlib.nullcontext():
        for k in range(1, steps + 1):
            fish.advance(t[k] - t[k - 1])
            state[k] = fish.state[0]
            angles[k] = fish.fin_angles()[0][0]
            if bar is not None:
                bar.update()
    return Trajectory(model.model if isinstance(model, ModelSpec) else model, t, state, angles, right, left)


def write_csv(traj: Trajectory, path: str | Path) -> Path:
    """Write a trajectory as CSV with the header :data:`CSV_COLUMNS`.

    Columns: ``t`` [s], ``X, Y`` [m], ``psi`` [rad], ``vx, vy`` [m/s], ``omega``
    [rad/s], ``gamma_right_deg, gamma_left_deg`` [deg].

    Args:
        traj: The trajectory.
        path: Output file; parent directories are created.

    Returns:
        The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = np.column_stack([traj.t, traj.state, np.degrees(traj.fin_angles)])
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(CSV_COLUMNS)
        writer.writerows([f"{v:.10g}" for v in row] for row in table)
    return path


_COLOURS = {"full": "tab:blue", "averaged": "tab:orange"}


def _draw_top_view(ax, traj: Trajectory, colour: str, label: str, linestyle: str, arrow_every: float) -> None:
    """Path, start/end markers and heading arrows of one trajectory on ``ax``."""
    x, y, psi = traj.state[:, 0], traj.state[:, 1], traj.state[:, 2]
    ax.plot(x, y, color=colour, linestyle=linestyle, lw=1.4, label=label)
    ax.plot(x[0], y[0], "o", color=colour, ms=7, mfc="white")
    ax.plot(x[-1], y[-1], "s", color=colour, ms=6)
    if arrow_every > 0:
        stride = max(1, round(arrow_every / max(traj.t[1] - traj.t[0], 1e-12))) if traj.t.size > 1 else 1
        idx = np.arange(0, traj.t.size, stride)
        length = 0.06  # m, drawn arrow length
        ax.quiver(x[idx], y[idx], length * np.cos(psi[idx]), length * np.sin(psi[idx]), color=colour,
                  angles="xy", scale_units="xy", scale=1.0, width=0.004, alpha=0.8)


def plot_trajectories(
    trajectories: Sequence[Trajectory],
    path: str | Path,
    labels: Sequence[str] | None = None,
    title: str | None = None,
    arrow_every: float = 5.0,
    colours: Sequence[str] | None = None,
    linestyles: Sequence[str] | None = None,
) -> Path:
    """Plot trajectories: top view in the tank, and ``vx, vy, omega`` over time.

    The top view draws the 2.30 m x 1.15 m tank outline, the path, a circle at
    the start and a square at the end, and heading arrows every
    ``arrow_every`` seconds. The right column shows the body-frame velocities
    (m/s) and the yaw rate (rad/s).

    Args:
        trajectories: One or more runs (e.g. full and averaged of one pattern).
        path: Output image (PNG by extension); parent directories are created.
        labels: Legend label per trajectory (default: the model name).
        title: Figure title.
        arrow_every: Heading-arrow spacing [s]; 0 disables arrows.
        colours: Line colour per trajectory (default: by model).
        linestyles: Line style per trajectory (default: solid).

    Returns:
        The path written.
    """
    Figure = require("matplotlib.figure").Figure
    Rectangle = require("matplotlib.patches").Rectangle

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    labels = list(labels) if labels is not None else [tr.model for tr in trajectories]
    colours = list(colours) if colours is not None else [_COLOURS.get(tr.model, "k") for tr in trajectories]
    linestyles = list(linestyles) if linestyles is not None else ["-"] * len(trajectories)

    fig = Figure(figsize=(12, 6), layout="constrained")
    grid = fig.add_gridspec(3, 2, width_ratios=(1.6, 1.0))
    top = fig.add_subplot(grid[:, 0])
    ax_vx = fig.add_subplot(grid[0, 1])
    ax_vy = fig.add_subplot(grid[1, 1], sharex=ax_vx)
    ax_om = fig.add_subplot(grid[2, 1], sharex=ax_vx)

    top.add_patch(Rectangle((0.0, 0.0), TANK_LENGTH, TANK_WIDTH, fill=False, lw=2.0, ec="0.3"))
    for tr, lab, col, ls in zip(trajectories, labels, colours, linestyles, strict=True):
        _draw_top_view(top, tr, col, lab, ls, arrow_every)
        ax_vx.plot(tr.t, tr.state[:, 3], color=col, linestyle=ls, lw=1.0, label=lab)
        ax_vy.plot(tr.t, tr.state[:, 4], color=col, linestyle=ls, lw=1.0)
        ax_om.plot(tr.t, tr.state[:, 5], color=col, linestyle=ls, lw=1.0)
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("X [m]")
    top.set_ylabel("Y [m]")
    top.set_title("top view (o start, \u25a0 end, arrows: heading)")
    top.legend(loc="best", fontsize="small")
    top.grid(alpha=0.3)
    for ax, name in ((ax_vx, "$v_x$ [m/s]"), (ax_vy, "$v_y$ [m/s]"), (ax_om, "$\\omega$ [rad/s]")):
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.axhline(0.0, color="0.5", lw=0.6)
    ax_om.set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110)
    return path


def plot_panels(
    groups: dict[str, Sequence[Trajectory]],
    path: str | Path,
    title: str | None = None,
    arrow_every: float = 5.0,
) -> Path:
    """Side-by-side panels, one per group: top view in the tank above the yaw rate over time.

    Within a group the full model is drawn solid and the averaged model dashed.

    Args:
        groups: Panel title -> trajectories (e.g. the full and averaged runs of one pattern).
        path: Output image; parent directories are created.
        title: Figure title.
        arrow_every: Heading-arrow spacing [s]; 0 disables arrows.

    Returns:
        The path written.
    """
    Figure = require("matplotlib.figure").Figure
    Rectangle = require("matplotlib.patches").Rectangle

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(4.6 * len(groups), 6.4), layout="constrained")
    axes = fig.subplots(2, len(groups), squeeze=False, height_ratios=(1.6, 1.0))
    for col, (name, trajectories) in enumerate(groups.items()):
        top, ax_om = axes[0, col], axes[1, col]
        top.add_patch(Rectangle((0.0, 0.0), TANK_LENGTH, TANK_WIDTH, fill=False, lw=2.0, ec="0.3"))
        for tr in trajectories:
            style = "--" if tr.model == "averaged" else "-"
            colour = _COLOURS.get(tr.model, "k")
            _draw_top_view(top, tr, colour, tr.model, style, arrow_every)
            ax_om.plot(tr.t, tr.state[:, 5], color=colour, linestyle=style, lw=1.0, label=tr.model)
        top.set_aspect("equal", adjustable="datalim")
        top.set_title(name, fontsize="medium")
        top.set_xlabel("X [m]")
        top.grid(alpha=0.3)
        ax_om.set_xlabel("t [s]")
        ax_om.axhline(0.0, color="0.5", lw=0.6)
        ax_om.grid(alpha=0.3)
    axes[0, 0].set_ylabel("Y [m]")
    axes[1, 0].set_ylabel("$\\omega$ [rad/s]")
    axes[0, 0].legend(loc="best", fontsize="small")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=100)
    return path
