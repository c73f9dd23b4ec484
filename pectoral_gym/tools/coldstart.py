"""Cold-start figures: ``import pectoral_gym`` and the first step of a fish env with an empty numba cache.

``python -m pectoral_gym.tools.coldstart [--rounds N] [--env ID] [--json]`` runs, per round, each
measurement in a fresh interpreter (one after another, never two at once), side by side with
Gymnasium's ``CartPole-v1`` in the same run:

* ``import``: ``import pectoral_gym`` (which registers the envs, and imports Gymnasium to do so)
  against ``import gymnasium``;
* ``first step, empty cache``: import, ``gymnasium.make``, ``reset(seed=0)`` and one ``step`` of the
  fish env with ``NUMBA_CACHE_DIR`` set to a new empty folder, as on a fresh install, a CI run or a
  new machine: the kernels come from the bundle the package ships (:mod:`pectoral_gym.model.kernel_bundle`)
  or compile (wall time, and the process's CPU time: on a machine shared with other jobs the CPU
  time is the steadier figure);
* ``... no bundle``: the same with ``PECTORAL_GYM_KERNEL_BUNDLE=0``: every kernel the step needs compiles;
* ``first step, warm cache``: the same in a new interpreter with the cache the previous run filled.

It prints the least and the largest value over the rounds and the project's targets (:data:`TARGETS`);
``--json`` also gives each round's values and ``os.getloadavg()`` at the start and the end. Timings belong
here, in a benchmark, not in the unit tests (which check structure: ``tests/test_cold_start.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from typing import Any

from pectoral_gym.model.kernel_bundle import BUNDLE_SETTING

__all__ = ["TARGETS", "measure", "main"]

#: The issue's targets [s]: ``import pectoral_gym`` and the first step of the recommended env with an empty cache.
TARGETS = {"import": 0.3, "first_step_empty_cache": 3.0}

_IMPORT = """
import json, time
t0 = time.perf_counter()
import {module}
print(json.dumps({{"seconds": time.perf_counter() - t0}}))
"""

_FIRST_STEP = """
import json, sys, time
t0, c0 = time.perf_counter(), time.process_time()
import gymnasium as gym
if sys.argv[1].startswith("PectoralFish"):
    import pectoral_gym  # noqa: F401 - registers the ids
t1 = time.perf_counter()
env = gym.make(sys.argv[1])
env.reset(seed=0)
action = env.action_space.sample()
t2 = time.perf_counter()
env.step(action)
t3, c3 = time.perf_counter(), time.process_time()
compiled = loaded = 0
if "numba" in sys.modules:  # the package's kernels and any other numba function: compiled or loaded from a cache
    import gc
    from numba.core.dispatcher import Dispatcher
    for dispatcher in [d for d in gc.get_objects() if isinstance(d, Dispatcher) and d._cache.cache_path]:
        compiled += sum(dispatcher.stats.cache_misses.values())
        loaded += sum(dispatcher.stats.cache_hits.values())
print(json.dumps({"seconds": t3 - t0, "cpu": c3 - c0, "import": t1 - t0, "make_reset": t2 - t1, "step": t3 - t2,
                  "compiled": compiled, "loaded": loaded}))
