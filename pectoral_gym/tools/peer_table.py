"""Side-by-side step rates of the fish and two standard peers, in one run: CartPole, MuJoCo's Swimmer, the fish.

``python -m pectoral_gym.tools.peer_table [--envs N] [--swimmer-envs N] [--steps N] [--vector-steps N]
[--repeats N] [--json]`` prints a markdown table: one row of single-env rates (``gymnasium.make``) and one of
vector rates at ``--envs`` environments, columns ``CartPole-v1``, ``Swimmer-v5``, the latest averaged and full
fish ids, each rate with its ratio to CartPole's in the same row. The vector envs are the native ones
(``vectorization_mode="vector_entry_point"``: the fish's own, gymnasium's ``CartPoleVectorEnv``); Swimmer has
none, so it runs in a ``SyncVectorEnv`` of ``--swimmer-envs`` single envs (its rate per env-step hardly depends
on the count, and thousands of MuJoCo instances cost minutes to build and step), a size the table states.

Timing is :mod:`pectoral_gym.tools.bench`'s: actions pre-generated from the seeded action space (new every
step), a warm-up first (numba's compilation or cache load excluded), passes round robin over all cells so that
load from elsewhere hits every column alike, the best pass kept. Swimmer needs ``mujoco`` (the ``bench`` extra);
without it its column reads ``n/a`` with a note, and the other columns are measured as usual.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

from pectoral_gym.tools.bench import CARTPOLE_ID, _environment, _Timer, single_env_timer, vector_env_timer
from pectoral_gym.versions import LATEST

__all__ = ["COLUMNS", "SWIMMER_ID", "main", "run_table", "to_markdown"]

SWIMMER_ID = "Swimmer-v5"
#: The table's columns, left to right; ratios are to the first.
COLUMNS = (CARTPOLE_ID, SWIMMER_ID, LATEST["averaged"], LATEST["full"])


def _mujoco_missing() -> str | None:
    """Why Swimmer cannot run here, or ``None`` when it can."""
    if importlib.util.find_spec("mujoco") is None:
        return "mujoco is not installed (pip install 'pectoral-gym[bench]'); Swimmer-v5 skipped"
    return None


def run_table(envs: int = 4096, swimmer_envs: int = 64, steps: int = 20_000, vector_steps: int = 30,
              repeats: int = 3, seed: int = 0, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Measure every cell of the table in one process.

    Args:
        envs: Environments of the vector row (native vector envs: CartPole and the fish).
        swimmer_envs: Environments of Swimmer's ``SyncVectorEnv`` in the vector row.
        steps: Single-env steps per timed pass.
        vector_steps: Batch steps per timed pass of a vector env.
        repeats: Timed passes per cell, round robin over the cells; the best is kept.
        seed: Seeds the pre-generated actions and the resets.
        progress: Called with a short message before the warm-up and each pass.

    Returns:
        A JSON-ready dict: ``rows`` (``"single"``, ``"vector"``) each mapping a column to its rate
        [env-steps/s] or ``None``, ``ratios`` (the same, divided by CartPole's rate in that row),
        ``num_envs`` (row -> column -> environment count), ``notes`` (column -> why it is missing),
        ``settings`` and ``environment``.

    Raises:
        ValueError: A size or count below 1.
    """
    import pectoral_gym  # noqa: F401  (registers the fish envs)

    if min(envs, swimmer_envs, steps, vector_steps, repeats) < 1:
        raise ValueError(f"envs, swimmer_envs, steps, vector_steps and repeats must be >= 1, got {envs}, "
                         f"{swimmer_envs}, {steps}, {vector_steps}, {repeats}")
    say = progress or (lambda _msg: None)
    notes: dict[str, str] = {}
    columns = list(COLUMNS)
    missing = _mujoco_missing()
    if missing:
        notes[SWIMMER_ID] = missing
        columns.remove(SWIMMER_ID)
    num_envs = {"single": dict.fromkeys(COLUMNS, 1),
                "vector": {c: swimmer_envs if c == SWIMMER_ID else envs for c in COLUMNS}}
    makers: dict[tuple[str, str], Callable[[], _Timer]] = {}
    for column in columns:
        makers["single", column] = partial(single_env_timer, column, steps, seed)
        mode = "sync" if column == SWIMMER_ID else "vector_entry_point"
        makers["vector", column] = partial(vector_env_timer, column, num_envs["vector"][column], vector_steps,
                                           seed, mode=mode)
    say("warming up (numba compilation or cache load) ...")
    timers: dict[tuple[str, str], _Timer] = {}
    best: dict[tuple[str, str], float] = {}
    try:
        for key, make in makers.items():
            try:
                timers[key] = make()
            except Exception as exc:  # noqa: BLE001 - one cell that cannot run is noted, the others go on
                notes.setdefault(key[1], f"{key[0]}: {type(exc).__name__}: {exc}")
        for rep in range(repeats):
            say(f"pass {rep + 1}/{repeats}")
            for key, timer in timers.items():
                best[key] = max(best.get(key, 0.0), timer.run())
    finally:
        for timer in timers.values():
            timer.close()
    rows = {row: {c: best.get((row, c)) for c in COLUMNS} for row in ("single", "vector")}
    ratios = {row: {c: (rate / rates[CARTPOLE_ID] if rate is not None and rates[CARTPOLE_ID] else None)
                    for c, rate in rates.items()} for row, rates in rows.items()}
    return {"rows": rows, "ratios": ratios, "num_envs": num_envs, "notes": notes,
            "settings": {"envs": envs, "swimmer_envs": swimmer_envs, "steps": steps, "vector_steps": vector_steps,
                         "repeats": repeats, "seed": seed},
            "environment": _environment()}


