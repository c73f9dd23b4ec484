"""How often a degraded radio or camera ends an episode on the emulated robot (the robot stack's tolerance targets).

Runs the hand baseline through the whole robot stack (``HardwareFishEnv``: radio link, firmware rules,
camera, tracker, observer, safety supervisor) against the emulated robot under each condition, and
counts the episodes that end in a ``link_lost`` or ``tracking_lost`` stop:

* ``clean``: loopback radio, the emulated camera as it is;
* ``bursty``: a radio with 100 ms one-way latency and fades covering 5 % of the time in 0.2 s bursts
  (:class:`pectoral_gym.hardware.radio.radioproxy.RadioProxy`);
* ``drops``: 10 % of the camera frames lost (:class:`pectoral_gym.hardware.vision.camerafaults.FaultyCamera`);
* ``load``: both cores loaded by two busy processes for the whole run.

The emulated robot and its camera run in a process of their own (radio over TCP, frames over
``emu://``, as ``python -m pectoral_gym.hardware.emulator`` serves them), as the real robot and camera run on their
own hardware: the PC's stack does not share its interpreter with the fish's physics and the camera's
rendering, and that process runs at a higher priority (``nice -10``, where permitted: the real fish and
camera do not wait for the PC's CPU; the load of the ``load`` condition competes with the PC's stack
only).

Example (the figures in docs/hardware.md)::

    python docs/validation/hardware/degraded_runs.py --episodes 25 --speed 1 --out degraded.json
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import multiprocessing
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.deploy_checks import DEFAULT_NICE, raise_priority
from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.radio.radioproxy import RadioProxy
from pectoral_gym.hardware.vision.camera import open_source
from pectoral_gym.hardware.vision.camerafaults import FaultyCamera

CONDITIONS = ("clean", "bursty", "drops", "load")


def _start(rng: np.random.Generator) -> tuple[float, float, float]:
    x = tk.START_INSET + rng.random() * (tk.TANK_X - 2 * tk.START_INSET)
    y = tk.START_INSET + rng.random() * (tk.TANK_Y - 2 * tk.START_INSET)
    return x, y, -math.pi + 2 * math.pi * rng.random()


@contextlib.contextmanager
def _busy_cores(n: int):
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _serve_robot(conn, speed: float, seed: int) -> None:
    """The robot's process: an emulated robot with its frame server; places the fish when asked."""
    with contextlib.suppress(OSError):  # the real fish and camera do not wait for the PC's CPU
        os.nice(-10)
    robot = EmulatedRobot(speed=speed, seed=seed, camera_port=0).start()
    try:
        conn.send((robot.url, robot.camera_spec))
        while True:
            request = conn.recv()
            if request[0] != "place":
                break
            robot.place(*request[1:])
            conn.send("placed")
    finally:
        robot.stop()


@contextlib.contextmanager
def _robot_process(speed: float, seed: int):
    """Start :func:`_serve_robot` in a process; yields ``(radio url, camera spec, place(x, y, psi))``."""
    context = multiprocessing.get_context("spawn")
    here, there = context.Pipe()
    process = context.Process(target=_serve_robot, args=(there, speed, seed), name="emulated-robot", daemon=True)
    process.start()
    try:
        if not here.poll(120):
            raise RuntimeError("the emulated robot's process did not start within 120 s")
        url, camera = here.recv()

        def place(x: float, y: float, psi: float) -> None:
            here.send(("place", x, y, psi))
            if not here.poll(10) or here.recv() != "placed":
                raise RuntimeError("the emulated robot's process did not place the fish")

        yield url, camera, place
    finally:
        with contextlib.suppress(OSError):
            here.send(("stop",))
        process.join(5)
        if process.is_alive():
            process.kill()


def run_condition(condition: str, episodes: int, speed: float, seed: int, progress: bool) -> dict:
    """Run ``episodes`` hand-law episodes under ``condition``; returns counts of how they ended."""
    with _robot_process(speed, seed) as (url, camera_spec, place):
        return _run(condition, episodes, speed, seed, progress, url, camera_spec, place)


def _run(condition, episodes, speed, seed, progress, url, camera_spec, place) -> dict:
    proxy = None
    if condition == "bursty":
        proxy = RadioProxy(url, latency=0.1, burst=(0.05, 0.2), seed=seed, speed=speed)
        url = proxy.url
    camera = open_source(camera_spec)
    if condition == "drops":
        camera = FaultyCamera(camera, drop=0.1, seed=seed)
    ends: Counter[str] = Counter()
    reasons: Counter[str] = Counter()
    stack = contextlib.ExitStack()
    if condition == "load":
        stack.enter_context(_busy_cores(2))
    env = None
    try:
        with stack:
            env = HardwareFishEnv(url, camera, speed=speed, reset_hook=lambda rng: place(*_start(rng)))
            controller = make_baseline("hand", env.config)
            for episode in tqdm(range(episodes), desc=condition, disable=not progress):
                obs, _ = env.reset(seed=seed + episode)
                controller.reset(seed + episode)
                steps = 0
                while True:
                    obs, _, terminated, truncated, info = env.step(controller.act(obs))
                    steps += 1
                    if terminated or truncated:
                        break
                stop = info["safety_stop"]
                end = stop or ("success" if info.get("is_success") else "end")
                ends[end] += 1
                if stop == "tracking_lost":
                    reasons[info["tracking"]["reason"][:60]] += 1
                elif stop == "link_lost":
                    link = info["link"]
                    reasons[f"link_lost at step {steps}: no reply for {link['status_age']:.2f} s, "
                            f"rtt {link['rtt']}"] += 1
    finally:
        if env is not None:
            env.close()
        if proxy is not None:
            proxy.close()
    lost = ends["link_lost"] + ends["tracking_lost"]
    return {"condition": condition, "episodes": episodes, "ends": dict(ends), "reasons": dict(reasons),
            "lost_share": lost / episodes}


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=25, help="episodes per condition (default %(default)s)")
    parser.add_argument("--speed", type=float, default=1.0, help="emulated clock speed-up (default %(default)s)")
    parser.add_argument("--seed", type=int, default=100, help="seed of starts, goals and faults (default %(default)s)")
    parser.add_argument("--conditions", nargs="+", choices=CONDITIONS, default=list(CONDITIONS))
    parser.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    parser.add_argument("--nice", type=int, default=DEFAULT_NICE,
                        help="the PC stack's nice value, as pectoral_gym.hardware.deploy sets it (default %(default)s)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    warning = raise_priority(args.nice)  # before any thread starts, as the deploy does
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    if args.episodes < 1 or not 0.1 <= args.speed <= 5:
        parser.error("--episodes must be >= 1 and --speed in [0.1, 5]")
    results = []
    for condition in args.conditions:
        t0 = time.monotonic()
        result = run_condition(condition, args.episodes, args.speed, args.seed, not args.no_progress)
        result["wall_s"] = round(time.monotonic() - t0, 1)
        results.append(result)
        print(json.dumps(result), flush=True)
    if args.out is not None:
        args.out.write_text(json.dumps({"speed": args.speed, "seed": args.seed, "results": results}, indent=2) + "\n")
    print("| condition | episodes | link_lost | tracking_lost | share | other ends |")
    print("|---|---|---|---|---|---|")
    for r in results:
        other = {k: v for k, v in r["ends"].items() if k not in ("link_lost", "tracking_lost")}
        print(f"| {r['condition']} | {r['episodes']} | {r['ends'].get('link_lost', 0)} | "
              f"{r['ends'].get('tracking_lost', 0)} | {100 * r['lost_share']:.0f} % | {other} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
