"""Where the robot's motion parts from the model's under the same actions: a deploy's actions replayed open loop.

``pectoral-deploy`` logs every step's action and the fish's pose (``true_pose``: the emulated robot's own; the
camera's ``pose`` on a real robot) in ``steps.jsonl``. This study resets a simulated env (default
:data:`pectoral_gym.versions.LATEST_FULL`, the model the emulated robot runs) at each episode's logged start and
goal, steps it with the logged actions, and finds the first step at which the simulated pose is further than
``--part-mm`` or ``--part-deg`` from the logged one. Against the emulated robot the two agree to a fraction of a
millimetre until something in the stack moves the fins differently from the model (the firmware's rules, the
radio's timing): the step it parts at, and the separation there, say where to look
(``docs/notes/2026-12-05-still-fins.md`` found two firmware faults this way). Against a real robot the model's own
error parts them too; calibrate first (``docs/calibration.md``).

Example::

    python -m pectoral_gym.agents.studies.open_loop_gap --deploy lk_demo --part-mm 5 --part-deg 3

Writes ``open_loop_gap.json`` into ``--out`` (default: the deploy folder).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.studies.stack_gap import DEFAULT_ENV, log_records, read_deploy

__all__ = ["Parting", "build_parser", "main", "read_steps", "replay_open_loop"]


@dataclass(frozen=True)
class Parting:
    """One episode replayed open loop: the first step past the thresholds (``None``: never) and the separations.

    Attributes:
        episode: The deploy's episode number.
        steps: Steps replayed (the logged ones).
        parted_at: First step (1-based) whose position or heading is past the threshold, or ``None``.
        position_mm: Position separation there [mm] (at the last step when it never parts).
        heading_deg: Heading separation there [deg], in [-180, 180).
        final_position_mm: Position separation at the last step [mm].
    """

    episode: int
    steps: int
    parted_at: int | None
    position_mm: float
    heading_deg: float
    final_position_mm: float


def read_steps(folder: str | Path) -> dict[int, list[tuple[np.ndarray, np.ndarray]]]:
    """Each episode's logged steps of a deploy's ``steps.jsonl``, in order: ``(action (8,), pose (3,))``.

    The pose is ``true_pose`` where logged, else the camera's ``pose``.

    Raises:
        ValueError: The file is missing, a line is not JSON, or a step record lacks a finite action of 8 entries or
            a finite pose of 3 (the message names the file and line).
    """
    path = Path(folder) / "steps.jsonl"
    if not path.is_file():
        raise ValueError(f"{path}: not found (a pectoral-deploy output folder has steps.jsonl)")
    episodes: dict[int, list[tuple[int, np.ndarray, np.ndarray]]] = {}
    for number, record in log_records(path):
        if record.get("event") == "reset" or "action" not in record:
            continue
        try:
            action = np.asarray(record["action"], dtype=float)
            pose = np.asarray(record.get("true_pose") or record["pose"], dtype=float)
            step, episode = int(record["step"]), int(record["episode"])
        except (TypeError, ValueError, KeyError):
            raise ValueError(f"{path}:{number}: a step record needs episode, step, action and a pose") from None
        if action.shape != (8,) or pose.shape != (3,) or not (np.isfinite(action).all() and np.isfinite(pose).all()):
            raise ValueError(f"{path}:{number}: the step's action (8) and pose (3) must be finite")
        episodes.setdefault(episode, []).append((step, action, pose))
    return {k: [(a, p) for _, a, p in sorted(rows, key=lambda row: row[0])] for k, rows in episodes.items()}


def replay_open_loop(folder: str | Path, env_id: str = DEFAULT_ENV, part_mm: float = 5.0,
                     part_deg: float = 3.0) -> list[Parting]:
    """Replay every episode of a deploy folder open loop in ``env_id`` (its logged start, goal and actions).

    Raises:
        ValueError: As :func:`read_deploy` and :func:`read_steps`, or for thresholds that are not > 0.
    """
    if not (part_mm > 0 and part_deg > 0):
        raise ValueError(f"the thresholds must be > 0, got {part_mm} mm and {part_deg} deg")
    import gymnasium as gym

    import pectoral_gym  # noqa: F401 - registers the ids

    steps = read_steps(folder)
    env = gym.make(env_id)
    out = []
    try:
        for episode in read_deploy(folder):
            env.reset(seed=episode.episode, options={"start": episode.start, "goal": episode.goal})
            parted, where, apart = None, (0.0, 0.0), (0.0, 0.0)
            logged = steps.get(episode.episode, [])
            for k, (action, pose) in enumerate(logged, 1):
                env.step(action.astype(np.float32))
                x, y, psi = (float(v) for v in env.unwrapped.fish_state[:3])
                turn = (psi - pose[2] + math.pi) % (2 * math.pi) - math.pi
                apart = (1000.0 * math.hypot(x - pose[0], y - pose[1]), math.degrees(turn))
                if parted is None and (apart[0] > part_mm or abs(apart[1]) > part_deg):
                    parted, where = k, apart
            if parted is None:
                where = apart
            out.append(Parting(episode.episode, len(logged), parted, round(where[0], 2), round(where[1], 2),
                               round(apart[0], 2)))
    finally:
        env.close()
    return out


def build_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    parser = argparse.ArgumentParser(
        prog="python -m pectoral_gym.agents.studies.open_loop_gap",
        description="Replay a deploy's actions open loop in simulation from its logged starts: the step at which "
                    "each episode's simulated pose parts from the logged one.",
        epilog="examples:\n  python -m pectoral_gym.agents.studies.open_loop_gap --deploy lk_demo\n"
               "  python -m pectoral_gym.agents.studies.open_loop_gap --deploy lk_demo --part-mm 2 --part-deg 1 "
               "--out gap_demo",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--deploy", required=True, metavar="DIR", help="a pectoral-deploy output folder")
    parser.add_argument("--env", default=DEFAULT_ENV, help=f"simulated env id (default: {DEFAULT_ENV})")
    parser.add_argument("--part-mm", type=float, default=5.0, help="position separation that counts [mm] (5)")
    parser.add_argument("--part-deg", type=float, default=3.0, help="heading separation that counts [deg] (3)")
    parser.add_argument("--out", metavar="DIR", help="where open_loop_gap.json goes (default: the deploy folder)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    args = build_parser().parse_args(argv)
    try:
        partings = replay_open_loop(args.deploy, args.env, args.part_mm, args.part_deg)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    parted = [p for p in partings if p.parted_at is not None]
    result: dict[str, Any] = {"episodes": len(partings), "parted": len(parted), "part_mm": args.part_mm,
                              "part_deg": args.part_deg, "per_episode": [asdict(p) for p in partings]}
    out = Path(args.out or args.deploy)
    out.mkdir(parents=True, exist_ok=True)
    (out / "open_loop_gap.json").write_text(json.dumps(result, indent=1) + "\n")
    print(f"{len(partings)} episodes: {len(parted)} part from the model by more than {args.part_mm:g} mm or "
          f"{args.part_deg:g} deg under the same actions")
    for p in parted:
        print(f"  episode {p.episode}: at step {p.parted_at} of {p.steps} ({p.position_mm:.1f} mm, "
              f"{p.heading_deg:+.1f} deg; {p.final_position_mm:.1f} mm at the end)")
    print(f"wrote {out / 'open_loop_gap.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
