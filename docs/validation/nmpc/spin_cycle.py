"""Find the NMPC's on-the-spot turn (``pectoral_gym.agents.nmpc.spin.SPIN_CYCLE``) and check it on the full model.

A cross-entropy search on the averaged model (``pectoral_gym.AveragedModel``: identified K, with its
transitional strokes, docs/model.md 3.7) over cycles of four control periods (0.5 s each) of both
fins' bias and amplitude, at the NMPC's fixed period (0.5 s) and ratio (5). From rest, each cycle is
repeated for 6 s; the score is the heading gained (a left turn) minus 30 per metre by which the
centre of mass strays more than 8 cm from its start, minus 100 per unit by which the robot's servo
rules would change the cycle (:func:`servo_excess`; off with ``--no-servo-limits``), minus
``--work-weight`` [1/J] times the fin work of the strokes swept (default 0). The best cycle is printed
in the FinInputs order of ``pectoral_gym.agents.nmpc.spin`` (amplitude right/left, bias right/left, degrees), then
the turn the shipped cycle gives on both models, from rest and after 5 s of straight swimming, from
each phase of the cycle, and the searched cycle's turn and fin work::

    PYTHONPATH=. python docs/validation/nmpc/spin_cycle.py                      # ~15 s: the shipped cycle
    PYTHONPATH=. python docs/validation/nmpc/spin_cycle.py --no-servo-limits --population 2000 --iterations 25

Output with the defaults: the shipped cycle (``SPIN_CYCLE`` holds it rounded to 0.1 deg), servo
excess 0; full model 89-93 deg in 6 s from rest within 0.06-0.12 m, 92-100 deg from swimming at
0.11 m/s (displacement up to 0.28 m, mostly the glide); the averaged model about 10 % more; fin work
0.16 J. The second command finds the faster cycle of docs/notes/2026-12-01-nmpc-rounds.md ("Goal, fifth round"): full
model 143-152 deg, averaged 18-22 % more, fin work 1.6 J, servo excess 2.4 (the robot would stretch
its strokes). Without servo limits, ``--work-weight`` 0.5 / 1 / 2 (30 iterations) give cycles of 0.86 /
0.44 / 0.11 J that turn the full model 136 / 119 / 86 deg.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from pectoral_gym.agents.nmpc.spin import SPIN_CYCLE
from pectoral_gym.model.finrules import stretch_transition
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.servo import ServoLimits, clip_beats

STEPS, DT, CYCLE = 12, 0.5, 4
LOW = np.array([math.radians(45), 0.0, 0.5, 5.0])  # bias, amplitude, period, ratio of one fin
HIGH = np.array([math.radians(135), math.radians(30), 0.5, 5.0])


def run(model: type, cycles: np.ndarray, warm: np.ndarray | None = None, with_work: bool = False):
    """States ``(STEPS, n, 6)`` under the cycles ``(n, CYCLE, 2, 4)`` from rest (or after ``warm`` for 5 s).

    With ``with_work`` also the fin work ``(n,)`` [J] of the strokes swept under the cycles.
    """
    m = model(n=len(cycles))
    m.reset()
    start = np.zeros((len(cycles), 6))
    if warm is not None:
        for _ in range(10):
            m.command_array(warm)
            m.advance(DT)
        start = m.state.copy()
    out, before = [], m.fin_work().sum(1)
    for k in range(STEPS):
        m.command_array(cycles[:, k % CYCLE])
        m.advance(DT)
        out.append(m.state - start)
    return (np.array(out), m.fin_work().sum(1) - before) if with_work else np.array(out)


def servo_excess(cycles: np.ndarray, limits: ServoLimits | None = None) -> np.ndarray:
    """How far the robot's servo rules would change each cycle ``(n, CYCLE, 2, 4)`` (0: executed as commanded).

    Sums what :mod:`pectoral_gym.hardware.radio.firmware` would do to each step of the repeated cycle: clipping (peak
    fin rate of the regular strokes), period stretching of the transitional half-stroke from either turning point
    of the previous step into either half-stroke of the next (the robot's ``max_speed``), and the excess of
    each parameter's change over ``max_rate`` times the control period.
    """
    limits = limits or ServoLimits()
    excess = np.zeros(len(cycles))
    for i, cycle in enumerate(cycles):
        for k in range(CYCLE):
            before, beats = cycle[k - 1], cycle[k]
            clipped = clip_beats(beats, limits)[0]
            excess[i] += np.abs(clipped - beats).sum()
            for turn in (before[:, 0] - before[:, 1], before[:, 0] + before[:, 1]):
                for power in (False, True):
                    excess[i] += np.abs(stretch_transition(clipped, turn, np.full(2, power), limits) - clipped).sum()
            excess[i] += np.maximum(np.abs(beats - before) - np.asarray(limits.max_rate) * DT, 0.0).sum()
    return excess


def search(seed: int = 0, population: int = 1500, elite: int = 100, iterations: int = 30,
           work_weight: float = 0.0, servo_limits: bool = True) -> np.ndarray:
    """The best cycle ``(CYCLE, 2, 4)`` of the cross-entropy search (right fin first, model units).

    With ``servo_limits`` a cycle pays 100 per unit of :func:`servo_excess`: the search keeps to cycles the
    robot's servos execute as commanded.
    """
    rng = np.random.default_rng(seed)
    shape = (CYCLE, 2, 4)
    mean, spread = (LOW + HIGH) / 2 * np.ones(shape), (HIGH - LOW) / 2 * np.ones(shape)
    for _ in range(iterations):
        cycles = np.clip(mean + spread * rng.standard_normal((population, *shape)), LOW, HIGH)
        states, work = run(AveragedModel, cycles, with_work=True)
        stray = np.hypot(states[:, :, 0], states[:, :, 1]).max(0)
        score = states[-1, :, 2] - 30.0 * np.maximum(stray - 0.08, 0.0) - work_weight * work
        if servo_limits:
            score -= 100.0 * servo_excess(cycles)
        best = cycles[np.argsort(-score)[:elite]]
        mean, spread = best.mean(0), best.std(0) + 1e-3 * (HIGH - LOW)
    return best[0]


def main() -> None:
    """Print the searched cycle and the shipped cycle's turns on both models."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work-weight", type=float, default=0.0, help="price of the swept fin work [1/J]")
    parser.add_argument("--iterations", type=int, default=30, help="cross-entropy iterations")
    parser.add_argument("--population", type=int, default=1500, help="cycles drawn per iteration")
    parser.add_argument("--no-servo-limits", action="store_true",
                        help="search without the robot's servo rules (pectoral_gym.hardware.radio.firmware)")
    args = parser.parse_args()
    cycle = search(population=args.population, iterations=args.iterations, work_weight=args.work_weight,
                   servo_limits=not args.no_servo_limits)
    print(f"servo excess of the searched cycle: {servo_excess(cycle[None])[0]:.3g}")
    print("cycle (amplitude right, amplitude left, bias right, bias left) [deg]:")
    for row in cycle:
        print("   ", np.round(np.degrees([row[0, 1], row[1, 1], row[0, 0], row[1, 0]]), 1).tolist())
    shipped = np.zeros((CYCLE, 2, 4))
    shipped[:, 0, :2] = SPIN_CYCLE[:, [2, 0]]
    shipped[:, 1, :2] = SPIN_CYCLE[:, [3, 1]]
    shipped[:, :, 2:] = (0.5, 5.0)
    phases = np.array([np.roll(shipped, -p, axis=0) for p in range(CYCLE)])
    warm = np.zeros((CYCLE, 2, 4))
    warm[:] = (math.radians(90), math.radians(20), 0.5, 5.0)
    print("the shipped SPIN_CYCLE, 6 s: turn [deg] / largest distance from the start [m]")
    for label, w in (("rest", None), ("swimming", warm)):
        full, avg = run(FullModel, phases, w), run(AveragedModel, phases, w)
        for p in range(CYCLE):
            f = f"{math.degrees(full[-1, p, 2]):6.1f} / {np.hypot(full[:, p, 0], full[:, p, 1]).max():.3f}"
            a = f"{math.degrees(avg[-1, p, 2]):6.1f} / {np.hypot(avg[:, p, 0], avg[:, p, 1]).max():.3f}"
            print(f"  from {label:8s} phase {p}: full {f}   averaged {a}")
    for name, model in (("full", FullModel), ("averaged", AveragedModel)):
        states, work = run(model, cycle[None], with_work=True)
        print(f"the searched cycle from rest, {name}: turn {math.degrees(states[-1, 0, 2]):.1f} deg, "
              f"fin work {work[0]:.3f} J")


if __name__ == "__main__":
    main()
