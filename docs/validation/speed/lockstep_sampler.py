"""Where a lockstep deployment's time goes: a sampling profiler over every thread of one run.

Usage: ``python lockstep_sampler.py OUT.txt pectoral_gym.hardware.deploy --policy ... --emulate --lockstep ...``
(``--jobs 1``: the episodes run in this process's threads).

Every 2 ms it records the stacks of the threads that are not waiting (on a lock, an event, the virtual clock).
In lockstep one thread runs at a time, so the shares are of the run's computing; functions compiled with numba's
``nogil`` release the GIL and are sampled fairly, while a C call that holds the GIL delays a sample to its end.
``cProfile`` sees the main thread only and inflates many small Python calls; ``py-spy`` is not installed here.
"""

from __future__ import annotations

import atexit
import collections
import os
import runpy
import sys
import threading
import time

INTERVAL = 0.002  # s between samples
WAITING = ("wait", "_suspend", "acquire", "_wait_for_tstate_lock", "select", "_recv")  # a blocked thread's top frame


def main() -> None:
    """Run the measurement and print (or write) its figures."""
    out, module = sys.argv[1], sys.argv[2]
    own: collections.Counter[str] = collections.Counter()
    inclusive: collections.Counter[str] = collections.Counter()
    threads: collections.Counter[str] = collections.Counter()

    def sample() -> None:
        me = threading.get_ident()
        while True:
            time.sleep(INTERVAL)
            names = {t.ident: t.name for t in threading.enumerate()}
            for ident, frame in sys._current_frames().items():
                if ident == me or frame.f_code.co_name in WAITING:
                    continue
                threads[names.get(ident, str(ident))] += 1
                own[f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_code.co_name}:{frame.f_lineno}"] += 1
                seen = set()
                while frame is not None:
                    key = f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_code.co_name}"
                    if key not in seen:
                        inclusive[key] += 1
                        seen.add(key)
                    frame = frame.f_back

    def report() -> None:
        total = max(sum(threads.values()), 1)
        with open(out, "w") as file:
            file.write(f"samples {total}\n== threads\n")
            for title, counts, rows in (("threads", threads, 20), ("inclusive", inclusive, 120), ("own line", own, 60)):
                if title != "threads":
                    file.write(f"== {title}\n")
                for key, count in counts.most_common(rows):
                    file.write(f"{100 * count / total:6.1f} {key}\n")

    threading.Thread(target=sample, daemon=True, name="sampler").start()
    atexit.register(report)
    sys.argv = [module, *sys.argv[3:]]
    runpy.run_module(module, run_name="__main__")


if __name__ == "__main__":
    main()
