"""Validation of the averaged model against the full model (``python -m pectoral_gym.scaling validate``).

The averaged model with given scaling functions K is compared with the full
blade-element model on fin patterns the identification never saw
(:mod:`pectoral_gym.scaling.validation.pattern_sets`):

1. the 12 patterns of the paper's Table 4, on the **left** fin as the table
   writes them (K is identified on the right fin, so this also tests the
   mirror symmetry): turning radius and period;
2. seeded random single-fin patterns (right fin) inside the identification
   grid's ranges intersected with the environments' default action ranges, off
   the grid: radius and period;
3. the forward-swimming sweep of Fig. 4 (both fins (95 deg, 15 deg, 1/f, 4),
   f = 0.25 ... 2.75 Hz): speed;
4. seeded random two-fin patterns with different left and right settings:
   radius, period, speed, and position after 60 s from rest.

Relative error = ``|averaged - full| / |full|`` of the cycle-averaged periodic
steady state (eq. 29). Results go to ``report.md``, ``validation.json`` and PNG
plots (:mod:`pectoral_gym.scaling.validation.plots`); the report reading guide is
``docs/scaling-validation.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pectoral_gym import __version__
from pectoral_gym.model.kfunctions import ScalingFunctions, default_scaling_path
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import make_model
from pectoral_gym.scaling.validation import plots as rendering
from pectoral_gym.scaling.validation.comparison import REST, fin_pattern, label, simulate_xy
from pectoral_gym.scaling.validation.pattern_sets import (
    MIN_AMPLITUDE,
    MIN_RATIO,
    MIN_TURN_RATE,
    SWEEP_FREQUENCIES,
    TABLE4,
    sampling_box,
    single_fin_section,
    sweep_section,
    table4_section,
    two_fin_section,
)
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name

__all__ = ["QUICK", "TARGETS", "add_arguments", "build_parser", "main", "validate"]

FIG5_PATTERNS = ((85, 22, 1, 4), (90, 22, 1, 3), (60, 20, 1, 4))  # left fin; the first is the paper's Fig. 5
FIG5_DURATION = 90.0  # s: long enough for the full model to close most of a circle
TARGETS = {
    "table4_radius_max": 0.02,
    "table4_period_max": 0.02,
    "single_median": 0.02,
    "single_worst": 0.05,
    "sweep_speed_max": 0.02,
}
QUICK = {"n_single": 6, "n_two": 4, "frequencies": (0.5, 1.0, 2.0), "table4": 4}


def _params_differ(identified: Any, params: FishParams) -> list[str] | None:
    """Model parameters whose value in the coefficients' metadata differs from ``params`` (None: not recorded)."""
    if not isinstance(identified, dict):
        return None
    ours = dataclasses.asdict(params)
    return sorted(k for k, v in identified.items()
                  if k in ours and not (isinstance(v, (int, float)) and math.isclose(v, ours[k], rel_tol=1e-9)))


def _targets(results: dict[str, Any]) -> list[dict[str, Any]]:
    checks = [
        ("Table 4 radius error, worst", results["table4"]["radius"]["worst"], TARGETS["table4_radius_max"]),
        ("Table 4 period error, worst", results["table4"]["period"]["worst"], TARGETS["table4_period_max"]),
        ("Single-fin radius error, median", results["single_fin"]["radius"]["median"], TARGETS["single_median"]),
        ("Single-fin period error, median", results["single_fin"]["period"]["median"], TARGETS["single_median"]),
        ("Single-fin radius error, worst", results["single_fin"]["radius"]["worst"], TARGETS["single_worst"]),
        ("Single-fin period error, worst", results["single_fin"]["period"]["worst"], TARGETS["single_worst"]),
        ("Table 4 patterns turning the other way (share)", results["table4"]["flips"]["share"], 0.0),
        ("Single-fin patterns turning the other way (share)", results["single_fin"]["flips"]["share"], 0.0),
        ("Forward sweep speed error, worst", results["sweep"]["speed"]["worst"], TARGETS["sweep_speed_max"]),
    ]
    return [{"check": name, "measured": value, "target": target, "met": value is not None and value <= target}
            for name, value, target in checks]


