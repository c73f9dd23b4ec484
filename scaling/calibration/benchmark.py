"""Calibration figures on emulated robots of known truth: ``python -m pectoral_gym.scaling.calibration.benchmark``.

For each seed: a robot with the uncertain fields drawn +-30 % around Table 1
(:func:`~pectoral_gym.scaling.calibration.synth.perturbed_params`), ``--minutes`` of identification logs, and
held-out logs of ``--held-out`` 40 s open-loop episodes (no walls: the model has none, and 40 s of swimming
does not fit the tank), both written by :func:`~pectoral_gym.scaling.calibration.synth.write_synthetic_log`;
then :func:`~pectoral_gym.scaling.calibration.fit.calibrate` and the held-out check. Prints one row per seed
and a summary line, and writes in ``--out``: ``benchmark.json`` (a list, one calibration report per seed,
:func:`~pectoral_gym.scaling.calibration.report.report_dict` with the truth, plus ``seed`` and ``coverage``) and
``summary.json`` (the summary line's figures). Coverage: the share of the reported 68 % and 95 % intervals
(+-1 and +-1.96 standard errors, in log terms) that hold the truth, over every field (standard error with the
prior) and every ratio of :data:`~pectoral_gym.scaling.calibration.identifiability.COMBINATIONS` (from the logs
alone) of every seed. Seeds 1-10 were used while developing; report on others (100+).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from pectoral_gym.runlog import read_run_log
from pectoral_gym.scaling.calibration.fit import CalibrationSettings, calibrate
from pectoral_gym.scaling.calibration.heldout import held_out
from pectoral_gym.scaling.calibration.identifiability import ASYMMETRY_FIELDS
from pectoral_gym.scaling.calibration.report import report_dict
from pectoral_gym.scaling.calibration.synth import (
    DEGRADED,
    Camera,
    asymmetric_params,
    perturbed_params,
    write_synthetic_log,
)

__all__ = ["main", "run_seed"]

CAMERAS = {"default": Camera(), "degraded": DEGRADED}


def run_seed(seed: int, out: Path, minutes: float = 3.0, camera: Camera | None = None,
             held_out_episodes: int = 5, window: float = 6.0, tick_aligned: bool = True,
             asymmetric: bool = False) -> dict:
    """One emulated robot: logs, calibration, held-out check (none for ``held_out_episodes=0``).

    ``tick_aligned=False``: the emulated firmware ticks at other instants than the PC's replay, as on a real robot
    (:func:`~pectoral_gym.scaling.calibration.synth.write_synthetic_log`): model error lasting many frames.
    ``asymmetric``: the robot's fins differ (:func:`~pectoral_gym.scaling.calibration.synth.asymmetric_params`) and
    the fit takes the asymmetry too, as ``calibrate --asymmetric``.

    Returns the report dict with the truth, the seed and its ``coverage`` (:func:`interval_scores`).
    """
    camera = camera or Camera()
    truth = perturbed_params(seed)
    settings = CalibrationSettings(window=window)
    if asymmetric:
        truth = asymmetric_params(seed, truth)
        settings = CalibrationSettings(window=window, fields=settings.fields + ASYMMETRY_FIELDS)
    fit_path, held_path = out / f"seed{seed}_fit.jsonl", out / f"seed{seed}_heldout.jsonl"
    write_synthetic_log(fit_path, truth, seed, duration=60.0 * minutes, camera=camera, tick_aligned=tick_aligned)
    cal = calibrate([read_run_log(fit_path)], settings=settings)
    if held_out_episodes > 0:
        write_synthetic_log(held_path, truth, 10_000 + seed, duration=40.0 * held_out_episodes + 1.0,
                            camera=camera, episode_length=40.0, tank=False, tick_aligned=tick_aligned)
        held = [read_run_log(held_path)]
        report = report_dict(cal, held_out(cal.params, held), held_out(cal.prior, held), truth)
    else:
        report = report_dict(cal, truth=truth)
    report["seed"] = seed
    report["coverage"] = interval_scores(report)
    return report


def interval_scores(report: dict) -> dict[str, dict[str, float]]:
    """Each reported quantity's error in standard errors, ``log(fitted / truth) / s.e.``, of a report with a truth.

    Returns ``{"reported": {name: z}, "gauss_newton": {name: z}}`` over the fields (``std_error_relative``: logs
    and prior) and the ratios (``data_std_error_relative``: logs alone); ``gauss_newton`` only when the report
    carries those standard errors for comparison.
    """
    scores: dict[str, dict[str, float]] = {"reported": {}}
    gn = report.get("gauss_newton")
    if gn:
        scores["gauss_newton"] = {}
    for name, f in report["fields"].items():
        if "error_rad" in f:  # an offset: fitted additively, its error and standard error in rad
            scores["reported"][name] = f["error_rad"] / f["std_error_rad"]
            if gn:
                scores["gauss_newton"][name] = f["error_rad"] / gn["std_error"][name]
            continue
        error = math.log1p(f["error_relative"])
        scores["reported"][name] = error / f["std_error_relative"]
        if gn:
            scores["gauss_newton"][name] = error / gn["std_error"][name]
    for name, c in report["combinations"].items():
        if c["data_std_error_relative"] == 0.0:
            continue  # a ratio of fields held at known values: not estimated
        error = math.log1p(c["error_relative"])
        scores["reported"][name] = error / c["data_std_error_relative"]
        if gn:
            scores["gauss_newton"][name] = error / gn["combination_se"][name]
    return scores


def coverage(rows: list[dict], which: str = "reported", names: tuple[str, ...] | None = None) -> dict[str, float]:
    """Share of the 68 % and 95 % intervals holding the truth over ``rows`` (:func:`interval_scores`), and the worst.

    ``names``: only these quantities (``None``: every field and ratio).
    """
    z = np.abs([v for r in rows if which in r["coverage"] for name, v in r["coverage"][which].items()
                if names is None or name in names])
    if not len(z):
        return {}
    return {"intervals": int(len(z)), "covered_68": float(np.mean(z <= 1.0)), "covered_95": float(np.mean(z <= 1.96)),
            "worst_z": float(np.max(z))}


def summary(rows: list[dict]) -> dict:
    """The figures of the benchmark's summary line (``summary.json``)."""
    held = [r["held_out"]["median_error_percent"] for r in rows if r.get("held_out", {}).get("episodes")]
    return {
        "robots": len(rows),
        "worst_coefficient_error": max(abs(f["error_relative"]) for r in rows for n, f in r["fields"].items()
                                       if not n.startswith("added") and "error_relative" in f),
        "worst_offset_error_deg": max((math.degrees(abs(f["error_rad"])) for r in rows for f in r["fields"].values()
                                       if "error_rad" in f), default=None),
        "worst_ratio_error": max(abs(c["error_relative"]) for r in rows for c in r["combinations"].values()),
        "held_out_median_percent": float(np.median(held)) if held else None,
        "not_converged": [r["seed"] for r in rows if not r.get("converged", True)],
        "wall_time_max_s": max(r["wall_time_s"] for r in rows),
        "coverage": coverage(rows), "coverage_gauss_newton": coverage(rows, "gauss_newton"),
        "coverage_asymmetry": coverage(rows, names=ASYMMETRY_FIELDS),
    }


