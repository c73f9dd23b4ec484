"""Run a controller (a trained policy, the NMPC or the hand baseline) on the robotic fish (or the emulated one).

Examples::

    python -m hardware.deploy --policy runs/ppo-goal --port /dev/ttyUSB0 --camera 0 --episodes 3
    python -m hardware.deploy --policy runs/ppo-goal/model.zip --emulate --speed 2 --episodes 1
    python -m hardware.deploy --controller nmpc --emulate --episodes 1

``--controller nmpc`` plans on the averaged model (:class:`agents.nmpc.NMPCController`, the same
controller as in simulation) with its step budget set to ``--solve-fraction`` of the control period
(wall time, so divided by ``--speed`` when emulated): a solve that fails or ends later than that is not
applied, and the rest of the last plan (then both fins at rest) is sent instead.

Writes ``steps.jsonl`` (one JSON object per step: action, command sent, measured pose, estimate,
reward, ends, link and tracking health, and the true pose when emulated), ``summary.json`` and
``trajectory.png`` into ``--out``. Ctrl-C and SIGTERM stop the fins before the program ends.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from hardware.safety import SafetyConfig, install_stop_handlers
from pectoral_gym.envs import tasks as tk
from pectoral_gym.envs.observation import OBS_SIZE

__all__ = ["main", "make_controller", "run_episodes", "plot_trajectories", "solver_summary"]


def _random_start(rng: np.random.Generator) -> tuple[float, float, float]:
    """A start pose as the simulated goal task draws one (tank inset by 0.3 m, any heading)."""
    x = tk.START_INSET + rng.random() * (tk.TANK_X - 2 * tk.START_INSET)
    y = tk.START_INSET + rng.random() * (tk.TANK_Y - 2 * tk.START_INSET)
    return x, y, -math.pi + 2 * math.pi * rng.random()


def run_episodes(env, controller, episodes: int, log_path: Path, seed: int | None = None, robot=None,
                 progress: bool = True) -> list[dict]:
    """Run ``episodes`` episodes; append one JSON line per step to ``log_path``; return per-episode summaries."""
    from tqdm import tqdm

    summaries = []
    with open(log_path, "w", encoding="utf-8") as log, tqdm(total=episodes, desc="episodes",
                                                              disable=not progress) as bar:
        for episode in range(episodes):
            ep_seed = None if seed is None else seed + episode
            obs, info = env.reset(seed=ep_seed)
            controller.reset(ep_seed)
            ret, steps, t0 = 0.0, 0, time.monotonic()
            record = {"episode": episode, "step": 0, "event": "reset", "pose": info["pose"],
                      "target": info["target"]}
            if robot is not None:
                record["true_pose"] = list(robot.pose())
            log.write(json.dumps(record) + "\n")
            while True:
                action = np.asarray(controller.act(obs), dtype=np.float32)
                obs, reward, terminated, truncated, info = env.step(action)
                ret += reward
                steps += 1
                record = {"episode": episode, "step": steps, "t": time.monotonic() - t0,
                          "action": action.tolist(), "command": info["command"], "pose": info["pose"],
                          "estimate": info["estimate"], "target": env.unwrapped.target, "reward": reward,
                          "terminated": terminated, "truncated": truncated, "safety_stop": info["safety_stop"],
                          "distance": info["distance"], "link": info["link"], "tracking": info["tracking"]}
                if robot is not None:
                    record["true_pose"] = list(robot.pose())
                log.write(json.dumps(record) + "\n")
                if terminated or truncated:
                    break
            log.flush()
            summaries.append({"episode": episode, "return": ret, "steps": steps, "terminated": terminated,
                              "truncated": truncated, "safety_stop": info["safety_stop"],
                              "success": bool(info.get("is_success", False)), "final_distance": info["distance"]})
            bar.update(1)
    return summaries


def plot_trajectories(log_path: Path, png_path: Path) -> None:
    """Tank, measured/estimated path (and the true path when emulated) and targets of every episode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episodes: dict[int, list[dict]] = {}
    for line in Path(log_path).read_text(encoding="utf-8").splitlines():
        rec = json.loads(line)
        episodes.setdefault(rec["episode"], []).append(rec)
    fig, ax = plt.subplots(figsize=(9, 5))
    ax.add_patch(plt.Rectangle((0, 0), tk.TANK_X, tk.TANK_Y, fill=False, lw=2, color="k"))
    for k, recs in episodes.items():
        colour = f"C{k % 10}"
        est = np.array([r["estimate"][:2] for r in recs if "estimate" in r])
        if len(est):
            ax.plot(est[:, 0], est[:, 1], "-", color=colour, label=f"episode {k} estimate")
        true = np.array([r["true_pose"][:2] for r in recs if "true_pose" in r])
        if len(true):
            ax.plot(true[:, 0], true[:, 1], ":", color=colour, label=f"episode {k} true")
        start = recs[0]["pose"]
        ax.plot(start[0], start[1], "o", color=colour)
        targets = np.array([r["target"] for r in recs if "target" in r])
        ax.plot(targets[:, 0], targets[:, 1], "x", color=colour, ms=8)
    ax.set(xlim=(-0.05, tk.TANK_X + 0.05), ylim=(-0.05, tk.TANK_Y + 0.05), xlabel="X [m]", ylabel="Y [m]",
           title="Deployment: path (o start, x target)", aspect="equal")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)
    plt.close(fig)