"""


def _run(code: str, *args: str, cache_dir: str | None = None, bundle: bool = True,
         checkout: str | None = None) -> dict[str, float]:
    env = dict(os.environ)
    env.pop(BUNDLE_SETTING, None)
    if checkout is not None:  # that checkout's package first on the path (run from a neutral folder)
        env["PYTHONPATH"] = os.pathsep.join([os.path.abspath(checkout), *filter(None, [env.get("PYTHONPATH")])])
    if not bundle:
        env[BUNDLE_SETTING] = "0"
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    done = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, check=False,
                          cwd=tempfile.gettempdir())
    if done.returncode != 0:
        raise RuntimeError(f"the measurement failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def measure(env_id: str = "PectoralFish-Averaged-v2", rounds: int = 3, checkout: str | None = None) -> dict[str, Any]:
    """The cold-start figures of ``env_id`` and ``CartPole-v1`` over ``rounds`` rounds (module docstring).

    ``checkout``: measure the package of that checkout (its root first on ``PYTHONPATH``), e.g. an older one.

    Returns:
        ``{"env_id", "rounds", "load": [start, end], "results": {name: [one dict per round]}}``; the names are
        ``import_fish``, ``import_gymnasium``, ``empty_cache`` (with the kernel bundle), ``no_bundle`` (empty cache,
        ``PECTORAL_GYM_KERNEL_BUNDLE=0``: every kernel compiles), ``warm_cache`` (the cache ``no_bundle`` filled)
        and ``cartpole``.
    """
    if rounds < 1:
        raise ValueError(f"rounds must be >= 1, got {rounds}")
    results: dict[str, list[dict[str, float]]] = {
        name: [] for name in ("import_fish", "import_gymnasium", "empty_cache", "no_bundle", "warm_cache", "cartpole")}
    load = [os.getloadavg()[0]]
    for _ in range(rounds):
        results["import_fish"].append(_run(_IMPORT.format(module="pectoral_gym"), checkout=checkout))
        results["import_gymnasium"].append(_run(_IMPORT.format(module="gymnasium"), checkout=checkout))
        with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
            results["empty_cache"].append(_run(_FIRST_STEP, env_id, cache_dir=cache, checkout=checkout))
        with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
            results["no_bundle"].append(_run(_FIRST_STEP, env_id, cache_dir=cache, bundle=False, checkout=checkout))
            results["warm_cache"].append(_run(_FIRST_STEP, env_id, cache_dir=cache, bundle=False, checkout=checkout))
        results["cartpole"].append(_run(_FIRST_STEP, "CartPole-v1", checkout=checkout))
    load.append(os.getloadavg()[0])
    return {"env_id": env_id, "rounds": rounds, "load": load, "checkout": checkout, "results": results}


def _span(rows: Sequence[dict[str, float]], key: str = "seconds") -> str:
    values = sorted(row[key] for row in rows)
    low, high = values[0], values[-1]
    return f"{low:.2f} s" if f"{low:.2f}" == f"{high:.2f}" else f"{low:.2f}-{high:.2f} s"


def table(measured: dict[str, Any]) -> str:
    """The figures of :func:`measure` as a Markdown table (least-largest over the rounds)."""
    r = measured["results"]

    def kernels(name: str) -> str:
        counts = sorted({(int(row["compiled"]), int(row["loaded"])) for row in r[name]})
        return ", ".join(f"{c} compiled, {k} loaded" for c, k in counts)

    lines = [
        f"| {measured['rounds']} rounds | {measured['env_id']} | CartPole-v1 | target |",
        "|---|---|---|---|",
        f"| import (`pectoral_gym` / `gymnasium`) | {_span(r['import_fish'])} | {_span(r['import_gymnasium'])} "
        f"| <= {TARGETS['import']} s |",
        f"| first step, empty numba cache (import + make + reset + step) | {_span(r['empty_cache'])} "
        f"| {_span(r['cartpole'])} | <= {TARGETS['first_step_empty_cache']} s |",
        f"| ... its CPU time | {_span(r['empty_cache'], 'cpu')} | {_span(r['cartpole'], 'cpu')} | |",
        f"| ... kernels | {kernels('empty_cache')} | - | |",
        f"| first step, empty cache, no bundle (`{BUNDLE_SETTING}=0`) | {_span(r['no_bundle'])} "
        f"| {_span(r['cartpole'])} | |",
        f"| ... its CPU time | {_span(r['no_bundle'], 'cpu')} | {_span(r['cartpole'], 'cpu')} | |",
        f"| ... kernels | {kernels('no_bundle')} | - | |",
        f"| first step, warm cache | {_span(r['warm_cache'])} | {_span(r['cartpole'])} | |",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: print the table (or ``--json``) of :func:`measure`."""
    parser = argparse.ArgumentParser(
        prog="python -m pectoral_gym.tools.coldstart",
        description="Cold start of a fish env against CartPole-v1: import time and the first step with an empty "
                    "numba cache, each in a fresh interpreter, least-largest over the rounds.")
    parser.add_argument("--env", default="PectoralFish-Averaged-v2", help="fish env id (default: %(default)s)")
    parser.add_argument("--rounds", type=int, default=3, metavar="N", help="rounds (default: %(default)s)")
    parser.add_argument("--checkout", metavar="DIR",
                        help="measure the package of another checkout (its root first on PYTHONPATH)")
    parser.add_argument("--json", action="store_true", help="print the measurements as one JSON object")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")
    measured = measure(args.env, args.rounds, args.checkout)
    print(json.dumps(measured) if args.json else table(measured))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
