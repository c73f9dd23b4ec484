"""The camera pipeline's latency: measured from the frames themselves, and the most the tank affords.

A frame carries the stamp of its capture (:class:`pectoral_gym.hardware.vision.frames.Frame`); the frame
grabber notes when each one became available on this machine (``FrameGrabber.ages``, arrival minus stamp).
The pipeline's latency (exposure end to the PC: sensor read-out, USB or network transfer, decoding) is the
*smallest* of the recent ages: what every frame pays, whereas the rest of an age is jitter (a frame that
waited for the grabber's next read). The smallest is also the safe choice: the supervisor's blind rule
credits only this much age as "a seen pose of an older time" (``docs/guide/safety.md``, "Camera latency").

The latency the tank affords (:func:`afforded_latency`) is ``tracking_timeout - reaction_time``: a pose
of capture time ``t`` is the fish's last sighting until the next frame, and the tracking timeout counts
from the capture, so at latency ``L`` the camera can miss frames for only ``tracking_timeout - L``
before the fins stop; the reaction budget (4.5 frames at 30 frames/s) is the least left for dropped
frames and jitter. With the defaults (0.5 s, 0.15 s) the tank affords 0.35 s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

__all__ = ["CameraLatencyError", "LATENCY_WINDOW", "afforded_latency", "check_latency", "pipeline_latency"]

#: Recent frame ages the latency is measured over (2 s at 30 frames/s).
LATENCY_WINDOW = 60


class CameraLatencyError(RuntimeError):
    """The camera's measured latency is more than the tank affords (the fins stay stopped)."""


def pipeline_latency(ages: Iterable[float], window: int = LATENCY_WINDOW) -> float:
    """The smallest of the newest ``window`` finite, non-negative frame ages [their unit]; ``nan`` if none.

    A negative age (a camera clock slightly ahead, within ``max_frame_lead``) counts as 0.
    """
    recent = list(ages)[-int(window):]
    finite = [max(float(a), 0.0) for a in recent if math.isfinite(float(a))]
    return min(finite) if finite else math.nan


def afforded_latency(tracking_timeout: float, reaction_time: float) -> float:
    """The longest camera latency [s] the tracking timeout leaves room for: ``tracking_timeout - reaction_time``."""
    return max(float(tracking_timeout) - float(reaction_time), 0.0)


def check_latency(latency: float, tracking_timeout: float, reaction_time: float) -> float:
    """``latency`` [s] if the tank affords it (or it is not measured, ``nan``); else :class:`CameraLatencyError`."""
    afforded = afforded_latency(tracking_timeout, reaction_time)
    if math.isfinite(latency) and latency > afforded:
        raise CameraLatencyError(
            f"the camera's frames reach this PC {latency:.3f} s after capture; the tank affords at most "
            f"{afforded:.3f} s (tracking timeout {tracking_timeout:.2f} s minus the reaction time "
            f"{reaction_time:.2f} s); the fins stay stopped: use a faster camera pipeline "
            "(docs/guide/safety.md, \"Camera latency\")")
    return latency
