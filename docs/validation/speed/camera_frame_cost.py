"""Cost of one frame of a lockstep rig's camera pipeline: render, FrameCheck, track (one core).

300 frames of a fish moving across the tank under the default scene conditions (sensor noise), each stage timed
around its call by the thread's CPU clock (the figures hold on a loaded machine); best of 5 passes, in ms per frame.
The tracker is handed the last sighting's box, as the safety supervisor hands it.

``--render-stages`` splits the render instead: each of the renderer's steps (the patch boxes, the background's
runs, the patch's kernels) timed inside whole frames by a wrapper around its call (the wrappers add their own
few microseconds to the render's total), best of 5 passes.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pectoral_gym.hardware.vision import scene
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.framecheck import FrameCheck
from pectoral_gym.hardware.vision.frames import Frame
from pectoral_gym.hardware.vision.scene import SceneConditions, render_frame
from pectoral_gym.hardware.vision.tracker import MarkerTracker

RENDER_STEPS = ("_patch_boxes", "copy_runs", "_shapes", "paint_centres", "sample_points", "paint_samples",
                "average_whole", "_render_patch")


def _timed(function: Callable[..., Any], name: str, spent: dict[str, float]) -> Callable[..., Any]:
    def call(*args: Any) -> Any:
        t0 = time.thread_time()
        result = function(*args)
        spent[name] = spent.get(name, 0.0) + time.thread_time() - t0
        return result
    return call


def render_stages() -> None:
    """Print each renderer step's CPU per frame (``_render_patch`` holds the kernels but ``copy_runs``)."""
    camera, conditions = CameraModel.default(), SceneConditions()
    poses = [(0.5 + 0.002 * i, 0.4 + 0.001 * i, 0.02 * i) for i in range(300)]
    spent: dict[str, float] = {}
    for name in RENDER_STEPS:
        setattr(scene, name, _timed(getattr(scene, name), name, spent))
    best: dict[str, float] = {}
    for rep in range(5):
        rng = np.random.default_rng(rep)
        spent.clear()
        t0 = time.thread_time()
        for pose in poses:
            render_frame(pose, camera, rng, conditions)
        spent["render (total)"] = time.thread_time() - t0
        for name, seconds in spent.items():
            best[name] = min(best.get(name, np.inf), 1e3 * seconds / len(poses))
    print(" ".join(f"{name} {ms:.3f} ms" for name, ms in best.items()))


def main() -> None:
    """Run the measurement and print (or write) its figures."""
    if sys.argv[1:] == ["--render-stages"]:
        render_stages()
        return
    camera, conditions = CameraModel.default(), SceneConditions()
    tracker = MarkerTracker(camera)
    poses = [(0.5 + 0.002 * i, 0.4 + 0.001 * i, 0.02 * i) for i in range(300)]
    best: dict[str, float] = {}
    for rep in range(5):
        rng, check, box = np.random.default_rng(rep), FrameCheck(0.5, 1.0), None
        spent = dict.fromkeys(("render", "check", "track"), 0.0)
        for i, pose in enumerate(poses):
            stamp = 1.0 + i / 30
            t0 = time.thread_time()
            image = render_frame(pose, camera, rng, conditions)
            t1 = time.thread_time()
            check.check(Frame(image, stamp), stamp, box)
            t2 = time.thread_time()
            box = tracker.track(Frame(image, stamp), near=box).box  # near the last sighting, as the supervisor
            t3 = time.thread_time()
            spent["render"] += t1 - t0
            spent["check"] += t2 - t1
            spent["track"] += t3 - t2
        for stage, seconds in spent.items():
            best[stage] = min(best.get(stage, np.inf), 1e3 * seconds / len(poses))
    print(" ".join(f"{stage} {ms:.3f} ms" for stage, ms in best.items()), f"total {sum(best.values()):.3f} ms")


if __name__ == "__main__":
    main()
