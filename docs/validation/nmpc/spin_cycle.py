"""Find the NMPC's on-the-spot turn (``agents.nmpc_spin.SPIN_CYCLE``) and check it on the full model.

A cross-entropy search on the averaged model (``pectoral_gym.AveragedModel``: identified K, with its
transitional strokes, docs/model.md 3.7) over cycles of four control periods (0.5 s each) of both
fins' bias and amplitude, at the NMPC's fixed period (0.5 s) and ratio (5). From rest, each cycle is
repeated for 6 s; the score is the heading gained (a left turn) minus 30 per metre by which the
centre of mass strays more than 8 cm from its start, minus ``--work-weight`` [1/J] times the fin work
of the strokes swept (default 0). The best cycle is printed in the FinInputs order
of ``agents.nmpc_spin`` (amplitude right/left, bias right/left, degrees), then the turn it gives on
both models, from rest and after 5 s of straight swimming, from each phase of the cycle::

    PYTHONPATH=. python docs/validation/nmpc/spin_cycle.py [--work-weight 1.0]    # a few seconds

Output of 2026-12-02: the cycle below (``SPIN_CYCLE`` holds it rounded to 0.1 deg); from rest at
phase 0, averaged model 180 deg within 0.08 m, full model 147 deg within 0.09 m; from the other
phases and from swimming (0.11 m/s) the full model turns 143-152 deg in 6 s (displacement up to
0.28 m, mostly the glide), the averaged model 18-22 % more. The fin work of those 6 s (strokes
swept) is 1.6 J; ``--work-weight`` 0.5 / 1 / 2 give cycles of 0.86 / 0.44 / 0.11 J that turn the full
model 136 / 119 / 86 deg (the last lines print the searched cycle's turn and work; the shipped one is the
default search's). The 1 J^-1 cycle in the NMPC (development seeds 100-199, ``agents.evaluate``): 0.98 /
0.96 success (full / randomised), 12.8 / 13.7 s to the goal, 1.05 / 1.06 J swept, against 1.00 / 0.99,
8.3 / 8.4 s, 1.52 / 1.63 J with the shipped cycle: not kept.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from agents.nmpc_spin import SPIN_CYCLE
from pectoral_gym.models import AveragedModel, FullModel

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


def search(seed: int = 0, population: int = 2000, elite: int = 100, iterations: int = 25,
           work_weight: float = 0.0) -> np.ndarray:
    """The best cycle ``(CYCLE, 2, 4)`` of the cross-entropy search (right fin first, model units)."""
    rng = np.random.default_rng(seed)
    shape = (CYCLE, 2, 4)
    mean, spread = (LOW + HIGH) / 2 * np.ones(shape), (HIGH - LOW) / 2 * np.ones(shape)
    for _ in range(iterations):
        cycles = np.clip(mean + spread * rng.standard_normal((population, *shape)), LOW, HIGH)
        states, work = run(AveragedModel, cycles, with_work=True)
        stray = np.hypot(states[:, :, 0], states[:, :, 1]).max(0)
        score = states[-1, :, 2] - 30.0 * np.maximum(stray - 0.08, 0.0) - work_weight * work
        best = cycles[np.argsort(-score)[:elite]]
        mean, spread = best.mean(0), best.std(0) + 1e-3 * (HIGH - LOW)
    return best[0]


def main() -> None:
    """Print the searched cycle and the shipped cycle's turns on both models."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work-weight", type=float, default=0.0, help="price of the swept fin work [1/J]")
    parser.add_argument("--iterations", type=int, default=25, help="cross-entropy iterations")
    args = parser.parse_args()
    cycle = search(iterations=args.iterations, work_weight=args.work_weight)
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
