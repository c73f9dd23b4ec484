"""Fidelity benchmark of the averaged model against the full model (``pectoral-scaling fidelity``).

Where the averaged model is used (agents train on it, the NMPCs plan with it),
fin patterns change and the two fins beat differently. This benchmark measures
it there, open loop, with the public :mod:`pectoral_gym.model.models` API:

1. **Open-loop scenarios** (:data:`SCENARIOS`): ``n`` fish from rest, seeded
   random two-fin patterns drawn uniformly from the environments' default action
   ranges, held constant, changed every 4 s or every 0.5 s (as an agent does),
   for :data:`DURATION` s. Position error = distance between the two models' end
   positions / max(full-model path length, :data:`MIN_PATH` m); heading error =
   end heading difference (deg, wrapped).
2. **Decomposition** of the constant-pattern error (:data:`DECOMPOSITION`): one
   fin or two, started from rest (the first command makes a transitional
   half-stroke) or on the pattern (``reset(right=, left=)``: no transitional stroke);
   and of every scenario by fins (:data:`FIN_SPLITS`): the same schedules with the
   left fin at rest (one fin's yaw) or copying the right fin (mirrored fins: no net
   moment, so both models keep heading 0 and only surge and sway are left).
3. **Two-fin periodic steady states**: speed, turning radius and turn period
   (eq. 29) of random patterns with different left and right settings.
4. **Single-fin held-out set and Table 4**, as ``python -m pectoral_gym.scaling validate``
   computes them (:mod:`pectoral_gym.scaling.validation.pattern_sets`).

Two seed sets (:data:`SEED_SETS`): ``dev`` to look at while working on the model,
``report`` (other seeds, other two-fin periods) run only for the published figures.

The candidate, measured against the full model at its reference steps, is a model spec named by its
preset (:data:`pectoral_gym.model.spec.PRESETS`; default :data:`DEFAULT_CANDIDATE`, the averaged model
with both corrections): e.g. ``"averaged-env"`` (the cycle averages alone, as the envs run them) or
``"full-fast"`` (the full model's fast integration preset: how far it is from the reference steps).
Output: ``fidelity_<set>[_<preset>].md``, ``.json`` (which records the spec it ran) and PNG plots
(:mod:`pectoral_gym.scaling.validation.fidelity_report`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pectoral_gym import __version__
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.kfunctions import ScalingFunctions, default_scaling_path
from pectoral_gym.model.kloading import held_yaw_damping, select_yaw_damping
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import PRESETS, AveragedSpec, ModelSpec, make_model
from pectoral_gym.scaling.identification.grids import draw_off_grid
from pectoral_gym.scaling.validation.comparison import REST, as_run, label, steady_pair, summarize
from pectoral_gym.scaling.validation.pattern_sets import (
    MIN_TURN_RATE,
    sampling_box,
    single_fin_section,
    table4_section,
)

__all__ = ["DECOMPOSITION", "DEFAULT_CANDIDATE", "DURATION", "FIN_SPLITS", "MIN_PATH", "SCENARIOS", "SEED_SETS",
           "TARGETS", "SeedSet", "draw_patterns", "fidelity", "main", "open_loop", "open_loop_errors", "split_fins"]

#: The candidate of the published report (docs/validation/fidelity): the averaged model with both corrections.
DEFAULT_CANDIDATE = "averaged"
DURATION = 40.0  # s of simulated time per open-loop run
SAMPLE = 0.5  # s between recorded positions (the path length is summed over them)
MIN_PATH = 0.25  # m: floor of the normaliser, so that fish that barely move do not dominate
SCENARIOS = {"constant": None, "every_4s": 4.0, "every_0.5s": 0.5}  # name: seconds between pattern changes
# name: (fins beating, start on the pattern)
DECOMPOSITION = {"one_fin_from_rest": (1, False), "one_fin_on_pattern": (1, True),
                 "two_fins_from_rest": (2, False), "two_fins_on_pattern": (2, True)}
#: name: what the left fin does in the split of each scenario (the right fin keeps its schedule)
FIN_SPLITS = {"one_fin": "at rest", "mirrored": "the right fin's pattern, mirrored"}
TARGETS = {  # docs/scaling.md's targets: (median, p90) of the position error; steady state (median, worst)
    "constant": (0.02, 0.05), "every_4s": (0.03, 0.08), "every_0.5s": (0.05, 0.12),
    "steady": (0.01, 0.05), "single_fin_worst": 0.01, "table4_worst": 0.01,
}


@dataclass(frozen=True)
class SeedSet:
    """One set of seeds and patterns of the benchmark.

    Attributes:
        name: ``"dev"`` or ``"report"``.
        seed: Seed of every random draw of the set.
        steady_periods: Periods [s] the two-fin steady-state patterns draw from (pairs share a short window).
    """

    name: str
    seed: int
    steady_periods: tuple[float, ...]


SEED_SETS = {
    "dev": SeedSet("dev", 12_001, (0.6, 0.75, 0.9, 1.2, 1.5, 1.8)),
    "report": SeedSet("report", 12_777, (0.5, 0.8, 1.0, 1.6, 2.0)),
}
FULL = {"n": 128, "n_steady": 16, "n_single": 60, "table4": 12, "duration": DURATION}
QUICK = {"n": 6, "n_steady": 2, "n_single": 2, "table4": 2, "duration": 6.0}


def draw_patterns(rng: np.random.Generator, n: int, segments: int, ranges: np.ndarray | None = None) -> np.ndarray:
    """Patterns ``(n, segments, 2, 4)`` uniform in ``ranges`` ``(4, 2)`` (default: the envs' action ranges)."""
    ranges = EnvConfig().ranges if ranges is None else np.asarray(ranges, dtype=np.float64)
    return rng.uniform(ranges[:, 0], ranges[:, 1], size=(n, segments, 2, 4))


def split_fins(schedule: np.ndarray, split: str) -> np.ndarray:
    """``schedule`` with the left fin at rest (``"one_fin"``) or on the right fin's patterns (``"mirrored"``)."""
    if split not in FIN_SPLITS:
        raise ValueError(f"split must be one of {sorted(FIN_SPLITS)}, got {split!r}")
    out = schedule.copy()
    out[:, :, 1] = REST if split == "one_fin" else schedule[:, :, 0]
    return out


def open_loop(kind: str | ModelSpec, schedule: np.ndarray, change_every: float | None, duration: float,
              params: FishParams, scaling: ScalingFunctions, on_pattern: bool = False) -> np.ndarray:
    """Poses ``(n, k + 1, 3)`` (X, Y, psi) every :data:`SAMPLE` s of one model under a command schedule.

    Args:
        kind: The model: a spec, a preset name, ``"full"`` (reference steps) or ``"averaged"``
            (:func:`pectoral_gym.scaling.validation.comparison.as_run`, which names the spec it runs).
        schedule: ``(n, segments, 2, 4)`` patterns; segment ``j`` is commanded at ``j * change_every``.
        change_every: Seconds between changes (``None``: the first segment for the whole run).
        duration: Simulated time [s], a multiple of :data:`SAMPLE`.
        params, scaling: Both models' parameters; the averaged model's K.
        on_pattern: Start with the fins on the first pattern (no transitional half-stroke) instead of at rest.
    """
    n = schedule.shape[0]
    model = make_model(kind, n, params, scaling)
    if on_pattern:
        model.reset(right=schedule[:, 0, 0], left=schedule[:, 0, 1])
    else:
        model.reset()
        model.command_array(np.ascontiguousarray(schedule[:, 0]))
    steps = round(duration / SAMPLE)
    every = steps if change_every is None else round(change_every / SAMPLE)
    poses = [model.state[:, :3].copy()]
    for k in range(1, steps + 1):
        model.advance(SAMPLE)
        poses.append(model.state[:, :3].copy())
        if k % every == 0 and k < steps and change_every is not None:
            model.command_array(np.ascontiguousarray(schedule[:, k // every]))
    return np.stack(poses, axis=1)


def open_loop_errors(full: np.ndarray, averaged: np.ndarray) -> dict[str, np.ndarray]:
    """Position error (end distance / max(full path, :data:`MIN_PATH`)), heading error [deg], path length [m]."""
    gap = np.linalg.norm(averaged[:, -1, :2] - full[:, -1, :2], axis=1)
    path = np.sum(np.linalg.norm(np.diff(full[:, :, :2], axis=1), axis=2), axis=1)
    dpsi = np.angle(np.exp(1j * (averaged[:, -1, 2] - full[:, -1, 2])))
    return {"position": gap / np.maximum(path, MIN_PATH), "heading_deg": np.degrees(np.abs(dpsi)),
            "gap_m": gap, "path_m": path}


def _scenario(schedule, change_every, duration, params, scaling, on_pattern=False, keep_paths=0,
              candidate: str | ModelSpec = DEFAULT_CANDIDATE) -> dict[str, Any]:
    # the candidate's poses are kept under "averaged" whichever model it is (steady_pair does the same)
    poses = {slot: open_loop(kind, schedule, change_every, duration, params, scaling, on_pattern)
             for slot, kind in (("full", "full"), ("averaged", candidate))}
    err = open_loop_errors(poses["full"], poses["averaged"])
    labels = [label(s[0]) for s in schedule]
    out = {"n": int(schedule.shape[0]), "change_every_s": change_every, "duration_s": duration,
           "on_pattern": on_pattern, "position": summarize(err["position"], labels),
           "heading_deg": summarize(err["heading_deg"], labels),
           "errors": {k: [float(x) for x in v] for k, v in err.items()}, "first_pattern": labels}
    if keep_paths:
        out["paths"] = {kind: np.round(p[:keep_paths], 5).tolist() for kind, p in poses.items()}
    return out


def _summary_only(stage):
    """``stage`` with its result cut to the summaries (no per-fish errors or labels: the JSON stays small)."""
    return lambda: {k: v for k, v in stage().items() if k not in ("errors", "first_pattern")}


def steady_section(scaling: ScalingFunctions, params: FishParams, n: int, rng: np.random.Generator,
                   periods: tuple[float, ...], candidate: str | ModelSpec = DEFAULT_CANDIDATE) -> dict[str, Any]:
    """Two-fin periodic steady states: speed, turning radius and turn period (radius and period of turning fish)."""
    low, high, grid, _ = sampling_box(scaling)
    beats = np.stack([draw_off_grid(rng, n, low, high, grid, periods) for _ in range(2)], axis=1)
    res = steady_pair(beats, scaling, params, candidate)
    turning = np.abs(res["full"]["omega"]) >= MIN_TURN_RATE
    labels = [label(b) for b in beats]
    rows = [{"pattern": labels[i], "turning": bool(turning[i]), "turns_the_other_way": bool(res["direction_flip"][i]),
             **{f"{m}_{k}": _num(res[m][k][i]) for m in ("full", "averaged") for k in ("speed", "omega", "radius",
                                                                                       "period")},
             **{f"{k}_error": _num(res[f"{k}_error"][i]) for k in ("speed", "radius", "period")}}
            for i in range(n)]
    return {"rows": rows, "n_turning": int(turning.sum()), "min_turn_rate": MIN_TURN_RATE, "periods": list(periods),
            "speed": summarize(res["speed_error"], labels),
            "radius": summarize(np.where(turning, res["radius_error"], np.nan), labels),
            "period": summarize(np.where(turning, res["period_error"], np.nan), labels),
            "flips": int(np.count_nonzero(res["direction_flip"] & turning))}


def _num(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _targets(results: dict[str, Any]) -> list[dict[str, Any]]:
    rows = []
    for name in SCENARIOS:
        med, p90 = TARGETS[name]
        s = results["scenarios"][name]["position"]
        rows += [(f"{name}: position error, median", s["median"], med), (f"{name}: position error, p90", s["p90"], p90)]
    med, worst = TARGETS["steady"]
    for key in ("speed", "radius", "period"):
        s = results["steady"][key]
        rows += [(f"two-fin steady {key}, median", s["median"], med),
                 (f"two-fin steady {key}, worst", s["worst"], worst)]
    for key in ("radius", "period"):
        rows.append((f"single-fin held-out {key}, worst", results["single_fin"][key]["worst"],
                     TARGETS["single_fin_worst"]))
        rows.append((f"Table 4 {key}, worst", results["table4"][key]["worst"], TARGETS["table4_worst"]))
    return [{"check": c, "measured": m, "target": t, "met": m is not None and m <= t} for c, m, t in rows]


def fidelity(scaling: ScalingFunctions, seed_set: str = "dev", out_dir: str | Path = "fidelity",
             params: FishParams | None = None, quick: bool = False, plots: bool = True, progress: bool = True,
             source: str = "<ScalingFunctions>", candidate: str = DEFAULT_CANDIDATE,
             spec: ModelSpec | None = None) -> dict[str, Any]:
    """Run the benchmark on one seed set; write ``fidelity_<set>[_<candidate>].md``, ``.json``, plots to ``out_dir``.

    Args:
        scaling: The averaged model's K (the candidate's yaw damping keeps its section of it).
        seed_set: A key of :data:`SEED_SETS`.
        out_dir: Output folder (created).
        params: Both models' parameters (default: Table 1).
        quick: Test-sized run (:data:`QUICK`); its figures mean nothing.
        plots: Write the PNG plots.
        progress: Show a progress bar over the stages.
        source: Where ``scaling`` came from, for the report.
        candidate: The preset (:data:`pectoral_gym.model.spec.PRESETS`) measured against the full model's
            reference integration; it names the outputs (no suffix for :data:`DEFAULT_CANDIDATE`).
        spec: The candidate's spec when it is not the preset's own (the command line's ``--coefficients``
            file with its yaw damping); ``None``: ``PRESETS[candidate]``.

    Returns:
        The results (the content of the JSON file); ``"spec"`` is the candidate's spec as it ran
        (:meth:`~pectoral_gym.model.spec.ModelSpec.to_dict`).

    Raises:
        ValueError: For an unknown seed set or preset, or K without the section the spec's yaw damping needs.
    """
    from pectoral_gym.scaling.validation import fidelity_report
    if seed_set not in SEED_SETS:
        raise ValueError(f"seed_set must be one of {sorted(SEED_SETS)}, got {seed_set!r}")
    if candidate not in PRESETS:
        raise ValueError(f"candidate must be a model preset, one of {sorted(PRESETS)}, got {candidate!r}")
    spec = PRESETS[candidate] if spec is None else spec
    if isinstance(spec, AveragedSpec):  # K keeps the spec's section only, so that every build runs the spec itself
        scaling = select_yaw_damping(scaling, spec.yaw_damping, source)
    spec = as_run(spec, scaling)
    params = params or FishParams()
    sizes = QUICK if quick else FULL
    seeds = SEED_SETS[seed_set]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n, duration = sizes["n"], sizes["duration"]
    rng = np.random.default_rng(seeds.seed)
    schedules = {name: draw_patterns(rng, n, 1 if every is None else math.ceil(duration / every))
                 for name, every in SCENARIOS.items()}
    base = schedules["constant"]
    one_fin = split_fins(base, "one_fin")
    def run(schedule, every=None, on=False, keep=0):
        return lambda: _scenario(schedule, every, duration, params, scaling, on, keep, spec)

    stages: list[tuple[tuple[str, ...], Any]] = [
        *((("scenarios", name), run(schedules[name], every, keep=4)) for name, every in SCENARIOS.items()),
        *((("decomposition", name), run(base if fins == 2 else one_fin, on=on))
          for name, (fins, on) in DECOMPOSITION.items() if name != "two_fins_from_rest"),
        *((("by_fins", name, split), _summary_only(run(split_fins(schedules[name], split), every)))
          for name, every in SCENARIOS.items() for split in FIN_SPLITS
          if (name, split) != ("constant", "one_fin")),  # that one is decomposition/one_fin_from_rest
        (("steady",), lambda: steady_section(scaling, params, sizes["n_steady"], rng, seeds.steady_periods,
                                             spec)),
        (("single_fin",), lambda: single_fin_section(scaling, params, sizes["n_single"], rng, spec)),
        (("table4",), lambda: table4_section(scaling, params, sizes["table4"], candidate=spec)),
    ]
    results: dict[str, Any] = {"seed_set": seeds.name, "seed": seeds.seed, "quick": quick, "version": __version__,
                               "source": source, "candidate": candidate, "spec": spec.to_dict(),
                               "scenarios": {}, "decomposition": {}, "by_fins": {}, "timing_s": {}}
    start = time.perf_counter()
    bar = tqdm(total=len(stages) + 1, desc=f"fidelity ({seed_set})", unit="stage", disable=not progress)
    for key, run in stages:
        bar.set_postfix_str("/".join(key))
        t0 = time.perf_counter()
        value = run()
        section = results
        for part in key[:-1]:
            section = section.setdefault(part, {})
        section[key[-1]] = value
        results["timing_s"]["/".join(key)] = time.perf_counter() - t0
        bar.update()
    results["decomposition"]["two_fins_from_rest"] = {
        k: v for k, v in results["scenarios"]["constant"].items() if k != "paths"}
    results["by_fins"]["constant"]["one_fin"] = {
        k: v for k, v in results["decomposition"]["one_fin_from_rest"].items() if k not in ("errors", "first_pattern")}
    results["targets"] = _targets(results)
    bar.set_postfix_str("report")
    stem = f"fidelity_{seeds.name}" + ("" if candidate == DEFAULT_CANDIDATE else "_" + candidate.replace("-", "_"))
    results["plots"] = fidelity_report.plots(results, out, stem) if plots else []
    results["timing_s"]["total"] = time.perf_counter() - start
    (out / f"{stem}.json").write_text(json.dumps(results, indent=1, allow_nan=False) + "\n")
    fidelity_report.write_markdown(results, out / f"{stem}.md")
    bar.update()
    bar.close()
    return results


def add_parser(sub) -> None:
    """The ``fidelity`` subcommand of ``pectoral-scaling``."""
    from pectoral_gym.tools.cli_common import examples

    p = sub.add_parser("fidelity", help="a model preset vs the full model with two fins and changing commands",
                       description="Fidelity benchmark: open-loop runs with constant and changing two-fin patterns, "
                       "their decomposition (one fin / two, from rest / on the pattern), each scenario split by "
                       "fins (left fin at rest; mirrored fins), two-fin steady states, the "
                       "single-fin held-out set and Table 4, of a model preset against the full model at its "
                       "reference steps. Writes fidelity_<set>[_<preset>].md, .json (with the spec it ran) and "
                       "PNG plots.",
                       epilog=examples("pectoral-scaling fidelity --quick --out fidelity",
                                       "pectoral-scaling fidelity --set report --candidate averaged-env --out fidelity",
                                       "pectoral-scaling fidelity --coefficients robot_k/scaling_coefficients.json "
                                       "--out robot_fidelity"))
    p.add_argument("--set", dest="seed_set", choices=sorted(SEED_SETS), default="dev",
                   help="seed set: dev (look at it while working) or report (for the published figures only)")
    p.add_argument("--candidate", choices=sorted(PRESETS), default=DEFAULT_CANDIDATE, metavar="PRESET",
                   help="model preset measured against the full model's reference steps (pectoral_gym.model.spec."
                        f"PRESETS: {', '.join(sorted(PRESETS))}; default: %(default)s, the averaged model with "
                        "transitional strokes and ripple offsets; averaged-env: the cycle averages alone)")
    p.add_argument("--coefficients", metavar="PATH", default=None,
                   help=f"scaling coefficients JSON (default: the installed {default_scaling_path().name}); an "
                        "averaged preset then runs with the richest yaw damping the file holds")
    p.add_argument("--out", metavar="DIR", default="fidelity", help="output folder (default: fidelity)")
    p.add_argument("--quick", action="store_true", help="test-sized run (figures not meaningful)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def main(args: argparse.Namespace) -> int:
    """Run ``pectoral-scaling fidelity`` with parsed ``args``; returns 0 (the report says which targets are met)."""
    from pectoral_gym.scaling.validation import fidelity_report
    path = Path(args.coefficients) if args.coefficients else default_scaling_path()
    try:
        scaling = ScalingFunctions.load(path)
    except (OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    source = "the shipped coefficients file" if not args.coefficients else str(path)  # no machine paths in reports
    spec = PRESETS[args.candidate]
    if args.coefficients and isinstance(spec, AveragedSpec):  # as pectoral-fish --scaling FILE
        spec = spec.replace(scaling=args.coefficients, yaw_damping=held_yaw_damping(scaling))
    results = fidelity(scaling, args.seed_set, args.out, quick=args.quick, plots=not args.no_plots,
                       progress=not args.no_progress, source=source, candidate=args.candidate, spec=spec)
    print(fidelity_report.summary_text(results))
    return 0
