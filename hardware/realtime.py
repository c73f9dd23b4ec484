"""Keeping Python's cyclic garbage collector from pausing the robot stack mid-episode.

A full (generation 2) collection walks every object the collector tracks and holds the interpreter lock
while it does: with the stack's libraries loaded (numpy, numba, OpenCV; a policy adds torch) that is
about 10^5 objects and 50 ms on an idle core, and 150 ms was measured with both cores busy. For that
long no thread of the process runs: no frame is tracked, no rule is judged, no command is sent. The
supervisor's blind rule then stops the fish once it has been unseen for longer than the reaction budget
(``SafetyConfig.stop_rule.reaction_time``) near a wall, although the camera and the robot were fine. Python
starts a full collection on its own whenever enough objects have survived the younger generations, so
one can fall in any episode.

:func:`settle_garbage` runs that collection at a moment when a pause harms nothing (the fins stopped,
the rules disarmed: :meth:`pectoral_gym.hardware.env.HardwareFishEnv.reset` calls it there) and then
freezes what survived (``gc.freeze``): the collections that fall during the episode then walk only the
objects made since, a few milliseconds at most. The next call unfreezes first, so cyclic garbage among
the frozen objects is still collected, once per call, and nothing leaks.
"""

from __future__ import annotations

import gc
import time

__all__ = ["settle_garbage"]


def settle_garbage() -> float:
    """Collect all cyclic garbage now, then freeze the survivors out of later collections; returns the seconds spent.

    Call it only where a pause of the whole process is harmless (fins stopped, no rule armed).
    """
    start = time.perf_counter()
    gc.unfreeze()  # what earlier calls froze is collected again, once, here
    gc.collect()
    gc.freeze()
    return time.perf_counter() - start
