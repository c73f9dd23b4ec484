"""What the robot stack itself costs a controller: its deploy episodes replayed in simulation from the same starts.

``pectoral-deploy`` logs each episode's start (``true_pose`` at the reset: the emulated robot's own pose; the
camera's ``pose`` on a real robot) and goal (``target``) in ``steps.jsonl``, and its outcome in ``summary.json``.
This study drives the same controller in a simulated env (default :data:`pectoral_gym.versions.LATEST_FULL`, the
model the emulated robot runs) from those starts and goals (``reset(options=...)``) and counts the episodes by
outcome on the robot stack and in simulation. The episodes the simulation reaches and the stack does not are what
the stack costs (camera, observer, radio, firmware rules, safety supervisor), not the controller's skill at the
task; each is listed with its stop and the goal's bearing off the heading at the start.

Example::

    python -m pectoral_gym.agents.studies.stack_gap --policy demo_out/run --deploy demo_out/robot
    python -m pectoral_gym.agents.studies.stack_gap --controller hand --deploy lk_hand --out gap_hand

Writes ``stack_gap.json`` into ``--out`` (default: the deploy folder).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pectoral_gym.versions import LATEST_FULL

__all__ = ["DEFAULT_ENV", "DeployedEpisode", "ReplayedEpisode", "build_parser", "log_records", "main", "read_deploy",
           "replay", "report"]

DEFAULT_ENV = LATEST_FULL  # the full model the emulated robot runs, in the recipe's version


@dataclass(frozen=True)
class DeployedEpisode:
    """One deploy episode: its start ``(X, Y, psi)`` [m, m, rad], goal ``(X, Y)`` [m] and outcome on the stack."""

    episode: int
    start: tuple[float, float, float]
    goal: tuple[float, float]
    success: bool
    stop: str  # the safety stop's reason, "" for none
    steps: int

    @property
    def bearing(self) -> float:
        """The goal's bearing off the fish's heading at the start [deg], in [-180, 180)."""
        x, y, psi = self.start
        angle = math.atan2(self.goal[1] - y, self.goal[0] - x) - psi
        return math.degrees((angle + math.pi) % (2 * math.pi) - math.pi)


@dataclass(frozen=True)
class ReplayedEpisode:
    """A deploy episode and the same start driven in simulation (``sim_steps``: control periods it took)."""

    deployed: DeployedEpisode
    sim_success: bool
    sim_steps: int


def log_records(path: Path) -> Iterator[tuple[int, dict[str, Any]]]:
    """``(line number, record)`` of each JSON object of a deploy's ``steps.jsonl`` (other values are skipped).

    Raises:
        ValueError: A line is not JSON (the message names the file and line).
    """
    with path.open() as lines:
        for number, line in enumerate(lines, 1):
            try:
                record = json.loads(line)
            except json.JSONDecodeError as err:
                raise ValueError(f"{path}:{number}: not JSON ({err.msg})") from None
            if isinstance(record, dict):
                yield number, record


def read_deploy(folder: str | Path) -> list[DeployedEpisode]:
    """The episodes of a ``pectoral-deploy`` output folder (``summary.json`` and ``steps.jsonl``).

    Raises:
        ValueError: A file is missing, a line is not JSON, or an episode of the summary has no reset record
            with a finite start and goal (the message names the file and line or episode).
    """
    folder = Path(folder)
    summary_path, steps_path = folder / "summary.json", folder / "steps.jsonl"
    for path in (summary_path, steps_path):
        if not path.is_file():
            raise ValueError(f"{path}: not found (a pectoral-deploy output folder has summary.json and steps.jsonl)")
    starts: dict[int, tuple[tuple[float, ...], tuple[float, ...]]] = {}
    for number, record in log_records(steps_path):
        if record.get("event") == "reset":
            pose = record.get("true_pose") or record.get("pose")  # the robot's own pose where known
            try:
                start, goal = tuple(float(v) for v in pose), tuple(float(v) for v in record["target"])
            except (TypeError, ValueError, KeyError):
                raise ValueError(f"{steps_path}:{number}: a reset record needs a pose and a target") from None
            if len(start) != 3 or len(goal) != 2 or not all(map(math.isfinite, start + goal)):
                raise ValueError(f"{steps_path}:{number}: the reset's pose (3) and target (2) must be finite")
            starts[int(record["episode"])] = (start, goal)
    try:
        episodes = json.loads(summary_path.read_text())["episodes"]
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{summary_path}: not a pectoral-deploy summary ({err})") from None
    out = []
    for row in episodes:
        k = int(row["episode"])
        if k not in starts:
            raise ValueError(f"{steps_path}: episode {k} of the summary has no reset record")
        start, goal = starts[k]
        out.append(DeployedEpisode(k, start, goal, bool(row["success"]), str(row.get("safety_stop") or ""),
                                   int(row.get("steps", 0))))
    return out


def replay(controller: Any, episodes: list[DeployedEpisode], env_id: str = DEFAULT_ENV,
           env_kwargs: dict[str, Any] | None = None) -> list[ReplayedEpisode]:
    """Drive ``controller`` (``reset(seed)``, ``act(obs)``) in ``env_id`` from each episode's start and goal.

    Episode ``k`` is reset with seed ``k`` and runs to its end or the env's step limit.
    """
    import gymnasium as gym

    import pectoral_gym  # noqa: F401 - registers the ids

    env = gym.make(env_id, **(env_kwargs or {}))
    out = []
    try:
        for episode in episodes:
            obs, info = env.reset(seed=episode.episode, options={"start": episode.start, "goal": episode.goal})
            controller.reset(episode.episode)
            steps, done = 0, False
            while not done:
                obs, _, terminated, truncated, info = env.step(controller.act(obs))
                steps, done = steps + 1, terminated or truncated
            out.append(ReplayedEpisode(episode, bool(info.get("is_success", False)), steps))
    finally:
        env.close()
    return out


def report(replayed: list[ReplayedEpisode]) -> dict[str, Any]:
    """Counts by (stack, simulation) outcome and the episodes lost only on the stack."""
    counts = Counter((r.deployed.success, r.sim_success) for r in replayed)
    lost = [r for r in replayed if r.sim_success and not r.deployed.success]
    return {
        "episodes": len(replayed),
        "both": counts[(True, True)], "stack_only": counts[(True, False)],
        "sim_only": counts[(False, True)], "neither": counts[(False, False)],
        "lost_on_the_stack": [{"episode": r.deployed.episode, "stop": r.deployed.stop or "time-out",
                               "bearing_deg": round(r.deployed.bearing, 1), "stack_steps": r.deployed.steps,
                               "sim_steps": r.sim_steps} for r in lost],
        "per_episode": [{**asdict(r.deployed), "sim_success": r.sim_success, "sim_steps": r.sim_steps}
                        for r in replayed],
    }


def build_parser() -> argparse.ArgumentParser:
    """The command line (``--help``)."""
    parser = argparse.ArgumentParser(
        prog="python -m pectoral_gym.agents.studies.stack_gap",
        description="Replay a deploy's episodes in simulation from the same starts and goals: which episodes "
                    "the robot stack loses that the simulation reaches.",
        epilog="examples:\n  python -m pectoral_gym.agents.studies.stack_gap --policy demo_out/run --deploy "
               "demo_out/robot\n  python -m pectoral_gym.agents.studies.stack_gap --controller hand --deploy lk_hand",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    who = parser.add_mutually_exclusive_group(required=True)
    who.add_argument("--policy", metavar="RUN_OR_ZIP", help="the policy the deploy ran (a run folder or .zip)")
    who.add_argument("--controller", choices=("hand", "nmpc"), help="the baseline controller the deploy ran")
    parser.add_argument("--deploy", required=True, metavar="DIR", help="a pectoral-deploy output folder")
    parser.add_argument("--env", default=DEFAULT_ENV, help=f"simulated env id (default: {DEFAULT_ENV})")
    parser.add_argument("--out", metavar="DIR", help="where stack_gap.json goes (default: the deploy folder)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    args = build_parser().parse_args(argv)
    try:
        episodes = read_deploy(args.deploy)
        if args.policy:
            from pectoral_gym.agents.training.evaluate import trained_env_kwargs
            from pectoral_gym.agents.training.policy import load_policy

            controller, env_kwargs = load_policy(args.policy), trained_env_kwargs(args.policy, args.env)
        else:
            from pectoral_gym.agents.baselines import make_baseline
            from pectoral_gym.envs.core import EnvConfig
            from pectoral_gym.registration import registered_settings

            controller, env_kwargs = make_baseline(args.controller, EnvConfig(**registered_settings(args.env))), {}
        result = report(replay(controller, episodes, args.env, env_kwargs))
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out or args.deploy)
    out.mkdir(parents=True, exist_ok=True)
    (out / "stack_gap.json").write_text(json.dumps(result, indent=1) + "\n")
    n = result["episodes"]
    print(f"{n} episodes: goal reached on the stack and in simulation {result['both']}, in simulation only "
          f"{result['sim_only']}, on the stack only {result['stack_only']}, neither {result['neither']}")
    for row in result["lost_on_the_stack"]:
        print(f"  episode {row['episode']}: {row['stop']} after {row['stack_steps']} steps on the stack; "
              f"simulation reached the goal in {row['sim_steps']}; goal {row['bearing_deg']:+.0f} deg off the heading")
    print(f"wrote {out / 'stack_gap.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
