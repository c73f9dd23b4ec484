"""``pectoral-scaling calibrate``: the model's uncertain parameters from run logs."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

__all__ = ["add_parser", "main"]

EXAMPLES = """examples:
  pectoral-scaling calibrate --logs run1.jsonl run2.jsonl --out robot.json
  pectoral-scaling calibrate --logs run1.jsonl --hold-out run2.jsonl --params measured.json \\
      --out robot.json --report calibration/
  pectoral-scaling calibrate --logs run1.jsonl --fields drag_coef,moment_coef,fin_force_coef \\
      --out robot.json
  pectoral-scaling calibrate --logs run1.jsonl --params measured.json --asymmetric --out robot.json

The logs are run logs (docs/run-log.md). robot.json is a parameters file (load_params) for
pectoral-scaling identify --params, training and deploy. The report folder gets report.json, report.md
and paths.png (measured against simulated paths). docs/calibration.md explains the fit and its figures.
"""


def add_parser(sub) -> None:
    """The ``calibrate`` subcommand of ``pectoral-scaling``."""
    from pectoral_gym.scaling.calibration.fit import CalibrationSettings
    from pectoral_gym.tools.cli_common import HelpFormatter

    defaults = CalibrationSettings()
    p = sub.add_parser(
        "calibrate", help="fit the uncertain FishParams fields from run logs",
        description="Fit the physically uncertain FishParams fields (added masses and inertia, drag, lift, moment "
        "and fin force coefficients) from recorded runs: the full model under the logged commands, its fins "
        "replayed by the firmware's rules, compared with the camera's poses over short windows (windowed "
        "shooting, robust least squares). Reports standard errors, what the logs cannot tell apart, and a "
        "held-out open-loop check. (pectoral-camera-calibrate is the camera's calibration, not this.)",
        epilog=EXAMPLES, formatter_class=HelpFormatter)
    p.add_argument("--logs", nargs="+", required=True, metavar="RUN", help="run logs to fit (docs/run-log.md)")
    p.add_argument("--out", type=Path, required=True, help="the calibrated parameters file to write (JSON)")
    p.add_argument("--params", metavar="KNOWN", default=None,
                   help="FishParams fields you measured (JSON/YAML); they are held fixed, as are the logs' "
                        "known_params (default: Table 1 for the rest)")
    p.add_argument("--hold-out", nargs="*", default=[], metavar="RUN",
                   help="logs kept out of the fit for the open-loop check (episodes of at least 0.9 x --horizon)")
    p.add_argument("--report", type=Path, default=None,
                   help="folder for report.json, report.md and paths.png (default: beside --out, <out>_report)")
    p.add_argument("--fields", default=None,
                   help="comma-separated fields to fit (default: the uncertain ones not given as known: "
                        f"{','.join(defaults.fields)})")
    p.add_argument("--asymmetric", action="store_true",
                   help="also fit how the fins differ: the left fin's force relative to the right one's "
                        "(fin_force_scale_left) and each fin's servo offset (fin_angle_offset_right/left)")
    p.add_argument("--window", type=float, default=defaults.window,
                   help=f"shooting window [s] (default {defaults.window})")
    p.add_argument("--prior-sigma", type=float, default=defaults.prior_sigma,
                   help=f"prior standard deviation of each log-parameter (default {defaults.prior_sigma})")
    p.add_argument("--max-evaluations", type=int, default=defaults.max_nfev, metavar="N",
                   help=f"most model evaluations of the fit (default {defaults.max_nfev}); a fit that stops there "
                        "says so")
    p.add_argument("--horizon", type=float, default=40.0, help="open-loop span of the held-out check [s] (default 40)")
    p.add_argument("--no-plots", action="store_true", help="no paths.png")


def _named_fields(path: Path) -> set[str]:
    """The field names a parameters file gives (``load_params`` has checked it)."""
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        return set(yaml.safe_load(path.read_text()) or {})
    return set(json.loads(path.read_text()))


def main(args: argparse.Namespace) -> int:
    """Run ``calibrate`` with parsed ``args``; 0 on success, 2 for bad input."""
    from pectoral_gym.model.params import PARAMS_FIELDS, load_params, params_dict, save_params
    from pectoral_gym.runlog import RunLogError, read_run_log
    from pectoral_gym.scaling.calibration.fit import CalibrationSettings, calibrate, prior_params
    from pectoral_gym.scaling.calibration.heldout import held_out
    from pectoral_gym.scaling.calibration.identifiability import ASYMMETRY_FIELDS
    from pectoral_gym.scaling.calibration.report import markdown, not_converged_text, plot_paths, report_dict

    if not (args.window > 0 and args.prior_sigma > 0 and args.horizon > 0 and args.max_evaluations > 0):
        print("error: --window, --prior-sigma, --horizon and --max-evaluations must be > 0", file=sys.stderr)
        return 2
    try:
        logs = [read_run_log(path) for path in args.logs]
        held = [read_run_log(path) for path in args.hold_out]
        known = params_dict(load_params(args.params)) if args.params else {}
        if args.params:  # only the fields the file names are known
            known = {k: v for k, v in known.items() if k in _named_fields(Path(args.params))}
        prior, known_names = prior_params(logs, known)
        fields = tuple(f.strip() for f in args.fields.split(",")) if args.fields else tuple(
            f for f in CalibrationSettings().fields if f not in known_names)
        if args.asymmetric:
            fields += tuple(f for f in ASYMMETRY_FIELDS if f not in fields and f not in known_names)
        bad = sorted(set(fields) - set(PARAMS_FIELDS))
        if bad or not fields:
            raise ValueError(f"--fields: unknown FishParams fields {bad}" if bad else "no field left to fit")
    except (OSError, ValueError, RunLogError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    np.seterr(all="ignore")
    settings = CalibrationSettings(fields=fields, window=args.window, prior_sigma=args.prior_sigma,
                                   max_nfev=args.max_evaluations)
    print(f"fitting {', '.join(fields)} to {len(logs)} log(s), {sum(log.duration for log in logs):.0f} s")
    cal = calibrate(logs, prior, settings)
    runs = held_out(cal.params, held, args.horizon) if held else []
    prior_runs = held_out(prior, held, args.horizon) if held else []
    report = report_dict(cal, runs if held else None, prior_runs if held else None)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_params(cal.params, args.out)
    folder = args.report or args.out.with_name(args.out.stem + "_report")
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    (folder / "report.md").write_text(markdown(report))
    if not args.no_plots:
        plot_paths(cal, runs, folder / "paths.png")
    print(markdown(report))
    print(f"wrote {args.out} and {folder}/report.json, report.md{'' if args.no_plots else ', paths.png'}")
    code = 0
    if not cal.converged:
        print(f"warning: {not_converged_text(cal.nfev, cal.remaining_step)}", file=sys.stderr)
    if held and not runs:
        longest = max((float(ep.pose_t[-1] - ep.pose_t[0]) for log in held for ep in log.episodes
                       if len(ep.pose_t) > 1), default=0.0)
        print(f"error: nothing was checked: no held-out episode has {0.9 * args.horizon:.0f} s of poses (0.9 x "
              f"--horizon; the longest has {longest:.0f} s). Pass a shorter --horizon (at most "
              f"{math.floor(longest / 0.9)} s here), or log longer held-out episodes (more --max-episode-steps on "
              "the deploy; an episode also ends at the tank's walls).", file=sys.stderr)
        code = 2
    return code
