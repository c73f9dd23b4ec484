"""The tracker contract the supervisor calls, ``track(frame, near=box) -> TrackResult``, checked when a user's
tracker is given (``check_tracker``, ``open_stack``): a precise error before anything is opened, not a stop at
the first frame.
"""

from __future__ import annotations

import pytest

from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.hardware.stack import open_stack
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.track_result import check_tracker
from pectoral_gym.hardware.vision.tracker import MarkerTracker


class _FrameOnly:
    def track(self, frame):
        return None


class _Keywords:
    def track(self, frame, **options):
        return None


class _NearFirst:
    def track(self, near, frame=None):  # "near" would be taken twice by track(frame, near=box)
        return None


class _NotATracker:
    track = "no method"


def test_trackers_the_supervisor_can_call_pass():
    check_tracker(MarkerTracker(CameraModel.default()))
    check_tracker(_Keywords())


@pytest.mark.parametrize("tracker, says", [
    (_FrameOnly(), r"_FrameOnly\.track must take track\(frame, near=None\).*unexpected keyword argument 'near'"),
    (_NearFirst(), r"_NearFirst\.track must take track\(frame, near=None\).*multiple values for argument 'near'"),
    (_NotATracker(), r"a tracker needs a method track\(frame, near=None\) -> TrackResult; _NotATracker has none"),
    (object(), r"a tracker needs a method track\(frame, near=None\).*; object has none"),
])
def test_a_tracker_the_supervisor_cannot_call_is_refused_with_what_it_must_take(tracker, says):
    with pytest.raises(TypeError, match=says):
        check_tracker(tracker)


class _Untouchable:
    """A port or camera that fails the test if the stack touches it (nothing may be opened)."""

    def __getattr__(self, name):
        pytest.fail(f"the stack touched the {name!r} of a part before checking the tracker")


def test_the_stack_refuses_such_a_tracker_before_it_opens_anything():
    with pytest.raises(TypeError, match="_FrameOnly.track must take"):
        open_stack(_Untouchable(), _Untouchable(), EnvConfig(), SafetyConfig(), tracker=_FrameOnly())
