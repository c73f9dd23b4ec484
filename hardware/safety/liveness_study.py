"""Study: cameras that are not live (frozen, replaying, showing another fish), against the supervisor, in lockstep.

Each episode runs a trained policy on a fresh lockstep rig (:func:`pectoral_gym.hardware.emurig.open_rig`,
seeded with ``seed + k``); after ``--fault-after`` control steps the camera turns into one of :data:`FAULTS`:

* ``repeat``, ``cycle31``, ``cycle60``, ``cycle300``: :class:`pectoral_gym.hardware.vision.camerafaults.FaultyCamera`'s
  frozen image, or its ring of the last 31, 60 or 300 live images going round (fresh stamps);
* ``noisy``: the frozen image under fresh Gaussian pixel noise (an analog camera frozen behind a capture card);
* ``recording``: a rendering, with fresh sensor noise, of an earlier episode's fish (``seed + 10000``), moved and
  turned to start exactly where ours is (no jump at the switch);
* ``other-fish``: a second fish (the full model) started in our fish's state, its fins beating a pattern of
  their own (right fin hard, left fin gentle);
* ``none``: a live camera (false stops).

Per episode it reports the stop, its reason, the delay from the fault to the stop [experiment s] and the least
clearance of the true fish's outline (body capsule and fin discs,
:class:`pectoral_gym.hardware.safety.geofence.Geofence`) from the walls over the whole episode, sampled at
every camera frame (negative: past a wall).

    python -m pectoral_gym.hardware.safety.liveness_study --policy RUN --fault noisy --episodes 20 --seed 4000
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Callable

import numpy as np

__all__ = ["FAULTS", "run_episode", "main"]

FAULTS = ("none", "repeat", "noisy", "cycle31", "cycle60", "cycle300", "recording", "other-fish")
_OTHER_FINS = np.array([[math.radians(100), math.radians(60), 0.8, 3.0],  # the other fish: right fin hard,
                        [math.radians(90), math.radians(15), 2.0, 1.0]])  # left fin gentle


def _record(policy, settings: dict, seed: int, duration: float = 20.0) -> list[tuple[float, tuple[float, ...]]]:
    """The true poses ``(t, (X, Y, psi))`` at every camera frame of one live episode, at most ``duration`` s."""
    poses: list[tuple[float, tuple[float, ...]]] = []
    run_episode(policy, settings, seed, "none", 10 ** 6, sink=poses, limit=duration)
    return poses


def _aligned(recording, start_pose, t_switch: float) -> Callable[[float], tuple[float, float, float]]:
    """The recording moved and turned to start at ``start_pose`` at ``t_switch`` (looping)."""
    t0, (x0, y0, psi0) = recording[0]
    times = np.array([t for t, _ in recording]) - t0
    poses = np.array([p for _, p in recording])
    turn = start_pose[2] - psi0
    c, s = math.cos(turn), math.sin(turn)

    def pose(t: float) -> tuple[float, float, float]:
        k = int(np.searchsorted(times, (t - t_switch) % max(times[-1], 1e-9)))
        x, y, psi = poses[min(k, len(poses) - 1)]
        dx, dy = x - x0, y - y0
        return (start_pose[0] + c * dx - s * dy, start_pose[1] + s * dx + c * dy, psi + turn)

    return pose


def run_episode(policy, settings: dict, seed: int, fault: str, fault_after: int, conditions=None, recording=None,
                sink: list | None = None, limit: float = math.inf, min_motion: float | None = None) -> dict:
    """One lockstep episode with the camera fault ``fault`` from step ``fault_after`` on; returns its summary.

    ``min_motion`` [m], if given, replaces the liveness check's (``LivenessWatch.min_motion``): a what-if.
    """
    from pectoral_gym.envs.tasks import kernels as tk
    from pectoral_gym.hardware.deploy import random_start
    from pectoral_gym.hardware.emurig import RigConditions, open_rig
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.safety.geofence import Geofence
    from pectoral_gym.hardware.safety.rules import SafetyConfig
    from pectoral_gym.hardware.vision.camerafaults import FaultyCamera
    from pectoral_gym.model.models import FullModel

    with contextlib.ExitStack() as resources:
        clock, robot, port, camera = open_rig(resources, seed, conditions or RigConditions(), lockstep=True)
        inner = camera.source if isinstance(camera, FaultyCamera) else camera
        cycle = int(fault[5:]) if fault.startswith("cycle") else 4
        faulty = FaultyCamera(camera, cycle=cycle, clock=clock, seed=[seed, 7])
        safety = SafetyConfig()
        fence = Geofence(_params(settings), safety.stop_rule)
        clearance = [math.inf]
        recording_on = [False]  # the sink records from the episode's start on (not the placing before it)

        def true_pose():  # the camera's view of our fish, the true outline's clearance noted at every frame
            pose, stamp = robot.pose_stamped()
            clearance[0] = min(clearance[0], float(np.min(fence.clearance(*pose))))
            if sink is not None and recording_on[0]:
                sink.append((stamp, tuple(pose)))
            return pose, stamp

        inner.pose_fn = true_pose
        inset = settings.get("start_inset", tk.START_INSET)
        env = HardwareFishEnv(port, faulty, reset_hook=lambda rng: robot.place(*random_start(rng, inset)),
                              clock=clock, handle_signals=False, safety=safety, **settings)
        resources.callback(env.close)
        if min_motion is not None:
            env.supervisor.liveness.min_motion = float(min_motion)
        obs, info = env.reset(seed=seed)
        policy.reset(seed)
        recording_on[0] = True
        t_fault, step, terminated, truncated = math.nan, 0, False, False
        while not (terminated or truncated) and env.now() < limit:
            if step == fault_after and fault != "none":
                t_fault = env.now()
                _inject(fault, faulty, inner, robot, clock, true_pose, recording, FullModel)
            obs, _, terminated, truncated, info = env.step(np.asarray(policy.act(obs), dtype=np.float32))
            step += 1
        sup = env.supervisor
        stopped = min(sup.fired.values()) if sup.fired else math.nan
        model = _model_error(sup.liveness, t_fault)
        return {"seed": seed, "fault": fault, "steps": step, "stop": info["safety_stop"],
                "success": bool(info.get("is_success", False)), "reason": info["tracking"]["reason"],
                "fault_time": t_fault, "delay": stopped - t_fault if math.isfinite(t_fault) else math.nan,
                "min_clearance": clearance[0], "latency": info["tracking"].get("latency"), **model}


def _model_error(watch, t_fault: float) -> dict:
    """The motion checks' margins while the camera was live (windows ending before ``t_fault``).

    ``model_miss_max``: the innovation less three standard errors (the model's own miss), at most [m];
    ``shown_share_min``: the share of the predicted motion the camera showed, at least (windows predicting
    ``min_motion`` or more).
    """
    rows = np.array([p for p in watch.predictions if not p[0] >= t_fault]).reshape(-1, 5)
    if not len(rows):
        return {"model_miss_max": None, "shown_share_min": None}
    miss = rows[:, 3] - (rows[:, 4] - watch.innovation)
    hard = rows[:, 1] >= watch.min_motion
    return {"model_miss_max": float(miss.max()),
            "shown_share_min": float((rows[hard, 2] / rows[hard, 1]).min()) if hard.any() else None}


def _params(settings: dict):
    from pectoral_gym.model.params import FishParams

    return settings.get("params") or FishParams()


def _inject(fault, faulty, inner, robot, clock, true_pose, recording, full_model) -> None:
    """Turn the camera into ``fault`` now (the true pose keeps being sampled for the clearance)."""
    if fault in ("repeat", "noisy") or fault.startswith("cycle"):
        faulty.freeze = "cycle" if fault.startswith("cycle") else fault
        return
    start = robot.state().copy()
    if fault == "recording":
        other = _aligned(recording, tuple(start[:3]), clock.monotonic())

        def pose_at(t):
            return other(t)
    else:
        model = full_model(n=1)
        model.reset(start[None], right=_OTHER_FINS[0][None], left=_OTHER_FINS[1][None])
        t0 = clock.monotonic()

        def pose_at(t):
            model.advance(max(t - t0 - model.time, 0.0))
            return tuple(model.state[0, :3])

    def shown():
        pose, stamp = true_pose()  # our fish's true pose: only for the clearance
        return pose_at(stamp), stamp

    inner.pose_fn = shown


def main(argv: list[str] | None = None) -> int:
    """Command line: run the study, print one JSON line per episode and a summary line."""
    parser = argparse.ArgumentParser(prog="python -m pectoral_gym.hardware.safety.liveness_study",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", required=True, help="trained policy run folder or .zip")
    parser.add_argument("--fault", choices=FAULTS, default="noisy")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--fault-after", type=int, default=8, help="control steps before the fault (default 8)")
    parser.add_argument("--pose-noise-mm", type=float, default=0.0)
    parser.add_argument("--pose-noise-deg", type=float, default=0.0)
    parser.add_argument("--camera-drop", type=float, default=0.0)
    parser.add_argument("--camera-latency", type=float, default=0.0)
    parser.add_argument("--min-motion-mm", type=float, default=None,
                        help="the liveness check's least judged motion [mm] instead of its own (a what-if)")
    args = parser.parse_args(argv)
    if args.min_motion_mm is not None and not (math.isfinite(args.min_motion_mm) and args.min_motion_mm > 0):
        parser.error(f"--min-motion-mm must be a number of millimetres > 0, got {args.min_motion_mm}")
    min_motion = None if args.min_motion_mm is None else args.min_motion_mm / 1000.0
    from pectoral_gym.agents.training.policy import load_policy
    from pectoral_gym.hardware.deploy import env_settings
    from pectoral_gym.hardware.emurig import RigConditions

    policy = load_policy(args.policy)
    settings, _ = env_settings(policy, None, None)
    conditions = RigConditions(camera_latency=args.camera_latency, camera_drop=args.camera_drop,
                               pose_noise=(args.pose_noise_mm / 1000.0, math.radians(args.pose_noise_deg)))
    recording = _record(policy, settings, args.seed + 10000) if args.fault == "recording" else None
    rows = []
    for k in range(args.episodes):
        row = run_episode(policy, settings, args.seed + k, args.fault, args.fault_after, conditions, recording,
                          min_motion=min_motion)
        rows.append(row)
        print(json.dumps(row), flush=True)
    delays = [r["delay"] for r in rows if math.isfinite(r["delay"])]
    summary = {"fault": args.fault, "episodes": len(rows), "stopped": sum(bool(r["stop"]) for r in rows),
               "successes": sum(r["success"] for r in rows),
               "delay_max": max(delays) if delays else None,
               "delay_median": float(np.median(delays)) if delays else None,
               "min_clearance": min(r["min_clearance"] for r in rows),
               "model_miss_max": max((r["model_miss_max"] for r in rows if r["model_miss_max"] is not None),
                                     default=None),
               "shown_share_min": min((r["shown_share_min"] for r in rows if r["shown_share_min"] is not None),
                                      default=None),
               "stops": {s: sum(r["stop"] == s for r in rows) for s in sorted({r["stop"] for r in rows})}}
    print(json.dumps({"summary": summary}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
