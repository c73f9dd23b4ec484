"""Command line: ``pectoral-scaling identify|fidelity|yaw-balance|validate|calibrate``.

Also ``python -m pectoral_gym.scaling``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import time
from pathlib import Path

import numpy as np

from pectoral_gym.model.kfunctions import K_NAMES, default_scaling_path
from pectoral_gym.scaling.calibration import cli as calibration_cli
from pectoral_gym.scaling.identification.grids import GRIDS, GridError, load_grid
from pectoral_gym.scaling.validation import fidelity, validate, yaw_balance
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name, subcommands

__all__ = ["build_parser", "main"]

# ``identify --quick``: the settings it overrides (with ``grid="quick"``).
QUICK_IDENTIFY = {"horizon": 3.0, "folds": 2, "max_degree": 1, "holdout": 12, "jobs": 1, "yaw_damping": "paper",
                  "no_progress": True}
_QUICK_TEXT = " ".join(f"--{k.replace('_', '-')} {v}" if v is not True else f"--{k.replace('_', '-')}"
                       for k, v in QUICK_IDENTIFY.items())


def _identify_parser(sub) -> None:
    p = sub.add_parser(
        "identify",
        help="identify K by full-model runs, NMPC and regression",
        description="Identify the scaling functions K_fx, K_fy, K_m (paper Sec. 4.3): full-model steady states on a "
        "grid of right-fin patterns, one NMPC per pattern, then the closed form: cross-validated polynomials "
        "and tensor-product cubic splines compete on off-grid held-out patterns.",
        epilog=examples("pectoral-scaling identify --quick --out k_quick",
                        "pectoral-scaling identify --params robot.json --out robot_k",
                        "pectoral-scaling identify --grid env --jobs 2 --out scaling_identification --install"),
    )
    p.add_argument("--grid", default="env", help=f"preset ({', '.join(GRIDS)}) or a grid JSON file (default: env)")
    p.add_argument("--out", type=Path, default=Path("scaling_identification"), help="output folder (default: "
                   "%(default)s)")
    p.add_argument("--params", metavar="FILE", default=None,
                   help="model parameters of the robot: a JSON or YAML file of FishParams fields (others keep "
                        "Table 1); recorded in the coefficients file's metadata (default: Table 1)")
    p.add_argument("--install", action="store_true", help="also install the coefficients as the package default")
    p.add_argument("--horizon", type=float, default=10.0, help="NMPC horizon T [s] (default 10)")
    p.add_argument("--sampling", type=float, default=1.0, help="NMPC sampling interval t_s [s] (default 1)")
    p.add_argument("--q", type=float, default=2000.0, help="stage weight Q = q I3 (default 2000)")
    p.add_argument("--q-terminal", type=float, default=80.0, help="terminal weight Q_T = q I3 (default 80)")
    p.add_argument("--substeps", type=int, default=0, help="RK4 steps per sampling interval (0: automatic)")
    p.add_argument("--max-degree", type=int, default=7, help="highest polynomial degree tried (default 7)")
    p.add_argument("--fit-target", type=float, default=2e-3,
                   help="held-out accuracy a closed form must reach (predicted relative velocity error, default 0.002)")
    p.add_argument("--holdout", type=int, default=60,
                   help="off-grid patterns on which polynomial and spline forms compete (default 60; 0: polynomial)")
    p.add_argument("--turn-target", type=float, default=0.02,
                   help="worst held-out turning radius / period error a form must reach (default 0.02)")
    p.add_argument("--yaw-damping", choices=("oscillation", "paper"), default="oscillation",
                   help="averaged model's yaw damping: its mean over a sinusoidal in-beat yaw oscillation "
                        "(default; beyond the paper, needs a tensor grid), or the paper's c4 w|w|")
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds (default 5)")
    p.add_argument("--seed", type=int, default=0, help="seed of the CV folds (default 0)")
    p.add_argument("--jobs", type=int, default=0, help="NMPC worker processes (default 0: all cores)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--quick", action="store_true",
                   help="smoke run in seconds (tests, CI, trying the command): overrides --grid with the 12-pattern "
                        f"'quick' grid and sets {_QUICK_TEXT}; the file records metadata['quick'] (K not meant for "
                        "use; refuses --install)")


def _write_table(result, path: Path) -> None:
    usable = result.usable
    reasons: dict[tuple[int, str], str] = {(f["pattern"], f["K"]): f["reason"] for f in result.flags}
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["bias_deg", "amplitude_deg", "period_s", "ratio", "vx", "vy", "omega", "radius", "turn_period",
                    *K_NAMES, *(f"{k}_oracle" for k in K_NAMES), *(f"{k}_flag" for k in K_NAMES),
                    "yaw_oscillation", "yaw_phase"])
        for i, p in enumerate(result.grid.patterns):
            w.writerow([
                f"{math.degrees(p[0]):.6g}", f"{math.degrees(p[1]):.6g}", f"{p[2]:.6g}", f"{p[3]:.6g}",
                *(f"{v:.9g}" for v in result.reference.velocities[i]),
                f"{result.reference.radius[i]:.9g}", f"{result.reference.turn_period[i]:.9g}",
                *(f"{v:.9g}" for v in result.k_nmpc[i]), *(f"{v:.9g}" for v in result.k_oracle[i]),
                *("" if usable[i, j] else reasons.get((i, K_NAMES[j]), "flagged") for j in range(3)),
                f"{result.reference.yaw_oscillation[i]:.9g}", f"{result.reference.yaw_phase[i]:.9g}",
            ])


def _run_identify(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from pectoral_gym.model.params import FishParams, load_params
    from pectoral_gym.scaling.identification.identify import identify
    from pectoral_gym.scaling.identification.nmpc import IdentificationNmpcSettings

    if args.quick:
        if args.install:
            parser.error("--quick identifies a K that is not meant for use; it cannot be --install'ed")
        args.grid = "quick"
        for key, value in QUICK_IDENTIFY.items():
            setattr(args, key, value)
    try:
        grid = load_grid(args.grid)
        settings = IdentificationNmpcSettings(args.horizon, args.sampling, args.q, args.q_terminal, args.substeps)
        params = load_params(args.params) if args.params else FishParams()
    except (GridError, ValueError, FileNotFoundError) as err:
        parser.error(str(err))
    if (args.max_degree < 0 or args.folds < 2 or args.jobs < 0 or not args.fit_target > 0 or args.holdout < 0
            or not args.turn_target > 0):
        parser.error("need --max-degree >= 0, --folds >= 2, --jobs >= 0, --fit-target > 0, --holdout >= 0, "
                     "--turn-target > 0")
    print(f"grid {grid.name!r}: {len(grid)} right-fin patterns")
    start = time.perf_counter()
    result = identify(grid, params, settings, args.max_degree, args.folds, args.seed, args.jobs, not args.no_progress,
                      args.fit_target, args.holdout, args.turn_target, args.yaw_damping)
    total = time.perf_counter() - start
    args.out.mkdir(parents=True, exist_ok=True)
    coefficients = args.out / "scaling_coefficients.json"
    if args.quick:
        result.scaling.metadata["quick"] = True  # a smoke run: its K is not meant for use
    result.scaling.save(coefficients)
    _write_table(result, args.out / "patterns.csv")
    (args.out / "flags.json").write_text(json.dumps(result.flags, indent=1) + "\n")
    print("\nstage times: " + ", ".join(f"{k} {v:.1f} s" for k, v in result.timings.items()) + f"; total {total:.1f} s")
    gaps = result.scaling.metadata["oracle_max_relative_gap"]
    print("NMPC vs algebraic solution, largest relative gap: " + ", ".join(f"{k} {v:.1e}" for k, v in gaps.items()))
    by_k = result.scaling.metadata["flags"]["by_K"]
    flagged = ", ".join(f"{k} {v}" for k, v in by_k.items())
    print(f"flagged (left out of the fit): {flagged}  (see {args.out / 'flags.json'})")
    print(f"\n{'K':5} {'features':34} {'degree':>6} {'terms':>5} {'R^2':>9} {'CV rmse':>9} {'CV max':>9}")
    for name, fit in result.fits.items():
        print(f"{name:5} {fit.features:34} {fit.degree:6d} {len(fit.coefs):5d} {fit.r2:9.6f} {fit.cv_rmse:9.2e} "
              f"{fit.cv_max:9.2e}")
    print("(CV errors are predicted relative speed / yaw-rate errors; "
          "see pectoral_gym.scaling.identification.regression)")
    if result.splines:
        nodes = "x".join(str(len(n)) for n in result.splines[K_NAMES[0]].nodes)
        spread = max(f.period_spread for f in result.splines.values())
        print(f"spline: {nodes} nodes (bias x amplitude x 1/ratio); largest K difference between periods {spread:.1e}")
    if any("radius_worst" in c for c in result.comparison.values()):
        print(f"\nheld-out turning errors ({args.holdout} off-grid patterns), median / worst:")
        for form, c in result.comparison.items():
            print(f"  {form:10} {c['coefficients']:6d} coefficients {c['multiplications']:5d} mult/eval   "
                  f"radius {100 * c['radius_median']:.2f} % / "
                  f"{100 * c['radius_worst']:.2f} %   period {100 * c['period_median']:.2f} % / "
                  f"{100 * c['period_worst']:.2f} %")
    print(f"chosen: {result.chosen}")
    print(f"\nwrote {coefficients}, {args.out / 'patterns.csv'}, {args.out / 'flags.json'}")
    if args.install:
        target = default_scaling_path()
        result.scaling.save(target)
        print(f"installed as the package default: {target}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-scaling`` (each subcommand stores its parser as ``parser``)."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-scaling", "pectoral_gym.scaling", "pectoral_gym.scaling.cli"),
        description="Identify (paper Sec. 4.3) and validate the scaling functions K of the averaged model; "
                    "calibrate the model's parameters from run logs.",
        formatter_class=HelpFormatter,
        epilog=examples("pectoral-scaling identify --quick --out k_quick",
                        "pectoral-scaling validate --quick --out scaling_validation",
                        "pectoral-scaling fidelity --quick --out fidelity",
                        "pectoral-scaling calibrate --logs run1.jsonl run2.jsonl --out robot.json"),
    )
    sub = subcommands(parser, dest="command", metavar="COMMAND", required=True)
    _identify_parser(sub)
    fidelity.add_parser(sub)
    yaw_balance.add_parser(sub)
    validate.add_arguments(sub.add_parser(
        "validate", help="averaged (identified K) against full on held-out patterns",
        description=validate.DESCRIPTION, epilog=validate.EXAMPLES))
    calibration_cli.add_parser(sub)
    for each in sub.choices.values():
        each.set_defaults(parser=each)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m pectoral_gym.scaling`` and ``pectoral-scaling``."""
    args = build_parser().parse_args(argv)
    np.seterr(all="ignore")
    if args.command == "validate":
        return validate.run(args, args.parser)
    if args.command == "calibrate":
        return calibration_cli.main(args)
    if args.command == "yaw-balance":
        return yaw_balance.main(args)
    return fidelity.main(args) if args.command == "fidelity" else _run_identify(args, args.parser)


if __name__ == "__main__":
    raise SystemExit(main())
