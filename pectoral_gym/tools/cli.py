"""The ``pectoral-fish`` command line (also ``python -m pectoral_gym``).

Subcommands::

    pectoral-fish steady   --model full --right 90,20,1,4 [--json]
    pectoral-fish simulate --model full --right 90,20,1,4 --duration 60 --out out [--compare]
    pectoral-fish patterns --out out
    pectoral-fish step-rate [--json] [--quick] [--against DIR]

``demo`` and ``bench`` are the deprecated names of ``patterns`` and ``step-rate`` (until 0.3.0).

Fin patterns are ``G0,GA,TP,ZETA``: bias and amplitude in degrees, period in
seconds, power/recovery ratio; an omitted fin is held at rest. Bad arguments
exit with status 2 and a one-line reason on stderr.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pectoral_gym.model.params import FinBeat
from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name, subcommands
from pectoral_gym.tools.cli_inputs import (
    FIN_HELP,
    MODEL_CHOICES,
    fin_label,
    fin_text,
    format_number,
    model_inputs,
    parse_fin,
    steady_result,
)

__all__ = ["build_parser", "main", "parse_fin"]

def _fins(args: argparse.Namespace, parser: argparse.ArgumentParser) -> tuple[FinBeat | None, FinBeat | None]:
    """``(right, left)`` from ``--right``/``--left``, or exit 2 via ``parser.error``."""
    try:
        return parse_fin(args.right, "--right"), parse_fin(args.left, "--left")
    except ValueError as exc:
        parser.error(str(exc))


def _positive(parser: argparse.ArgumentParser, **values: float) -> None:
    """Exit 2 unless every value is a finite number > 0."""
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0):
            parser.error(f"--{name.replace('_', '-')} must be a finite number > 0, got {value}")


# --------------------------------------------------------------------------- steady


def _model_inputs(args: argparse.Namespace, parser: argparse.ArgumentParser):
    try:
        return model_inputs(args.model, args.params, args.scaling, not args.no_params_check)
    except (ValueError, FileNotFoundError) as error:
        parser.error(str(error))


def _cmd_steady(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    right, left = _fins(args, parser)
    params, spec = _model_inputs(args, parser)
    res = steady_result(args.model, right, left, params, spec)
    if not all(math.isfinite(res[k]) for k in ("vx", "vy", "omega")):
        print(f"error: the {args.model} model gave non-finite velocities for {fin_label(right, left)}",
              file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(res))
        return 0
    turn = "straight" if res["radius"] is None else ("left turn" if res["omega"] > 0 else "right turn")
    rows = [
        ("vx", format_number(res["vx"], ".5f"), "m/s"),
        ("vy", format_number(res["vy"], ".5f"), "m/s"),
        ("omega", format_number(res["omega"], ".5f"), f"rad/s  ({turn})"),
        ("speed", format_number(res["speed"], ".5f"), "m/s"),
        ("radius", format_number(res["radius"], ".4f"), "m"),
        ("period", format_number(res["period"], ".3f"), "s"),
        ("drift angle", format_number(math.degrees(res["drift_angle"]), ".2f"), "deg"),
    ]
    held = "" if spec.model == "full" else f" (scaling {spec.scaling}, forcing {spec.forcing})"
    print(f"steady state, {args.model} model{held}")
    print(f"  right fin    {fin_text(right)}")
    print(f"  left fin     {fin_text(left)}")
    for name, value, unit in rows:
        print(f"  {name:<12} {value:>10}  {unit}")
    if not res["converged"]:
        print("  warning: not converged within the time limit; values are the last window averages")
    return 0


# --------------------------------------------------------------------------- simulate


def _cmd_simulate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from pectoral_gym.tools.simulate import MODELS, plot_trajectories, simulate, write_csv

    right, left = _fins(args, parser)
    _positive(parser, duration=args.duration, sample=args.sample)
    for name in ("x0", "y0", "heading_deg"):
        if not math.isfinite(getattr(args, name)):
            parser.error(f"--{name.replace('_', '-')} must be a finite number, got {getattr(args, name)}")
    if args.duration / args.sample > 10_000_000:
        parser.error("--duration / --sample gives more than 10,000,000 samples; use a larger --sample")
    family = _model_inputs(args, parser)[1].model  # "full" or "averaged"
    models = [args.model] + ([m for m in MODELS if m != family] if args.compare else [])
    out = Path(args.out)
    trajectories = []
    for model in models:
        own = model == args.model  # --scaling is the chosen model's
        params, spec = _model_inputs(argparse.Namespace(**{**vars(args), "model": model,
                                                           "scaling": args.scaling if own else None}), parser)
        traj = simulate(spec, right, left, args.duration, args.x0, args.y0, math.radians(args.heading_deg),
                        args.sample, params=params, progress=True)
        name = "trajectory.csv" if model == args.model else f"trajectory_{model}.csv"
        print(f"wrote {write_csv(traj, out / name)}")
        trajectories.append(traj)
    title = f"{' vs '.join(models)} model, {fin_label(right, left)}"
    print(f"wrote {plot_trajectories(trajectories, out / 'trajectory.png', title=title)}")
    return 0


# --------------------------------------------------------------------------- demo

# name -> (right, left, x0 [m], y0 [m], duration [s]), fins in the paper's units (Table 3 and Table 2
# patterns). The forward swim stops before the far wall; the turns start about one full-model turning
# radius (0.44 m) from the tank's mid-line and run for about one full-model turn, so the circles stay inside.
DEMO_PATTERNS: dict[str, tuple[tuple[float, ...] | None, tuple[float, ...] | None, float, float, float]] = {
    "forward swim": ((100, 12, 0.8, 4), (100, 12, 0.8, 4), 0.25, 0.575, 35.0),
    "right fin: left turn": ((85, 22, 1.0, 4), None, 1.15, 0.14, 60.0),
    "left fin: right turn": (None, (85, 22, 1.0, 4), 1.15, 1.01, 60.0),
}


def _cmd_demo(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from pectoral_gym.tools.simulate import MODELS, plot_panels, simulate

    out = Path(args.out)
    groups: dict[str, list] = {}
    rows: list[dict[str, Any]] = []
    for name, (r, lf, x0, y0, duration) in DEMO_PATTERNS.items():
        right = FinBeat.from_degrees(*r) if r else None
        left = FinBeat.from_degrees(*lf) if lf else None
        panel = groups.setdefault(f"{name}, {duration:g} s", [])
        for model in MODELS:
            traj = simulate(model, right, left, duration, x0, y0, 0.0, 0.05)
            panel.append(traj)
            res = steady_result(model, right, left)
            rows.append({"pattern": name, "model": model, "right": fin_text(right), "left": fin_text(left),
                         "vx": res["vx"], "vy": res["vy"], "omega": res["omega"], "speed": res["speed"],
                         "radius": res["radius"], "period": res["period"],
                         "X_end": traj.state[-1, 0], "Y_end": traj.state[-1, 1]})
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "demo.csv"
    with csv_path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({k: ("" if v is None else v) for k, v in row.items()} for row in rows)
    png = plot_panels(groups, out / "demo.png",
                      title="full (solid) vs averaged (dashed) model, from rest")

    print(f"{'pattern':<22} {'model':<9} {'vx m/s':>8} {'vy m/s':>8} {'omega rad/s':>11} {'radius m':>9} "
          f"{'period s':>9}")
    for row in rows:
        print(f"{row['pattern']:<22} {row['model']:<9} {row['vx']:>8.4f} {row['vy']:>8.4f} {row['omega']:>11.4f} "
              f"{format_number(row['radius'], '.3f'):>9} {format_number(row['period'], '.1f'):>9}")
    print("(steady-state cycle averages; omega > 0 is a left turn)")
    print(f"wrote {csv_path}")
    print(f"wrote {png}")
    return 0


# --------------------------------------------------------------------------- bench


def _cmd_bench(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from pectoral_gym.tools.bench import run_benchmark

    for name in ("steps", "vector_steps", "repeats", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    progress = None if args.json else (lambda msg: print(msg, file=sys.stderr, flush=True))
    if args.against is not None:
        return _bench_against(args, parser, progress)
    res = run_benchmark(args.steps, args.vector_steps, args.repeats, args.seed, args.quick, progress)
    status = 1 if res["errors"] else 0
    if args.json:
        print(json.dumps(res))
        return status
    rate = lambda v: "failed" if v is None else f"{v:>14,.0f}"  # noqa: E731
    print("single env (gymnasium.make), steps/s:")
    for env_id, value in res["single_env"].items():
        print(f"  {env_id:<40} {rate(value)}")
    print("native vector env, env-steps/s:")
    for env_id, value in res["vector_env"].items():
        print(f"  {env_id:<40} {rate(value)}  @ {res['num_envs'][env_id]} envs")
    print("targets:")
    for t in res["targets"].values():
        value = "n/a" if t["value"] is None else (f"{t['value']:.3f}" if t["target"] < 100 else f"{t['value']:,.0f}")
        target = f"{t['target']:g}x" if t["target"] < 100 else f"{t['target']:,.0f}"
        print(f"  {t['what']:<52} {value:>12}  target >= {target:<10} {'met' if t['met'] else 'NOT MET'}")
    for key, msg in res["errors"].items():
        print(f"error in {key}: {msg}", file=sys.stderr)
    if res["settings"]["quick"]:
        print("(--quick: smoke-test sizes, rates are not meaningful)")
    return status


def _bench_against(args: argparse.Namespace, parser: argparse.ArgumentParser, progress) -> int:
    from pectoral_gym.tools.bench_compare import compare, format_comparison

    bench_args = ["--steps", str(args.steps), "--vector-steps", str(args.vector_steps), "--repeats",
                  str(args.repeats), "--seed", str(args.seed)] + (["--quick"] if args.quick else [])
    try:
        res = compare(args.against, args.rounds, bench_args, progress)
    except (ValueError, RuntimeError) as err:
        parser.error(str(err))
    print(json.dumps(res) if args.json else format_comparison(res))
    return 0


# --------------------------------------------------------------------------- parser


def _add_model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", choices=MODEL_CHOICES, default="full", metavar="MODEL",
                   help="full (the blade-element model at converged steps), averaged (the cycle-averaged model with "
                        f"the shipped K), or a preset: {', '.join(MODEL_CHOICES[2:])} (default: %(default)s)")
    p.add_argument("--right", metavar="G0,GA,TP,ZETA", help=f"right {FIN_HELP}")
    p.add_argument("--left", metavar="G0,GA,TP,ZETA", help=f"left {FIN_HELP}")
    p.add_argument("--scaling", default=None, metavar="identified|none|FILE",
                   help="averaged models: scaling functions K: the shipped file, 'none' (K = 1) or a coefficients "
                        "file from `pectoral-scaling identify` (default: the model's, "
                        "identified)")
    p.add_argument("--params", metavar="FILE",
                   help="model parameters: a JSON or YAML file of FishParams fields (others keep Table 1)")
    p.add_argument("--no-params-check", action="store_true",
                   help="averaged model: use K even if its file was identified for other parameters")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-fish`` (each subcommand stores its handler)."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-fish", "pectoral_gym", "pectoral_gym.tools.cli"),
        description="Robotic fish with two rowing pectoral fins: steady states, trajectories, swimming patterns, "
                    "step rates. Fin patterns are G0,GA,TP,ZETA: bias and amplitude [deg], period [s], "
                    "power/recovery ratio; an omitted fin is held at rest.",
        epilog=examples("pectoral-fish steady --model full --right 90,20,1,4",
                        "pectoral-fish simulate --model averaged --right 85,22,1,4 --duration 60 --out out --compare",
                        "pectoral-fish patterns --out out",
                        "pectoral-fish step-rate --quick"),
        formatter_class=HelpFormatter,
    )
    from pectoral_gym import __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = subcommands(parser, dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("steady", help="periodic steady state: velocities, turning radius and period",
                       description="Cycle-averaged periodic steady state from rest (eq. 29). Body frame: x forward, "
                                   "y left, omega > 0 a left turn. The right fin alone turns the fish left.",
                       epilog=examples("pectoral-fish steady --model full --right 90,20,1,4",
                                       "pectoral-fish steady --model averaged --right 90,20,1,4 --left 90,20,1,4 "
                                       "--json"))
    _add_model_options(p)
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (SI units: m/s, rad/s, m, s, rad; radius/period null if straight)")
    p.set_defaults(handler=_cmd_steady, parser=p)

    p = sub.add_parser("simulate", help="simulate a trajectory in the tank; write CSV and PNG",
                       description="Simulate one fish from rest with constant fin patterns. Writes trajectory.csv "
                                   "(t [s], X, Y [m], psi [rad], vx, vy [m/s], omega [rad/s], fin angles [deg]) and "
                                   "trajectory.png (top view in the 2.30 m x 1.15 m tank, velocities over time).",
                       epilog=examples("pectoral-fish simulate --model full --right 90,20,1,4 --duration 60 --out out",
                                       "pectoral-fish simulate --model averaged --left 85,22,1,4 --compare --out out"))
    _add_model_options(p)
    p.add_argument("--duration", type=float, metavar="S", default=60.0,
                   help="simulated time [s] (default: %(default)s)")
    p.add_argument("--x0", type=float, metavar="M", default=1.15,
                   help="initial X in the tank [m] (default: %(default)s)")
    p.add_argument("--y0", type=float, metavar="M", default=0.575,
                   help="initial Y in the tank [m] (default: %(default)s)")
    p.add_argument("--heading-deg", type=float, metavar="DEG", default=0.0,
                   help="initial heading from the tank X axis [deg] (default: %(default)s)")
    p.add_argument("--sample", type=float, metavar="S", default=0.05,
                   help="output sampling interval [s] (default: %(default)s)")
    p.add_argument("--out", default="out", metavar="DIR", help="output directory (default: %(default)s)")
    p.add_argument("--compare", action="store_true",
                   help="also simulate the other model (written to trajectory_<model>.csv) and plot both")
    p.set_defaults(handler=_cmd_simulate, parser=p)

    p = sub.add_parser("patterns", help="illustrative swimming patterns, full vs averaged model",
                       description="Forward swim, right-fin turn and left-fin turn with both models "
                                   "from rest. Writes demo.png and demo.csv, prints a table of steady states. "
                                   "(Not the trained-policy demo, which is pectoral-demo.)",
                       epilog=examples("pectoral-fish patterns", "pectoral-fish patterns --out patterns_out"))
    p.add_argument("--out", default="out", metavar="DIR", help="output directory (default: %(default)s)")
    p.set_defaults(handler=_cmd_demo, parser=p)

    p = sub.add_parser("step-rate", help="step rates of the fish envs against CartPole-v1",
                       description="Single-env step rates through gymnasium.make (averaged, full, CartPole-v1) and "
                                   "native vector-env rates (averaged @ 4096, full @ 1024 envs, averaged with the PPO "
                                   "file's settings), new random actions every step, best of --repeats (round robin) "
                                   "after a warm-up, compared with the project's targets. --against DIR: side by side "
                                   "with another checkout. (The controllers' results table is pectoral-benchmark.)",
                       epilog=examples("pectoral-fish step-rate", "pectoral-fish step-rate --quick --json",
                                       "pectoral-fish step-rate --against ../main --rounds 3"))
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--steps", type=int, metavar="N", default=20_000,
                   help="single-env steps per timed run (default: %(default)s)")
    p.add_argument("--vector-steps", type=int, metavar="N", default=100,
                   help="vector-env batch steps per timed run (default: %(default)s)")
    p.add_argument("--repeats", type=int, metavar="N", default=5,
                   help="timed runs per measurement, best kept (default: %(default)s)")
    p.add_argument("--seed", type=int, metavar="N", default=0, help="seed of the random actions (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="tiny step counts: a smoke test, not a measurement")
    p.add_argument("--against", metavar="DIR", default=None,
                   help="also run the benchmark in the checkout at DIR (e.g. a worktree of main), alternating, "
                        "and print both rates and their ratio")
    p.add_argument("--rounds", type=int, metavar="N", default=3,
                   help="with --against: alternating runs per checkout, best kept (default: %(default)s)")
    p.set_defaults(handler=_cmd_bench, parser=p)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``pectoral-fish`` with ``argv`` (default: ``sys.argv[1:]``).

    Returns:
        The exit status: 0, or 1 if a computation failed (non-finite steady
        state, a benchmark that could not run). Bad arguments raise
        ``SystemExit(2)`` after a one-line reason on stderr.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    return args.handler(args, args.parser)


if __name__ == "__main__":
    raise SystemExit(main())