def validate(
    scaling: ScalingFunctions,
    params: FishParams | None = None,
    out_dir: str | Path = "scaling_validation",
    n_single: int = 60,
    n_two: int = 30,
    seed: int = 0,
    quick: bool = False,
    plots: bool = True,
    source: str = "<ScalingFunctions>",
    progress: bool = True,
) -> dict[str, Any]:
    """Run every validation stage, write ``report.md``, ``validation.json`` and plots into ``out_dir``.

    Args:
        scaling: The K functions under test (the averaged model's).
        params: Model parameters of both models (default: Table 1).
        out_dir: Output folder (created).
        n_single, n_two: Numbers of random single-fin and two-fin patterns.
        seed: Seed of the random patterns.
        quick: Small sizes for tests and CI (:data:`QUICK`); results are not meaningful as figures.
        plots: Write the PNG plots.
        source: Where ``scaling`` came from, for the report.
        progress: Show a progress bar over the stages.

    Returns:
        The results (the content of ``validation.json``).
    """
    if n_single < 1 or n_two < 1:
        raise ValueError(f"n_single and n_two must be >= 1, got {n_single} and {n_two}")
    params = params or FishParams()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    if quick:
        n_single, n_two = min(n_single, QUICK["n_single"]), min(n_two, QUICK["n_two"])
    frequencies = QUICK["frequencies"] if quick else SWEEP_FREQUENCIES
    stages = [
        ("table4", lambda: table4_section(scaling, params, QUICK["table4"] if quick else len(TABLE4))),
        ("single_fin", lambda: single_fin_section(scaling, params, n_single, rng)),
        ("sweep", lambda: sweep_section(scaling, params, frequencies)),
        ("two_fin", lambda: two_fin_section(scaling, params, n_two, rng)),
    ]
    results: dict[str, Any] = {
        "source": source, "metadata_status": scaling.metadata.get("status"), "is_unit": scaling.is_unit,
        "params_differ": _params_differ(scaling.metadata.get("model_parameters", scaling.metadata.get("params")),
                                        params),
        "seed": seed, "quick": quick, "version": __version__, "targets": {}, "timing_s": {},
        "exclusions": {"min_amplitude_deg": math.degrees(MIN_AMPLITUDE), "min_ratio": MIN_RATIO,
                       "two_fin_min_turn_rate": MIN_TURN_RATE},
    }
    start = time.perf_counter()
    bar = tqdm(total=len(stages) + 2, desc="validate", unit="stage", disable=not progress)
    for name, run in stages:
        bar.set_postfix_str(name)
        t0 = time.perf_counter()
        results[name] = run()
        results["timing_s"][name] = time.perf_counter() - t0
        bar.update()
    results["targets"] = _targets(results)
    bar.set_postfix_str("plots")
    t0 = time.perf_counter()
    results["plots"] = _plots(scaling, params, results, out) if plots else []
    results["timing_s"]["plots"] = time.perf_counter() - t0
    bar.update()
    results["timing_s"]["total"] = time.perf_counter() - start
    bar.set_postfix_str("report")
    (out / "validation.json").write_text(json.dumps(results, indent=1, allow_nan=False) + "\n")
    rendering.write_report(results, out / "report.md")
    bar.update()
    bar.close()
    return results


def _plots(scaling: ScalingFunctions, params: FishParams, results: dict[str, Any], out: Path) -> list[str]:
    beats = np.array([[REST, fin_pattern(*p)] for p in FIG5_PATTERNS])
    paths = {kind: simulate_xy(make_model(kind, len(beats), params, scaling), beats,
                                     FIG5_DURATION)
             for kind in ("full", "averaged")}
    low, high, _, _ = sampling_box(scaling)
    files = [
        rendering.plot_k_surfaces(scaling, out / "k_surfaces.png", low, high),
        rendering.plot_speed_sweep(results["sweep"]["rows"], out / "forward_sweep.png"),
        rendering.plot_trajectories(paths["full"], paths["averaged"], [label(b) for b in beats],
                                out / "trajectories.png"),
        rendering.plot_single_fin_errors(results["single_fin"]["rows"], out / "single_fin_errors.png"),
    ]
    return [f.name for f in files]


DESCRIPTION = ("Validate the averaged model (given K) against the full model: Table 4, random single-fin patterns "
               "off the grid, the Fig. 4 forward sweep, random two-fin patterns. Writes report.md, validation.json "
               "and PNG plots.")


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``pectoral-scaling validate`` to ``parser`` (and return it)."""
    parser.add_argument("--coefficients", metavar="PATH", default=None,
                        help=f"scaling coefficients JSON (default: the installed {default_scaling_path().name})")
    parser.add_argument("--params", metavar="FILE", default=None,
                        help="model parameters of both models: a JSON or YAML file of FishParams fields "
                             "(default: Table 1); the report flags a difference from the coefficients' own")
    parser.add_argument("--out", metavar="DIR", default="scaling_validation", help="output folder")
    parser.add_argument("--n-single", type=int, default=60, metavar="N", help="random single-fin patterns")
    parser.add_argument("--n-two", type=int, default=30, metavar="N", help="random two-fin patterns")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random patterns")
    parser.add_argument("--quick", action="store_true", help="small sizes for tests and CI")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of ``python -m pectoral_gym.scaling.validation.validate`` (``pectoral-scaling validate``)."""
    return add_arguments(argparse.ArgumentParser(
        prog=prog_name(None, "pectoral_gym.scaling.validation.validate"), description=DESCRIPTION,
        formatter_class=HelpFormatter, epilog=EXAMPLES))


EXAMPLES = examples("pectoral-scaling validate --quick --out scaling_validation",
                    "pectoral-scaling validate --coefficients robot_k/scaling_coefficients.json --params robot.json "
                    "--out robot_validation")


def run(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run the validation with parsed ``args``; bad input exits 2 through ``parser.error``."""
    from pectoral_gym.model.params import load_params

    if args.n_single < 1 or args.n_two < 1:
        parser.error(f"--n-single and --n-two must be >= 1, got {args.n_single} and {args.n_two}")
    path = Path(args.coefficients) if args.coefficients else default_scaling_path()
    try:
        params = load_params(args.params) if args.params else None
        scaling = ScalingFunctions.load(path)
    except (OSError, ValueError) as err:
        parser.error(str(err))
    source = "the shipped coefficients file" if not args.coefficients else str(path)  # no machine paths in reports
    results = validate(scaling, params=params, out_dir=args.out, n_single=args.n_single, n_two=args.n_two,
                       seed=args.seed, quick=args.quick, plots=not args.no_plots, source=source,
                       progress=not args.no_progress)
    print(rendering.summary_text(results, Path(args.out)))
    return 0


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns 0 (also when targets are missed: the report says which)."""
    parser = build_parser()
    return run(parser.parse_args(argv), parser)


if __name__ == "__main__":
    raise SystemExit(main())