def summary_line(s: dict) -> str:
    """One line: what the benchmark found over all robots."""
    cov, gn = s["coverage"], s["coverage_gauss_newton"]
    held = "no held-out runs" if s["held_out_median_percent"] is None else \
        f"held-out median {s['held_out_median_percent']:.2f} % of path"
    line = (f"{s['robots']} robots: worst coefficient {100 * s['worst_coefficient_error']:.1f} %, worst ratio "
            f"{100 * s['worst_ratio_error']:.1f} %; {held}; intervals holding the truth {100 * cov['covered_68']:.0f} %"
            f" (68 % nominal) and {100 * cov['covered_95']:.0f} % (95 %) of {cov['intervals']}, worst "
            f"{cov['worst_z']:.1f} s.e.")
    if gn:
        line += f" (Gauss-Newton s.e.: {100 * gn['covered_68']:.0f} % and {100 * gn['covered_95']:.0f} %)"
    asym = s.get("coverage_asymmetry")
    if asym:
        line += (f"; the fins' asymmetry: {100 * asym['covered_68']:.0f} % and {100 * asym['covered_95']:.0f} % of "
                 f"{asym['intervals']}, worst {asym['worst_z']:.1f} s.e., worst offset "
                 f"{s['worst_offset_error_deg']:.2f} deg")
    not_converged = s["not_converged"]
    return line + (f"; not converged: seeds {' '.join(map(str, not_converged))}" if not_converged else
                   "; every fit converged") + f"; fit wall time <= {s['wall_time_max_s']:.0f} s"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m pectoral_gym.scaling.calibration.benchmark``."""
    from pectoral_gym.tools.cli_common import HelpFormatter, add_seeds_argument, examples, prog_name

    p = argparse.ArgumentParser(
        prog=prog_name(None, "pectoral_gym.scaling.calibration.benchmark"), description=__doc__,
        formatter_class=HelpFormatter,
        epilog=examples("python -m pectoral_gym.scaling.calibration.benchmark --seeds 101 102 --minutes 1",
                        "python -m pectoral_gym.scaling.calibration.benchmark --camera degraded --out cal_bench"))
    add_seeds_argument(p, [101, 102, 103, 104, 105], "robots, one per seed (default 101-105)")
    p.add_argument("--camera", choices=sorted(CAMERAS), default="default",
                   help="default: 1 mm, 0.5 deg, no drops; degraded: 5 mm, 2 deg, 10 %% dropped frames")
    p.add_argument("--minutes", type=float, default=3.0, help="logged robot time to fit [min] (default 3)")
    p.add_argument("--unaligned", action="store_true",
                   help="the emulated firmware ticks at other instants than the PC's replay, as on a real robot "
                        "(model error lasting many frames; default: on the replay's tick grid)")
    p.add_argument("--held-out", type=int, default=5, metavar="N",
                   help="held-out 40 s episodes per robot (default 5; 0: none, for coverage runs)")
    p.add_argument("--asymmetric", action="store_true",
                   help="robots whose fins differ (left fin's force +-30 %%, servo offsets +-0.1 rad), fitted as "
                        "pectoral-scaling calibrate --asymmetric")
    p.add_argument("--out", type=Path, default=Path("calibration_benchmark"), metavar="DIR", help="output folder")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point (module docstring)."""
    args = build_parser().parse_args(argv)
    if args.minutes <= 0 or args.held_out < 0:
        print("error: --minutes must be > 0 and --held-out >= 0", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"{'seed':>5} {'wall s':>7} {'worst field %':>14} {'worst ratio %':>14} {'held-out median %':>18} "
          f"{'(prior) %':>10} {'worst |z|':>10}")
    for seed in args.seeds:
        r = run_seed(seed, args.out, args.minutes, CAMERAS[args.camera], args.held_out,
                     tick_aligned=not args.unaligned, asymmetric=args.asymmetric)
        rows.append(r)
        worst_field = max(abs(f["error_relative"]) for n, f in r["fields"].items()
                          if not n.startswith("added") and "error_relative" in f)
        worst_ratio = max(abs(c["error_relative"]) for c in r["combinations"].values())
        held = [r.get(k, {}).get("median_error_percent") for k in ("held_out", "held_out_prior")]
        held_text = " ".join(f"{'-' if v is None else f'{v:.2f}':>{w}}" for v, w in zip(held, (18, 10), strict=True))
        print(f"{seed:5d} {r['wall_time_s']:7.1f} {100 * worst_field:14.2f} {100 * worst_ratio:14.2f} {held_text} "
              f"{max(map(abs, r['coverage']['reported'].values())):10.1f}"
              f"{'' if r.get('converged', True) else '  (not converged)'}", flush=True)
        (args.out / "benchmark.json").write_text(json.dumps(rows, indent=1) + "\n")  # each seed: a partial run counts
    figures = summary(rows)
    (args.out / "summary.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(summary_line(figures))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