def make_controller(name: str, config, step_budget: float, safety: SafetyConfig | None = None):
    """The ``nmpc`` or ``hand`` baseline for the robot's env config; NMPC steps end within ``step_budget`` [s].

    The NMPC plans with the stopping-distance band of the env's geofence (``safety``, default
    :class:`hardware.safety.SafetyConfig`), so it does not swim into it (``agents.stop_band``).
    """
    from agents.baselines import make_baseline

    if name == "nmpc":
        safety = safety or SafetyConfig()
        band = (safety.geofence_margin, safety.reaction_time, safety.coast_horizon)
        return make_baseline("nmpc", config, step_budget=step_budget, stop_band=band)
    return make_baseline(name, config)


def solver_summary(controller) -> dict:
    """Solve times (p50/p95/max [ms]), failed and late steps of an NMPC controller."""
    times = np.asarray(controller.solve_times, dtype=float) * 1e3
    if times.size == 0:
        return {"solves": 0, "failures": int(controller.failures), "late": int(controller.late)}
    return {"solves": int(times.size), "p50_ms": float(np.percentile(times, 50)),
            "p95_ms": float(np.percentile(times, 95)), "max_ms": float(times.max()),
            "failures": int(controller.failures), "late": int(controller.late)}


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m hardware.deploy", description=__doc__.split("\n\n")[0])
    parser.add_argument("--controller", choices=("policy", "nmpc", "hand"), default="policy",
                        help="what drives the fish (default %(default)s: --policy)")
    parser.add_argument("--policy", default=None, help="run folder or SB3 .zip (agents.policy.load_policy)")
    parser.add_argument("--solve-fraction", type=float, default=0.5, metavar="F",
                        help="nmpc: share of the control period a step's solves may take (default %(default)s)")
    parser.add_argument("--port", default=None, help="serial URL: /dev/ttyUSB0, socket://HOST:PORT, ...")
    parser.add_argument("--camera", default=None, help="camera index, video file or emu://HOST:PORT")
    parser.add_argument("--emulate", action="store_true", help="start an emulated robot and camera in-process")
    parser.add_argument("--episodes", type=int, default=1, help="number of episodes (default %(default)s)")
    parser.add_argument("--task", choices=("goal", "track"), default="goal", help="task (default %(default)s)")
    parser.add_argument("--control-period", type=float, default=0.5, metavar="S", help="default %(default)s s")
    parser.add_argument("--max-steps", type=int, default=240, help="steps per episode (default %(default)s)")
    parser.add_argument("--speed", type=float, default=1.0, help="emulated clock speed-up (--emulate only)")
    parser.add_argument("--calibration", default=None, help="camera calibration JSON (hardware.calibrate)")
    parser.add_argument("--geofence", type=float, default=0.05, metavar="M",
                        help="clearance kept from the walls on top of the stopping distance [m] (default 0.05)")
    parser.add_argument("--robot-address", default=None, metavar="HEX",
                        help="64-bit address of the robot's XBee, e.g. 0013A20012345678 (default: broadcast)")
    parser.add_argument("--tracking-timeout", type=float, default=0.5, metavar="S", help="default %(default)s s")
    parser.add_argument("--seed", type=int, default=0, help="seed of targets and emulated starts")
    parser.add_argument("--out", default="deploy_out", help="output folder (default %(default)s)")
    parser.add_argument("--no-prompt", action="store_true", help="do not ask to place the fish before episodes")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if not args.emulate and (args.port is None or args.camera is None):
        parser.error("--port and --camera are required unless --emulate is given")
    if args.episodes < 1 or args.max_steps < 1:
        parser.error("--episodes and --max-steps must be >= 1")
    if args.speed <= 0 or (args.speed != 1.0 and not args.emulate):
        parser.error("--speed must be > 0 and only applies with --emulate")
    if (args.controller == "policy") != (args.policy is not None):
        parser.error("--policy is needed with --controller policy, and only then")
    if not 0 < args.solve_fraction <= 1:
        parser.error("--solve-fraction must be in (0, 1]")
    controller = None
    if args.controller == "policy":
        from agents.policy import load_policy  # lazy: agents/ pulls in torch

        try:
            controller = load_policy(args.policy)
        except (FileNotFoundError, ValueError) as err:
            parser.error(f"cannot load policy {args.policy!r}: {err}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    robot = None
    from hardware.env import HardwareFishEnv

    try:
        safety = SafetyConfig(geofence_margin=args.geofence, tracking_timeout=args.tracking_timeout)
    except ValueError as err:
        parser.error(str(err))
    if args.emulate:
        from hardware.emulator import EmulatedRobot

        robot = EmulatedRobot(speed=args.speed, seed=args.seed).start()
        port, camera = robot.url, robot.camera(seed=args.seed)
        hook = lambda rng: robot.place(*_random_start(rng))  # noqa: E731 - a hand that puts the fish back
    else:
        port, camera = args.port, args.camera
        if args.robot_address is not None:
            from hardware.link import RadioLink

            try:
                port = RadioLink(args.port, dest64=int(args.robot_address, 16))
            except ValueError as err:
                parser.error(f"--robot-address: {err}")
        hook = None if args.no_prompt else (lambda rng: input("Place the fish in the tank and press Enter: "))
    env = None
    restore = lambda: None  # noqa: E731
    try:
        env = HardwareFishEnv(port, camera, task=args.task, control_period=args.control_period,
                              calibration=args.calibration, safety=safety, speed=args.speed,
                              max_episode_steps=args.max_steps, reset_hook=hook,
                              # a policy trained with the fin block gets it from the PC's fin replay
                              observe_fins=getattr(controller, "obs_size", OBS_SIZE) > OBS_SIZE)
        restore = install_stop_handlers(env.stop)
        if controller is None:
            controller = make_controller(args.controller, env.config, args.solve_fraction * args.control_period
                                         / args.speed, safety)
        summaries = run_episodes(env, controller, args.episodes, out / "steps.jsonl", args.seed, robot,
                                 progress=not args.quiet)
    finally:
        restore()
        if env is not None:
            env.close()
        if robot is not None:
            robot.stop()
    link = env.link.health()
    report = {"controller": args.controller, "policy": None if args.policy is None else str(args.policy),
              "episodes": summaries, "link": link}
    if hasattr(controller, "solve_times"):
        report["solver"] = solver_summary(controller)
    (out / "summary.json").write_text(json.dumps(report, indent=2), encoding="utf-8")
    plot_trajectories(out / "steps.jsonl", out / "trajectory.png")
    for s in summaries:
        print(f"episode {s['episode']}: return {s['return']:.3f}, {s['steps']} steps, "
              f"stop: {s['safety_stop'] or ('success' if s['success'] else 'end')}")
    print(f"log {out / 'steps.jsonl'}, plot {out / 'trajectory.png'}; link: sent {link['sent']}, "
          f"acked {link['acked']}, retries {link['retries']}, crc errors {link['crc_errors']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
