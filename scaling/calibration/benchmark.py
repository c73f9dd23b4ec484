"""Calibration figures on emulated robots of known truth: ``python -m pectoral_gym.scaling.calibration.benchmark``.

For each seed: a robot with the uncertain fields drawn +-30 % around Table 1
(:func:`~pectoral_gym.scaling.calibration.synth.perturbed_params`), ``--minutes`` of identification logs, and
held-out logs of ``--held-out`` 40 s open-loop episodes (no walls: the model has none, and 40 s of swimming
does not fit the tank), both written by :func:`~pectoral_gym.scaling.calibration.synth.write_synthetic_log`;
then :func:`~pectoral_gym.scaling.calibration.fit.calibrate` and the held-out check. Prints one row per seed
and writes ``benchmark.json`` in ``--out``. Seeds 1-10 were used while developing; report on others (100+).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from pectoral_gym.runlog import read_run_log
from pectoral_gym.scaling.calibration.fit import CalibrationSettings, calibrate
from pectoral_gym.scaling.calibration.heldout import held_out
from pectoral_gym.scaling.calibration.report import report_dict
from pectoral_gym.scaling.calibration.synth import DEGRADED, Camera, perturbed_params, write_synthetic_log

__all__ = ["main", "run_seed"]

CAMERAS = {"default": Camera(), "degraded": DEGRADED}


def run_seed(seed: int, out: Path, minutes: float = 3.0, camera: Camera | None = None,
             held_out_episodes: int = 5, window: float = 6.0) -> dict:
    """One emulated robot: logs, calibration, held-out check; returns the report dict with the truth."""
    camera = camera or Camera()
    truth = perturbed_params(seed)
    fit_path, held_path = out / f"seed{seed}_fit.jsonl", out / f"seed{seed}_heldout.jsonl"
    write_synthetic_log(fit_path, truth, seed, duration=60.0 * minutes, camera=camera)
    write_synthetic_log(held_path, truth, 10_000 + seed, duration=40.0 * held_out_episodes + 1.0, camera=camera,
                        episode_length=40.0, tank=False)
    cal = calibrate([read_run_log(fit_path)], settings=CalibrationSettings(window=window))
    held = [read_run_log(held_path)]
    report = report_dict(cal, held_out(cal.params, held), held_out(cal.prior, held), truth)
    report["seed"] = seed
    return report


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m pectoral_gym.scaling.calibration.benchmark``."""
    from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name

    p = argparse.ArgumentParser(
        prog=prog_name(None, "pectoral_gym.scaling.calibration.benchmark"), description=__doc__,
        formatter_class=HelpFormatter,
        epilog=examples("python -m pectoral_gym.scaling.calibration.benchmark --seeds 101 102 --minutes 1",
                        "python -m pectoral_gym.scaling.calibration.benchmark --camera degraded --out cal_bench"))
    p.add_argument("--seeds", type=int, nargs="+", default=[101, 102, 103, 104, 105], help="robots, one per seed")
    p.add_argument("--camera", choices=sorted(CAMERAS), default="default",
                   help="default: 1 mm, 0.5 deg, no drops; degraded: 5 mm, 2 deg, 10 %% dropped frames")
    p.add_argument("--minutes", type=float, default=3.0, help="logged robot time to fit [min] (default 3)")
    p.add_argument("--out", type=Path, default=Path("calibration_benchmark"), metavar="DIR", help="output folder")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point (module docstring)."""
    args = build_parser().parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"{'seed':>5} {'wall s':>7} {'worst field %':>14} {'worst ratio %':>14} {'held-out median %':>18} "
          f"{'(prior) %':>10}")
    for seed in args.seeds:
        r = run_seed(seed, args.out, args.minutes, CAMERAS[args.camera])
        rows.append(r)
        worst_field = max(abs(f["error_relative"]) for n, f in r["fields"].items() if not n.startswith("added"))
        worst_ratio = max(abs(c["error_relative"]) for c in r["combinations"].values())
        print(f"{seed:5d} {r['wall_time_s']:7.1f} {100 * worst_field:14.2f} {100 * worst_ratio:14.2f} "
              f"{r['held_out']['median_error_percent']:18.2f} {r['held_out_prior']['median_error_percent']:10.2f}",
              flush=True)
    (args.out / "benchmark.json").write_text(json.dumps(rows, indent=1) + "\n")
    med = np.median([r["held_out"]["median_error_percent"] for r in rows])
    print(f"median over seeds of the held-out median: {med:.2f} %; wall time max "
          f"{max(r['wall_time_s'] for r in rows):.1f} s; {'' if math.isfinite(med) else 'no held-out runs'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
