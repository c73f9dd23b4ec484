"""Build or check the kernel bundle (:mod:`pectoral_gym.model.kernel_bundle`).

``python -m pectoral_gym.tools.kernel_bundle`` compiles, in a fresh interpreter with an empty numba
cache and ``NUMBA_CPU_NAME=generic``, every kernel that the first :data:`STEPS` random steps (with the
resets of ended episodes) of each registered fish env call, those of the latest ids' native vector
envs at :data:`VECTOR_ENVS` envs (the parallel builds, the autoreset) and those of the robot stack's replays
of the fins and liveness paths (:func:`pectoral_gym.model.finreplay.warm_up`), the task state's own observation
(the robot env's, :meth:`pectoral_gym.envs.tasks.table.TaskState.observe`) and the band cost's shortfall
(:func:`pectoral_gym.envs.cost.env_band_shortfall`), and writes them into
``pectoral_gym/data/kernels/`` (emptied first). Run it after
an edit of the kernels' sources (a stale bundled kernel is never used: the kernel compiles instead)
and before building a release.

``--check`` runs the same steps in a fresh interpreter with an empty numba cache and the
bundle on, and lists the kernels that compiled all the same (exit status 1 if any did).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

from pectoral_gym.model.kernel_bundle import BUNDLE, BUNDLE_CPU, BUNDLE_SETTING, MANIFEST, platform_key

__all__ = ["STEPS", "VECTOR_ENVS", "build", "check", "main"]

#: Native vector envs of this size (>= ``jit.PARALLEL_MIN_ITEMS``) run the parallel builds.
VECTOR_ENVS = 64
#: Random steps per env: past the episodes' step limit, so ended episodes reset (the vector envs' autoreset).
STEPS = 250

_FIRST_STEPS = """
import json, sys
import gymnasium as gym
import numpy as np
import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.registration import ENV_IDS, LATEST_AVERAGED, LATEST_FULL

compiled = []
if sys.argv[1] == "check":
    from numba.core import event

    class Compiled(event.Listener):
        def on_start(self, e):
            function = getattr(e.data["dispatcher"], "py_func", None)
            if function is not None and (function.__module__ or "").startswith("pectoral_gym"):
                compiled.append(f"{function.__module__}.{function.__qualname__}")

        def on_end(self, e):
            pass

    event.register("numba:compile", Compiled())
steps = int(sys.argv[3])
rng = np.random.default_rng(0)
for env_id in ENV_IDS:  # a first episode and the reset after it
    env = gym.make(env_id)
    env.reset(seed=0)
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, 8).astype(np.float32))
        if terminated or truncated:
            env.reset()
    env.close()
for env_id in (LATEST_AVERAGED, LATEST_FULL):  # the parallel builds, and the autoreset of ended episodes
    n = int(sys.argv[2])
    envs = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    for _ in range(steps):
        envs.step(rng.uniform(-1.0, 1.0, (n, 8)).astype(np.float32))
    envs.close()
from pectoral_gym.model import finreplay

finreplay.warm_up()  # the fins' replays and the liveness check's paths (the robot stack)
env = gym.make(LATEST_AVERAGED)  # the robot env observes through the task state alone (TaskState.observe)
env.reset(seed=0)
core = env.unwrapped.core
core.task_state.observe(core.model.state.copy())
from pectoral_gym.envs.cost import env_band_shortfall

env_band_shortfall(env)  # the safe-RL band cost (BandCost)
env.close()
saved = []
if sys.argv[1] == "build":
    import gc
    from pathlib import Path

    from pectoral_gym.model.jit import Kernel

    for kernel in [k for k in gc.get_objects() if isinstance(k, Kernel) and k.built and k.cached]:
        dispatcher = kernel.dispatcher
        for sig, cres in list(dispatcher.overloads.items()):
            if dispatcher._cache.save_to_bundle(sig, cres, Path(sys.argv[4])):
                saved.append(f"{kernel.__module__}.{kernel.__qualname__}")
print(json.dumps({"compiled": sorted(set(compiled)), "saved": sorted(saved)}))
"""


def _first_steps(mode: str, env: dict[str, str], *args: str) -> dict[str, list[str]]:
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
        done = subprocess.run([sys.executable, "-c", _FIRST_STEPS, mode, str(VECTOR_ENVS), str(STEPS), *args],
                              env={**os.environ, **env, "NUMBA_CACHE_DIR": cache}, capture_output=True, text=True,
                              check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the first steps failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def build(folder: Path = BUNDLE) -> list[str]:
    """Write the bundle into ``folder`` (emptied first); returns the kernels written (one entry per signature)."""
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    env = {"NUMBA_CPU_NAME": BUNDLE_CPU, "NUMBA_CPU_FEATURES": "", BUNDLE_SETTING: "0"}
    saved = _first_steps("build", env, str(folder))["saved"]
    (folder / MANIFEST).write_text(json.dumps(platform_key(), indent=1) + "\n", encoding="utf-8")
    return saved


def check(folder: Path = BUNDLE) -> list[str]:
    """The kernels that the first steps compile with an empty numba cache and the bundle at ``folder``."""
    return _first_steps("check", {BUNDLE_SETTING: str(folder)})["compiled"]


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m pectoral_gym.tools.kernel_bundle",
                                     description="Build the kernel bundle the package ships (or --check it).")
    parser.add_argument("--check", action="store_true",
                        help="list the kernels the first steps still compile with the bundle (exit 1 if any)")
    parser.add_argument("--folder", type=Path, default=BUNDLE, help="bundle folder (default: the package's)")
    args = parser.parse_args(argv)
    if args.check:
        stale = check(args.folder)
        print("\n".join(stale) if stale else f"the bundle in {args.folder} holds every kernel the first steps call")
        return 1 if stale else 0
    saved = build(args.folder)
    size = sum(f.stat().st_size for f in args.folder.rglob("*") if f.is_file())
    print(f"{len(saved)} compiled kernels written to {args.folder} ({size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
