"""``pectoral-fish step-rate --against DIR``: this checkout's step rates side by side with another checkout's.

A speed claim needs a reference measured in the same run: this machine is shared
and its load changes by the minute. :func:`compare` runs ``python -m pectoral_gym
step-rate --json`` (``bench`` in a checkout too old to know that name) alternately in this
checkout and in ``other`` (e.g. today's
``main`` in a worktree: ``git worktree add ../main-ref main``), ``rounds`` times
each, and keeps each rate's best, so a burst of load slows both alike::

    pectoral-fish step-rate --against ../main-ref --rounds 3 --vector-steps 30

Each run is its own process with ``PYTHONPATH`` set to its checkout, so each
imports its own package (and numba cache). Rates the other checkout does not
measure (an older ``bench``) are reported as missing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["checkout_root", "compare", "format_comparison"]


def checkout_root() -> Path:
    """The folder that holds this ``pectoral_gym`` package (the checkout under test)."""
    return Path(__file__).resolve().parents[2]


def _run(root: Path, bench_args: Sequence[str]) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for name in ("step-rate", "bench"):  # checkouts before 0.2.0 know the subcommand as bench only
        done = subprocess.run([sys.executable, "-m", "pectoral_gym", name, "--json", *bench_args], cwd=root, env=env,
                              capture_output=True, text=True, check=False)
        if not (done.returncode == 2 and "invalid choice" in done.stderr):
            break
    lines = done.stdout.strip().splitlines()
    if not lines:
        raise RuntimeError(f"bench in {root} printed nothing (exit {done.returncode}): {done.stderr.strip()[-500:]}")
    return json.loads(lines[-1])


def _rates(result: dict[str, Any]) -> dict[str, float | None]:
    rates = {f"single: {k}": v for k, v in result.get("single_env", {}).items()}
    envs = result.get("num_envs", {})
    rates.update({f"vector: {k} @ {envs.get(k, '?')}": v for k, v in result.get("vector_env", {}).items()})
    return rates


def compare(other: str | os.PathLike, rounds: int = 3, bench_args: Sequence[str] = (),
            progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Best rates of this checkout and ``other`` over ``rounds`` alternating runs of the benchmark.

    Args:
        other: Root of the other checkout (the folder with its ``pectoral_gym`` package).
        rounds: Runs per checkout, alternating (this, other, this, ...).
        bench_args: Further ``pectoral-fish step-rate`` arguments (``--steps``, ``--vector-steps``, ...).
        progress: Called with a short message before each run.

    Returns:
        ``{"this": path, "other": path, "rows": [{"rate", "this", "other", "ratio"}, ...], "rounds": rounds}``
        with rates in steps/s (env-steps/s for vector envs) and ``ratio = this / other``.

    Raises:
        ValueError: If ``other`` holds no ``pectoral_gym`` package, or ``rounds < 1``.
    """
    other_root = Path(other).resolve()
    if not (other_root / "pectoral_gym" / "__init__.py").is_file():
        raise ValueError(f"{other_root} holds no pectoral_gym package (give the root of a checkout)")
    if rounds < 1:
        raise ValueError(f"rounds must be >= 1, got {rounds}")
    roots = {"this": checkout_root(), "other": other_root}
    best: dict[str, dict[str, float | None]] = {"this": {}, "other": {}}
    say = progress or (lambda _msg: None)
    for r in range(rounds):
        for name, root in roots.items():
            say(f"round {r + 1}/{rounds}: {name} ({root})")
            for key, value in _rates(_run(root, bench_args)).items():
                old = best[name].get(key)
                best[name][key] = value if old is None else (old if value is None else max(old, value))
    rows = []
    for key in dict.fromkeys([*best["this"], *best["other"]]):
        a, b = best["this"].get(key), best["other"].get(key)
        rows.append({"rate": key, "this": a, "other": b, "ratio": a / b if a and b else None})
    return {"this": str(roots["this"]), "other": str(other_root), "rounds": rounds, "rows": rows}


def format_comparison(result: dict[str, Any]) -> str:
    """A table of :func:`compare`'s result for the terminal."""
    def rate(v: float | None) -> str:
        return "missing" if v is None else f"{v:,.0f}"

    lines = [f"this:  {result['this']}", f"other: {result['other']}",
             f"best of {result['rounds']} alternating runs each, steps/s (vector: env-steps/s)",
             f"  {'rate':<58} {'this':>12} {'other':>12} {'this/other':>10}"]
    for row in result["rows"]:
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}x"
        lines.append(f"  {row['rate']:<58} {rate(row['this']):>12} {rate(row['other']):>12} {ratio:>10}")
    return "\n".join(lines)