def _rate(rate: float | None) -> str:
    """A rate as k/s or M/s."""
    if rate is None:
        return "n/a"
    return f"{rate / 1e6:.2f} M/s" if rate >= 1e6 else f"{rate / 1e3:.1f} k/s"


def to_markdown(result: dict[str, Any]) -> str:
    """The table of :func:`run_table`'s result: rates with ratios to CartPole, then the notes."""
    lines = ["| envs | " + " | ".join(COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for row, label in (("single", "1"), ("vector", f"{result['settings']['envs']} (native vector)")):
        cells = []
        for c in COLUMNS:
            rate, ratio = result["rows"][row][c], result["ratios"][row][c]
            cell = _rate(rate) + (f" ({ratio:.3g}x)" if ratio is not None and c != CARTPOLE_ID else "")
            if row == "vector" and c == SWIMMER_ID:
                cell += f" @ {result['num_envs']['vector'][c]} envs, SyncVectorEnv"
            cells.append(cell)
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("Env-steps per second, best of each cell's passes; in brackets: ratio to CartPole-v1 in the same row.")
    lines += [f"Note: {c}: {why}" for c, why in result["notes"].items()]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: print the table (or ``--json``); exit 2 with a one-line reason on bad arguments."""
    parser = argparse.ArgumentParser(prog="python -m pectoral_gym.tools.peer_table",
                                     description=__doc__.split("\n", 1)[0])
    parser.add_argument("--envs", type=int, default=4096, help="envs of the native vector row (default: %(default)s)")
    parser.add_argument("--swimmer-envs", type=int, default=64,
                        help="Swimmer's SyncVectorEnv size in the vector row (default: %(default)s)")
    parser.add_argument("--steps", type=int, default=20_000, help="single-env steps per pass (default: %(default)s)")
    parser.add_argument("--vector-steps", type=int, default=30,
                        help="vector batch steps per pass (default: %(default)s)")
    parser.add_argument("--repeats", type=int, default=3, help="passes per cell, best kept (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and resets (default: %(default)s)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    args = parser.parse_args(argv)
    try:
        result = run_table(args.envs, args.swimmer_envs, args.steps, args.vector_steps, args.repeats, args.seed,
                           progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    except ValueError as exc:
        print(f"peer_table: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2) if args.json else to_markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
