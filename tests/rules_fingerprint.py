"""A fingerprint of the robot's fin rules, to show that moving code changed no behaviour (run as a script).

Hashes, section by section: seeded firmware-rule streams through the Python reference robot
(``tests/firmware_streams.py``, ``tests/firmware_robots.py``), the rule functions on seeded batches,
:class:`FinReplay` on seeded commands, stops and latch reports and on a synthetic run log (written, read back,
replayed by the calibration), :class:`FirmwarePath` predictions for a batch of fish, the first steps of seeded
episodes of the registered ids with the servos' rate limit, and the emulator's lockstep deployment of the hand
controller (40 steps over a lossy radio). Equal hashes before and after a refactoring mean bit-identical outputs.

Usage: ``python tests/rules_fingerprint.py`` (about a minute after numba's cache is warm).
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from firmware_robots import ReferenceRobot  # noqa: E402
from firmware_streams import generate  # noqa: E402

from pectoral_gym.agents.controllers.firmware_path import FirmwarePath  # noqa: E402
from pectoral_gym.model.finreplay import FinReplay  # noqa: E402
from pectoral_gym.model.finrules import FirmwareConfig, rate_limit, slew_at_latch, stretch_transition  # noqa: E402
from pectoral_gym.model.models import FullModel  # noqa: E402
from pectoral_gym.model.servo import ServoLimits, clip_beats, peak_rates  # noqa: E402
from pectoral_gym.runlog import read_run_log  # noqa: E402
from pectoral_gym.scaling.calibration.replay import replay_fins  # noqa: E402
from pectoral_gym.scaling.calibration.synth import write_synthetic_log  # noqa: E402


def _digest(*parts: object) -> str:
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(str(part.shape).encode() + np.ascontiguousarray(part, dtype=float).tobytes())
        elif isinstance(part, bytes):
            h.update(part)
        else:
            h.update(repr(part).encode())
    return h.hexdigest()[:16]


def streams(seeds: range = range(12)) -> str:
    parts: list[object] = []
    for seed in seeds:
        s = generate(seed)
        robot = ReferenceRobot(FirmwareConfig(), s.boot, s.uptime0)
        for t_ms, kind, data in s.events:
            snap = robot.step(t_ms, kind, data)
            parts += [snap.tx, snap.latches, snap.halts, sorted(snap.info.items()), snap.fins]
    return _digest(*parts)


def _random_beats(rng: np.random.Generator, shape: tuple[int, ...], wire: bool = False) -> np.ndarray:
    """Patterns ``(*shape, 2, 4)``, some outside the servo limits (``wire``: all that the wire format carries)."""
    low = np.array([0.0, 0.0, 0.05, 0.1]) if wire else np.array([-0.5, -0.2, 0.05, 0.1])
    high = np.array([3.5, 1.8, 5.0, 8.0])
    return rng.uniform(low, high, (*shape, 2, 4))


def rule_functions() -> str:
    rng = np.random.default_rng(11)
    limits = ServoLimits()
    parts: list[object] = []
    beats = _random_beats(rng, (64,))
    clipped, changed = clip_beats(beats, limits)
    parts += [clipped, changed, [peak_rates(b) for b in clipped]]
    for b in beats[:8]:
        parts += list(clip_beats(b, limits))
    turn, power = rng.uniform(0.1, 3.0, (64, 2)), rng.random((64, 2)) < 0.5
    parts.append(stretch_transition(clipped, turn, power, limits))
    ran = clip_beats(_random_beats(rng, (64,)), limits)[0]
    duration, still = rng.uniform(0.0, 1.5, (64, 2)), rng.random((64, 2)) < 0.2
    parts.append(slew_at_latch(clipped, ran, duration, still, limits))
    parts.append([rate_limit(a, b, dt, limits) for a, b, dt in zip(ran[:8], clipped[:8], duration[:8, 0], strict=True)])
    return _digest(*parts)


def fin_replay() -> str:
    rng = np.random.default_rng(12)
    replay = FinReplay()
    parts: list[object] = []
    t = 0.0
    for k in range(60):
        t += float(rng.uniform(0.05, 0.9))
        roll = rng.random()
        if roll < 0.1:
            replay.stop(t)
        elif roll < 0.25:
            beat = clip_beats(_random_beats(rng, ()), ServoLimits())[0][0]
            parts.append(replay.latch(t, int(rng.integers(0, 2)), beat, float(rng.uniform(0.5, 2.5)),
                                      bool(rng.random() < 0.5)))
        else:
            replay.command(t, _random_beats(rng, (), wire=True) if k % 3 else np.array([[1.57, 0.5, 1.0, 2.0]] * 2))
        parts += [replay.fins.copy(), replay.model.fin_angles()[0][0], replay.model.state.copy()]
    replay.advance(t + 2.0)
    parts.append(replay.fins.copy())
    return _digest(*parts)


def synthetic_log() -> str:
    from pectoral_gym.model.params import FishParams

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "synth.jsonl"
        info = write_synthetic_log(path, FishParams(), seed=3, duration=20.0, episode_length=8.0, tick_aligned=False)
        text = path.read_text(encoding="utf-8")
        track = replay_fins(read_run_log(path))
    return _digest(sorted(info.items()), text, track.times, track.kinds, track.values, track.t0)


def firmware_path() -> str:
    rng = np.random.default_rng(13)
    n = 6
    model, path = FullModel(n, integration="fast"), FirmwarePath(n)
    parts: list[object] = []
    for k in range(25):
        if k % 5 == 4:
            path.reset()
        path.command(_random_beats(rng, (n,)))
        parts += [path.target.copy(), path.advance(model, 0.5).copy(), model.fins.copy()]
    return _digest(*parts)


def env_steps() -> str:
    import gymnasium as gym

    import pectoral_gym  # noqa: F401 - registers the ids
    from pectoral_gym.registration import ENV_SETTINGS

    parts: list[object] = []
    for env_id in sorted(ENV_SETTINGS):
        env = gym.make(env_id)
        obs, _ = env.reset(seed=21)
        parts.append(obs)
        rng = np.random.default_rng(21)
        for _ in range(6):
            obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape))
            parts += [obs, reward, terminated, truncated]
        env.close()
    return _digest(*parts)


def lockstep_deploy() -> str:
    from pectoral_gym.hardware.emurig import RigConditions
    from pectoral_gym.hardware.lockstep_jobs import LockstepJob, run_lockstep

    conditions = RigConditions(radio_latency=0.05, radio_jitter=0.02, radio_loss=0.1, camera_latency=0.03,
                               camera_drop=0.1, pose_noise=(0.002, 0.02))
    job = LockstepJob(seed=5, conditions=conditions, max_steps=40)
    out: dict = {}
    thread = threading.Thread(target=lambda: out.update(r=run_lockstep(job, [0], progress=False)))
    thread.start()
    thread.join(timeout=600.0)
    result = out["r"][0]
    summary = {k: v for k, v in result.summary.items() if k != "wall_time"}
    return _digest(result.log, json.dumps(summary, sort_keys=True, default=str),
                   json.dumps(result.link, sort_keys=True, default=str))


SECTIONS = {"streams": streams, "rule_functions": rule_functions, "fin_replay": fin_replay,
            "synthetic_log": synthetic_log, "firmware_path": firmware_path, "env_steps": env_steps,
            "lockstep_deploy": lockstep_deploy}

if __name__ == "__main__":
    chosen = sys.argv[1:] or list(SECTIONS)
    for name in chosen:
        print(f"{name:16s} {SECTIONS[name]()}", flush=True)
