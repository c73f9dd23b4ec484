"""The cold start: what ``import pectoral_gym`` loads, and what the first step of an env compiles.

Structural guards, no wall-clock limits (the figures are ``python -m pectoral_gym.tools.coldstart``'s):
importing the package registers the envs and loads no heavy library, and the first reset and step of an
env with an empty numba cache compiles each kernel it needs once, and none of the other model's or of
the parallel builds; with the kernel bundle the package ships, nothing compiles. Each check runs in a fresh
interpreter (this one has imported and compiled much).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from pectoral_gym.model.kernel_bundle import BUNDLE, BUNDLE_SETTING, bundle_fits

#: Libraries that ``import pectoral_gym`` must not load: the compiler and what it pulls in, and the heavy
#: optional ones some tools use.
HEAVY = ("numba", "llvmlite", "scipy", "yaml", "torch", "casadi", "cv2", "matplotlib", "stable_baselines3")

_IMPORT = """
import json, sys
import pectoral_gym
from gymnasium.envs.registration import registry
print(json.dumps({"modules": sorted(sys.modules), "ids": sorted(i for i in registry if i.startswith("PectoralFish"))}))
"""

_FIRST_STEP = """
import gc, json, sys
import gymnasium as gym
import numpy as np
import pectoral_gym
from pectoral_gym.model.jit import Kernel

env = gym.make(sys.argv[1])
env.reset(seed=0)
env.step(np.zeros(8, dtype=np.float32))
kernels = [o for o in gc.get_objects() if isinstance(o, Kernel) and o.built]
compiled = {k.__qualname__: len(k.signatures) for k in kernels if k.signatures}
built = sorted(k.__qualname__ for k in kernels)
print(json.dumps({"compiled": compiled, "built": built}))
"""


def _run(code: str, *args: str, cache_dir: str | None = None, bundle: str | None = None) -> dict:
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    if bundle is not None:
        env[BUNDLE_SETTING] = bundle
    done = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_import_registers_the_envs_and_loads_no_heavy_library():
    result = _run(_IMPORT)
    loaded = {name.split(".")[0] for name in result["modules"]}
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))
    assert "PectoralFish-Averaged-v2" in result["ids"] and "PectoralFish-Full-v2" in result["ids"]
    assert not any(name.startswith("pectoral_gym.envs") for name in result["modules"])  # the envs load at make


def test_the_package_exports_load_at_first_use():
    code = ("import json, sys, pectoral_gym; exported = 'FullModel' in vars(pectoral_gym); "
            "model = pectoral_gym.FullModel(1); "
            "print(json.dumps([exported, type(model).__module__, 'numba' in sys.modules]))")
    exported, module, numba_loaded = _run(code)
    assert (exported, module, numba_loaded) == (False, "pectoral_gym.model.models", False)


#: Kernels only the full model's step calls.
FULL_ONLY = {"advance_full_one", "fin_force_right", "_step_full_serial"}
#: Kernels only the averaged model's step calls (the K tables, the cycle averages).
AVERAGED_ONLY = {"advance_averaged_one", "pattern_values", "scaled_forcing", "_step_averaged_serial"}


@pytest.mark.parametrize("env_id", ["PectoralFish-Averaged-v2",
                                    pytest.param("PectoralFish-Full-v2", marks=pytest.mark.slow)])
def test_first_step_compiles_each_kernel_it_needs_once_and_nothing_else(env_id, tmp_path):
    # An empty cache and no bundle: everything the step needs compiles.
    result = _run(_FIRST_STEP, env_id, cache_dir=str(tmp_path / "numba-cache"), bundle="0")
    compiled = result["compiled"]
    averaged = "Averaged" in env_id
    own, other = (AVERAGED_ONLY, FULL_ONLY) if averaged else (FULL_ONLY, AVERAGED_ONLY)
    assert own <= set(compiled), sorted(own - set(compiled))
    assert not other & set(compiled), sorted(other & set(compiled))  # the other model's code
    assert "advance_one" not in compiled  # the kernel that picks the model at run time compiles both
    assert {n: k for n, k in compiled.items() if k != 1} == {}  # one signature each: no specialisations
    assert not [n for n in compiled if n.endswith("_parallel")]  # one env: the serial builds only
    # A kernel is made (and compiled) when it is first called, from Python or from a kernel being compiled;
    # the other kernels of the imported modules (the vector env's loops, the tools', the camera's) stay unmade.
    assert not [n for n in result["built"] if n.endswith("_parallel")]
    assert "advance_full_one" not in result["built"] if averaged else "advance_averaged_one" not in result["built"]


def _needs_the_bundle() -> None:
    if not BUNDLE.is_dir():
        pytest.skip("this checkout ships no kernel bundle (python -m pectoral_gym.tools.kernel_bundle builds it)")
    if not bundle_fits(BUNDLE):
        pytest.skip("the kernel bundle was built for another numba, Python or platform (its manifest.json)")


def test_with_the_shipped_bundle_the_first_steps_compile_nothing():
    _needs_the_bundle()
    from pectoral_gym.tools.kernel_bundle import check

    stale = check()  # every registered id's first step, and the latest ids' vector envs, with an empty cache
    assert stale == [], ("these kernels compile although the package ships a bundle: their sources changed since "
                         f"it was built; rebuild it with python -m pectoral_gym.tools.kernel_bundle: {stale}")


_SEEDED = """
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from config_fingerprint import GOLDEN, fingerprint

from pectoral_gym.envs import fused

golden, current = np.load(GOLDEN), fingerprint()
differ = sorted(name for name in golden.files if golden[name].tobytes() != current[name].tobytes())
stats = fused.STEP[True].serial.dispatcher.stats  # the averaged step: loaded (a hit) or compiled (a miss)
print(json.dumps([differ, sum(stats.cache_hits.values()), sum(stats.cache_misses.values())]))
"""


def test_the_bundled_kernels_give_the_recorded_bits(tmp_path):
    # The generic CPU's code against the golden file that code compiled for the recording machine wrote: numba
    # compiles without fast-math, so no CPU may reorder or fuse the arithmetic.
    _needs_the_bundle()
    tests = os.path.dirname(os.path.abspath(__file__))
    differ, loaded, compiled = _run(_SEEDED, tests, cache_dir=str(tmp_path / "numba-cache"))
    assert (loaded, compiled) == (1, 0)  # the averaged step came from the bundle (the cache was empty)
    assert differ == []


def test_a_bundle_takes_only_code_compiled_for_the_generic_cpu(tmp_path):
    import numpy as np

    from pectoral_gym.model.kernel_bundle import BundledCache
    from pectoral_gym.model.ktables import bspline_basis

    bspline_basis(np.arange(8.0), 4, 3.5)  # compiled for this machine's CPU
    dispatcher = bspline_basis.dispatcher
    sig, cres = next(iter(dispatcher.overloads.items()))
    assert isinstance(dispatcher._cache, BundledCache)
    with pytest.raises(ValueError, match="generic"):
        dispatcher._cache.save_to_bundle(sig, cres, tmp_path)
    assert not any(tmp_path.iterdir())
