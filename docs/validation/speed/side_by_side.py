"""Alternate vector_steps.py runs over variants and print two rates per variant, as ratios to the first.

``python side_by_side.py "VARIANT;VARIANT;..." ROUNDS ENV_ID NUM_ENVS STEPS PASSES``; a variant is
``[NAME=VALUE,...@]CHECKOUT`` (environment variables for that run, e.g. ``GOMP_SPINCOUNT=300000@.``).
Rates: the median over all passes, and the per-step minimum (each step's least time over all passes,
summed: the least disturbed steps, an estimate of the rate on an idle machine).
"""

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np

variants = sys.argv[1].split(";")
rounds, args = int(sys.argv[2]), sys.argv[3:]
script = str(Path(__file__).with_name("vector_steps.py"))
rates = {v: [] for v in variants}
steps = {v: [] for v in variants}
for _ in range(rounds):
    for v in variants:
        settings, _, root = v.rpartition("@")
        env = dict(os.environ, PYTHONPATH=os.path.abspath(root))
        env.update(kv.split("=", 1) for kv in settings.split(",") if kv)
        done = subprocess.run([sys.executable, script, *args], cwd=root, env=env, capture_output=True, text=True,
                              check=True)
        result = json.loads(done.stdout.strip().splitlines()[-1])
        rates[v] += result["rates"]
        steps[v] += result["steps"]
n = int(args[1])
first = None
for v in variants:
    times = np.array(steps[v])
    median, floor = statistics.median(rates[v]), n * times.shape[1] / times.min(axis=0).sum()
    first = first or (median, floor)
    print(f"{v:45s} median {median / 1e3:6.0f} k ({median / first[0]:.2f}x)  "
          f"per-step minimum {floor / 1e3:6.0f} k ({floor / first[1]:.2f}x)")
