"""Step cost of this checkout against another one (e.g. a worktree of an earlier release), measured in one run.

One long-lived worker process per checkout (its root first on ``PYTHONPATH``) builds the envs and
warms them up (numba compiles or loads its cache); the parent then asks the two workers in
alternating rounds (base, this, this, base, ...) to time the same pass and prints the medians and
the ratios base / this (above 1: this checkout is faster)::

    python docs/validation/step_path/speed_vs_base.py --base /tmp/stepbase

Cases: the single averaged and full envs through :func:`gymnasium.make` (``steps`` steps, actions
pre-drawn from the seeded action space, reset on termination or truncation), timed in the CPU time
of the stepping thread (:func:`time.thread_time`: other jobs on the machine slow it much less than
they slow the wall clock, and the vector env's worker threads, which may still spin after its pass,
are not counted); and the averaged vector env at 4096 envs
(``vector_entry_point``, a new action every step), timed in wall-clock time since its parallel
build runs on several threads.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
CASES = ("averaged", "full", "vector@4096")


def _worker(steps: int, vector_steps: int) -> None:
    """Serve timing requests on stdin (one case name per line); answer one JSON line per request."""
    import gymnasium as gym

    import pectoral_gym  # noqa: F401 - registers the envs

    runs = {}
    for case, env_id in (("averaged", "PectoralFish-Averaged-v0"), ("full", "PectoralFish-Full-v0")):
        env = gym.make(env_id)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(steps)]

        def single(env=env, actions=actions) -> float:
            env.reset(seed=0)
            start = time.thread_time()
            for action in actions:
                _, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    env.reset()
            return time.thread_time() - start

        runs[case] = single
    envs = gym.make_vec("PectoralFish-Averaged-v0", num_envs=4096, vectorization_mode="vector_entry_point")
    envs.action_space.seed(0)
    batch = [envs.action_space.sample() for _ in range(vector_steps)]

    def vector() -> float:
        envs.reset(seed=0)
        start = time.perf_counter()
        for action in batch:
            envs.step(action)
        return time.perf_counter() - start

    runs["vector@4096"] = vector
    for run in runs.values():
        run()  # warm-up
    print(json.dumps({"ready": True, "module": pectoral_gym.__file__}), flush=True)
    for line in sys.stdin:
        case = line.strip()
        print(json.dumps({"seconds": runs[case]()}), flush=True)


def _start(root: Path, steps: int, vector_steps: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    process = subprocess.Popen(
        [sys.executable, __file__, "--worker", "--steps", str(steps), "--vector-steps", str(vector_steps)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=root)
    ready = json.loads(process.stdout.readline())
    print(f"# {root}: {ready['module']}", flush=True)
    return process


def _ask(process: subprocess.Popen, case: str) -> float:
    process.stdin.write(case + "\n")
    process.stdin.flush()
    return json.loads(process.stdout.readline())["seconds"]


def main() -> None:
    """Parse the arguments; run the workers or compare."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", type=Path, help="root of the checkout to compare with")
    parser.add_argument("--rounds", type=int, default=15, help="timed passes per case and checkout")
    parser.add_argument("--steps", type=int, default=2000, help="single-env steps per pass")
    parser.add_argument("--vector-steps", type=int, default=20, help="vector-env batch steps per pass")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        _worker(args.steps, args.vector_steps)
        return
    if args.base is None:
        parser.error("--base is required")
    workers = {"base": _start(args.base.resolve(), args.steps, args.vector_steps),
               "this": _start(ROOT, args.steps, args.vector_steps)}
    times: dict[tuple[str, str], list[float]] = {(w, c): [] for w in workers for c in CASES}
    for k in range(args.rounds):
        order = ("base", "this") if k % 2 == 0 else ("this", "base")
        for case in CASES:
            for name in order:
                times[name, case].append(_ask(workers[name], case))
    for process in workers.values():
        process.stdin.close()
        process.wait()
    print(f"# {args.rounds} alternating rounds; single envs: thread CPU time of {args.steps} steps, "
          f"vector env: wall time of {args.vector_steps} batch steps")
    print(f"{'case':<14}{'base us/step':>14}{'this us/step':>14}{'base/this':>11}")
    for case in CASES:
        per = 1e6 / (args.steps if case != "vector@4096" else args.vector_steps * 4096)
        base, this = (statistics.median(times[w, case]) for w in ("base", "this"))
        print(f"{case:<14}{base * per:>14.3f}{this * per:>14.3f}{base / this:>11.3f}")


if __name__ == "__main__":
    main()
