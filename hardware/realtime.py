"""Keeping Python's cyclic garbage collector from pausing the robot stack mid-episode.

A full (generation 2) collection walks every object the collector tracks and holds the interpreter lock
while it does: with the stack's libraries loaded (numpy, numba, OpenCV; a policy adds torch) that is
about 10^5 objects and 50 ms on an idle core, and 150 ms was measured with both cores busy. For that
long no thread of the process runs: no frame is tracked, no rule is judged, no command is sent. The
supervisor's blind rule then stops the fish once it has been unseen for longer than the reaction budget
(``SafetyConfig.stop_rule.reaction_time``) near a wall, although the camera and the robot were fine. Python
starts a full collection on its own whenever enough objects have survived the younger generations, so
one can fall in any episode.

:func:`settle_garbage` runs a collection at a moment when a pause harms nothing (the fins stopped, the rules
disarmed: :meth:`pectoral_gym.hardware.env.HardwareFishEnv.reset` calls it there) and then freezes what survived
(``gc.freeze``): the collections that fall during the episode then walk only the objects made since, a few
milliseconds at most.

Most of what a call finds frozen is long-lived (the libraries' modules, functions and types, a loaded policy)
and survives every collection: walking it again at every call (twice per lockstep episode) would cost a tenth
of a second or more each time and find nothing. So a call collects only the objects made since the last call
(the frozen ones are out of the collector's reach), freezes the survivors, and walks everything (unfreeze,
collect, freeze) only once the frozen set may have grown to more than ``1 + growth`` times its size after the
last full collection (it counts what each call froze; what was freed since is not taken off, so it may walk
early, never late). Cyclic garbage among frozen objects (an episode's rig, frozen while it ran, is garbage
after it) waits for that walk; what it costs in memory is bounded: after every call the frozen set, garbage
included, is at most ``1 + growth`` times the set that survived the last full collection, which held no cyclic
garbage (unless other code freezes objects too). The pause mid-episode is what it was (the collections then
walk only what was made since the call), and every call pauses the process only where it is harmless, as
before.
"""

from __future__ import annotations

import gc
import time

__all__ = ["DEFAULT_GROWTH", "settle_garbage"]

# The frozen set's growth (a fraction of its size after a full collection) that triggers one. Frozen garbage holds
# what it references too (an old rig's frames and tables): the peak resident memory of 30 lockstep episodes in one
# process was 644 MB walking everything at every call, 656 MB at 0.05 and 685 MB at 0.25 (with each rig's camera
# holding tables of its own then). At 0.1 such a process walks everything about every sixth episode (its frozen set
# grows by some 7 000 objects of 450 000 per episode).
DEFAULT_GROWTH = 0.1

# The collector is one per process, so is this bookkeeping: the frozen set's size right after the last full
# collection, and an upper bound of its size now (what each call froze added; what was freed since not taken off).
# ``gc.get_freeze_count`` would tell the size itself, but it walks the whole frozen set, which is what is avoided.
_frozen_after_full = 0
_frozen_bound = 0


def settle_garbage(growth: float = DEFAULT_GROWTH) -> float:
    """Collect the cyclic garbage made since the last call, then freeze the survivors; returns the seconds spent.

    Everything the collector tracks is walked (unfreeze, collect, freeze) instead when the frozen set may
    otherwise exceed ``1 + growth`` times its size after the last such walk, and at the first call. Call it
    only where a pause of the whole process is harmless (fins stopped, no rule armed).

    Args:
        growth: The frozen set's allowed growth since the last full walk, as a fraction (>= 0) of its size then.
    """
    global _frozen_after_full, _frozen_bound
    if growth < 0.0:
        raise ValueError(f"growth must be >= 0, got {growth}")
    start = time.perf_counter()
    full = _frozen_after_full == 0
    if not full:
        gc.collect()  # the frozen objects are out of its reach: it walks only what was made since the last call
        _frozen_bound += len(gc.get_objects())  # the survivors, about to be frozen (the frozen set is not listed)
        gc.freeze()
        full = _frozen_bound > (1.0 + growth) * _frozen_after_full
    if full:
        gc.unfreeze()  # garbage among the frozen objects is collected here, with everything else
        gc.collect()
        _frozen_after_full = _frozen_bound = max(1, len(gc.get_objects()))
        gc.freeze()
    return time.perf_counter() - start
