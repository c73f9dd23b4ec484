"""The first step of PectoralFish-Averaged-v2, empty numba cache, no kernel bundle, alternately in two checkouts.

``python docs/validation/speed/cold_start_alternate.py OTHER_CHECKOUT [ROUNDS]``.

Each run is ``python -m pectoral_gym.tools.coldstart``'s child script in a fresh interpreter with a new cache
folder and ``PECTORAL_GYM_KERNEL_BUNDLE=0`` (every kernel the step calls compiles); alternating puts both
checkouts under the same load. Prints wall and CPU time and the number of kernels compiled per run.
"""

import sys
import tempfile
from pathlib import Path

from pectoral_gym.tools import coldstart

this = str(Path(__file__).resolve().parents[3])
other, rounds = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 3
for _ in range(rounds):
    for name, checkout in (("other", other), ("this", this)):
        with tempfile.TemporaryDirectory() as cache:
            row = coldstart._run(coldstart._FIRST_STEP, "PectoralFish-Averaged-v2", cache_dir=cache, bundle=False,
                                 checkout=checkout)
        print(f"{name}: wall {row['seconds']:.2f} s, CPU {row['cpu']:.2f} s, {row['compiled']} kernels compiled",
              flush=True)
