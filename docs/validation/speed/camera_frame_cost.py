"""Cost of one frame of a lockstep rig's camera pipeline: render, FrameCheck, track (one core).

300 frames of a fish moving across the tank under the default scene conditions (sensor noise), each stage timed
around its call by the thread's CPU clock (the figures hold on a loaded machine); best of 5 passes, in ms per frame.
The tracker is handed the last sighting's box, as the safety supervisor hands it.
"""

from __future__ import annotations

import time

import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.framecheck import FrameCheck
from pectoral_gym.hardware.vision.frames import Frame
from pectoral_gym.hardware.vision.scene import SceneConditions, render_frame
from pectoral_gym.hardware.vision.tracker import MarkerTracker


def main() -> None:
    """Run the measurement and print (or write) its figures."""
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
