"""A controller on the emulated robot through the whole robot stack, in lockstep: one run, its summary and metrics.

:func:`run_robot_stack` runs :func:`pectoral_gym.hardware.library.run_deployment` on the emulated robot in
lockstep, in this process (radio link and firmware rules, rendered camera, tracker, observer, safety supervisor;
the emulated robot runs the full model with nominal parameters), the run that ``python -m
pectoral_gym.hardware.deploy --emulate --lockstep`` makes, and summarises its episodes from memory. The demo
(:mod:`pectoral_gym.agents.training.demo`) and the benchmark's robot columns
(:mod:`pectoral_gym.agents.studies.benchmark`) reach this module as the ``emulated`` robot stack
(:mod:`pectoral_gym.agents.studies.robot_stack`, the entry point group ``pectoral_gym.robot_stacks``): agents/
imports nothing from hardware/. The same seed gives the same run (lockstep); only the wall time differs.

What the logs can tell (per episode):

* from the summary (``summary.json``): success, the safety stop's reason
  (``pectoral_gym.hardware.safety.supervisor.PRIORITY``; empty for none), steps, return, final distance (from the
  measured pose), the NMPC's solve times;
* from the step records (``steps.jsonl``), whose ``true_pose`` is the emulated robot's centre-of-mass pose after
  the reset and after each step: the path and the tracking error of the true pose, and wall contacts. The log holds
  no fin angles, so a contact is the geofence's outline (:func:`pectoral_gym.model.tank.clearance`: body
  capsule, and a disc of the fin span around each fin pivot, which holds the fin tip wherever it points)
  across a wall line at a logged pose: an upper bound for the fins, and a touch between two steps
  (0.5 s apart) is not seen.

Fin work is not logged by the deploy, so it is not reported.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.studies.robot_stack import ROBOT_COLUMNS
from pectoral_gym.hardware.deploy import report_lines
from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.hardware.library import DeployError, DeployRequest, run_deployment

__all__ = ["DEGRADED", "NOMINAL", "ROBOT_CONDITIONS", "ROBOT_CONTROLLERS", "conditions_argv", "prepare_workers",
           "robot_cell", "robot_cells", "run_robot_stack"]

NOMINAL = RigConditions()
#: The degraded conditions of the robot stack's targets: radio 10 % loss each way and 100 ms one-way latency, camera
#: 10 % frame drops, camera pose noise 5 mm / 2 deg (standard deviations).
DEGRADED = RigConditions(radio_latency=0.1, radio_loss=0.1, camera_drop=0.1, pose_noise=(0.005, math.radians(2.0)))
#: Benchmark column label (:data:`pectoral_gym.agents.studies.robot_stack.ROBOT_COLUMNS`) -> conditions of the
#: emulated radio and camera.
ROBOT_CONDITIONS = dict(zip(ROBOT_COLUMNS, (NOMINAL, DEGRADED), strict=True))
#: Baselines the deploy can drive (``--controller``); trained policies run through ``--policy``.
ROBOT_CONTROLLERS = ("hand", "nmpc")


def conditions_argv(conditions: RigConditions) -> list[str]:
    """The deploy's ``--radio-*``, ``--camera-*`` and ``--pose-noise-*`` flags for ``conditions`` (none for none)."""
    flags = (("--radio-latency", conditions.radio_latency), ("--radio-jitter", conditions.radio_jitter),
             ("--radio-loss", conditions.radio_loss), ("--camera-latency", conditions.camera_latency),
             ("--camera-drop", conditions.camera_drop), ("--pose-noise-mm", conditions.pose_noise[0] * 1e3),
             ("--pose-noise-deg", math.degrees(conditions.pose_noise[1])))
    return [item for flag, value in flags if value for item in (flag, repr(float(value)))]


def prepare_workers(jobs: int) -> contextlib.AbstractContextManager[Any]:
    """``jobs`` workers for a later :func:`run_robot_stack` with ``jobs`` and a trained policy, started now.

    A context manager whose value is passed on as :func:`run_robot_stack`'s ``workers``: the workers do their
    start-up (imports, numba's kernels, torch) at the lowest priority while the caller does other work, e.g.
    trains the policy, then wait for the run (:func:`pectoral_gym.hardware.lockstep_jobs.start_pool`). The run
    ends them; so does the block's end, on every path (SIGTERM included). The calling program's top-level code
    must sit under ``if __name__ == "__main__":``, as the workers are spawned.
    """
    from pectoral_gym.hardware.lockstep_jobs import start_pool

    return start_pool(jobs, policy=True)


def run_robot_stack(out: str | Path, episodes: int, seed: int, controller: str = "policy",
                    policy: str | Path | None = None, conditions: RigConditions = NOMINAL,
                    max_steps: int | None = None, task: str | None = None, progress: bool = False,
                    capture: bool = False, jobs: int = 1, workers: Any = None) -> dict[str, Any]:
    """Run the deploy on the emulated robot in lockstep and summarise it.

    Args:
        out: The deploy's output folder (``summary.json``, ``steps.jsonl``, ``run.jsonl``, ``trajectory.png``).
        episodes: Episodes, >= 1; episode ``k`` is seeded with ``seed + k``.
        seed: Seed of the starts, targets and every emulated condition.
        controller: ``"policy"`` (needs ``policy``), ``"hand"`` or ``"nmpc"``.
        policy: Run folder or ``.zip`` of a trained policy.
        conditions: Radio and camera conditions of the emulated rig.
        max_steps: Steps per episode (``None``: the deploy's default, 240 = 2 min).
        task: ``"goal"`` or ``"track"`` (``None``: the policy's own, else ``goal``).
        progress: Show the deploy's progress bar.
        capture: Write the deploy's closing lines to ``<out>/deploy.txt`` instead of the terminal.
        jobs: Episodes run at once, each worker process with its own rig (the deploy's ``--jobs``; the results are
            the same for any number). The calling program's top-level code must sit under
            ``if __name__ == "__main__":``, as the workers are spawned.
        workers: :func:`prepare_workers`'s value for ``jobs`` workers, which then run the episodes (and are ended
            by the run); ``None``: the run starts its own.

    Returns:
        ``{"episodes", "seed", "task", "control_period" [s], "conditions", "success" (mean and 95 % CI),
        "safety_stops" (reason -> episodes), "wall_contacts" (episodes), "wall_time_s", "solver" (NMPC only,
        else ``None``), "link", "command", "out", "per_episode"}``; ``per_episode`` holds one dict per
        episode (:func:`robot_cell` turns them into metrics). ``command`` is the ``pectoral-deploy`` command line
        of the same run.

    Raises:
        RuntimeError: If the deploy refuses its settings or does not finish (the deploy's exit status, the
            reason and the folder named).
    """
    from pectoral_gym.agents.training.metrics import summarize

    out = Path(out)
    # no --controller for a policy: the deploy's default, and the demo's command as it always read
    argv = [*([] if controller == "policy" else ["--controller", controller]),
            *([] if policy is None else ["--policy", str(policy)]),
            "--emulate", "--lockstep", "--episodes", str(episodes), "--seed", str(seed), "--out", str(out),
            "--no-prompt", "--nice", "0", *([] if progress else ["--no-progress"]),
            *([] if jobs == 1 else ["--jobs", str(jobs)]),
            *([] if max_steps is None else ["--max-episode-steps", str(max_steps)]),
            *([] if task is None else ["--task", task]), *conditions_argv(conditions)]
    command = "python -m pectoral_gym.hardware.deploy " + " ".join(argv)
    out.mkdir(parents=True, exist_ok=True)
    try:
        request = DeployRequest(controller=controller, policy=policy, episodes=episodes, seed=seed, task=task,
                                rig="lockstep", conditions=conditions, jobs=jobs, out=out, progress=progress,
                                **({} if max_steps is None else {"max_episode_steps": max_steps}))
        run = run_deployment(request, notify=lambda line: print(line, file=sys.stderr),  # as the deploy's
                             workers=workers)
    except (ValueError, DeployError) as err:  # the deploy's exit status 2 (a setting) or 1 (a device, an episode)
        status = 2 if isinstance(err, ValueError) else 1
        raise RuntimeError(f"the robot-stack run ({command}) ended with status {status}: {err}; see {out}") from err
    lines = report_lines(request, run)
    if capture:
        (out / "deploy.txt").write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    else:
        print("\n".join(lines))
    summary = json.loads(json.dumps(run.summary))  # as summary.json holds it (lists for tuples)
    runs = summary["episodes"]
    per_episode = _episode_records(summary, run.steps)
    return {"episodes": len(runs), "seed": seed, "task": summary["settings"]["task"],
            "control_period": summary["settings"]["control_period"],
            "conditions": summary.get("emulation", {}).get("conditions"),
            "success": summarize(np.array([float(e["success"]) for e in runs])).as_dict(),
            "safety_stops": dict(Counter(e["safety_stop"] for e in runs if e["safety_stop"])),
            "wall_contacts": sum(e["wall_contact"] for e in per_episode),
            "wall_time_s": summary.get("wall_time"), "solver": summary.get("solver"), "link": summary.get("link"),
            "command": command, "out": str(out), "per_episode": per_episode}


def _episode_records(summary: dict[str, Any], steps: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The summary's episodes, each with its true path, tracking error and wall clearance from the step records."""
    from pectoral_gym.model import tank
    from pectoral_gym.model.params import FishParams

    outline = tank.Outline.from_params(FishParams())  # the emulated robot's (nominal parameters)
    poses: dict[int, list[list[float]]] = {}
    errors: dict[int, list[float]] = {}
    for rec in steps:
        if "true_pose" not in rec:
            continue
        poses.setdefault(rec["episode"], []).append(rec["true_pose"])
        if rec.get("step", 0) > 0:  # the samples after each step, as the simulated tracking error
            errors.setdefault(rec["episode"], []).append(math.dist(rec["true_pose"][:2], rec["target"][:2]))
    records = []
    for e in summary["episodes"]:
        true = np.asarray(poses.get(e["episode"], []), dtype=float).reshape(-1, 3)
        clear = min((float(tank.clearance(x, y, psi, outline).min()) for x, y, psi in true), default=math.nan)
        records.append({**e, "path_length": float(np.sum(np.hypot(*np.diff(true[:, :2], axis=0).T))),
                        "tracking_error": float(np.mean(errors[e["episode"]])) if errors.get(e["episode"])
                        else math.nan,
                        "min_clearance": clear, "wall_contact": bool(clear < 0.0)})
    return records


def robot_cell(run: dict[str, Any], controller: str, label: str) -> dict[str, Any]:
    """A benchmark cell from :func:`run_robot_stack`'s result: the metrics that apply, and the robot's own figures.

    Args:
        run: :func:`run_robot_stack`'s result.
        controller: The row's controller name.
        label: The column label (:data:`ROBOT_CONDITIONS`).

    Returns:
        ``controller, env, env_id, task, seed, n_episodes, metrics`` as the simulated cells (``success``,
        ``time_to_goal`` [s] for ``goal``, ``tracking_error`` [m] for ``track``; ``path_length`` [m],
        ``final_distance`` [m], ``return``, ``length`` [steps], ``min_clearance`` [m]) and ``robot``: safety stops
        by reason, wall contacts (episodes), wall time per step [ms], the NMPC's solve times (or ``None``),
        conditions, command, output folder.
    """
    from pectoral_gym.agents.training.metrics import summarize

    eps = run["per_episode"]
    period = float(run["control_period"])

    def column(key: str) -> np.ndarray:
        return np.array([float(e[key]) for e in eps])

    success = column("success")
    values = {"path_length": column("path_length"), "final_distance": column("final_distance"),
              "return": column("return"), "length": column("steps"), "min_clearance": column("min_clearance")}
    if run["task"] == "goal":
        values["success"] = success
        values["time_to_goal"] = np.where(success > 0, column("steps") * period, np.nan)  # as metrics.time_to_goal
    else:
        values["tracking_error"] = column("tracking_error")
    steps = int(sum(e["steps"] for e in eps))
    wall_time = run.get("wall_time_s")
    robot = {"safety_stops": run["safety_stops"], "wall_contacts": run["wall_contacts"],
             "wall_ms_per_step": None if wall_time is None or not steps else 1e3 * wall_time / steps,
             "solver": run["solver"], "conditions": run["conditions"], "command": run["command"], "out": run["out"]}
    return {"controller": controller, "env": label, "env_id": "emulated robot (lockstep)", "task": run["task"],
            "seed": run["seed"], "n_episodes": run["episodes"],
            "metrics": {k: summarize(v).as_dict() for k, v in values.items()}, "robot": robot}


def robot_cells(label: str, task: str, controllers: tuple[str, ...], policies: dict[str, tuple[Any, str]],
                episodes: int, seed: int, out: Path, say: Callable[[str], None], errors: dict[str, str],
                max_steps: int | None = None) -> list[dict[str, Any]]:
    """The benchmark's robot-stack cells of one column and task, one deploy run each.

    Args:
        label: The column (:data:`ROBOT_CONDITIONS`).
        task: ``"goal"`` or ``"track"``.
        controllers: The benchmark's baselines; those the deploy drives (:data:`ROBOT_CONTROLLERS`) get a cell.
        policies: Name -> (loaded policy, run folder or ``.zip``); a policy gets a cell on the task it trained on.
        episodes: Episodes per cell (< 1: no cells).
        seed: Episode ``k`` is seeded with ``seed + k``.
        out: Folder of the deploy runs, one subfolder per cell.
        say: Called with a short message before each cell.
        errors: Where a failing cell's error is recorded, under ``controller/label/task``.
        max_steps: Steps per episode (``None``: the deploy's 240).
    """
    # The deploy drives hand, nmpc and policies only: the random baseline is the simulated table's floor,
    # and random fin commands through the safety supervisor would say nothing about the stack.
    entries = [(name, None) for name in controllers if name in ROBOT_CONTROLLERS]
    # a policy runs on its own task only (the deploy refuses another one); "goal" where its folder does not say
    entries += [(name, path) for name, (policy, path) in policies.items()
                if (getattr(policy, "trained", None) or {}).get("task", "goal") == task]
    cells = []
    for name, path in entries if episodes >= 1 else ():
        say(f"{name} on {label} (emulated robot, lockstep), {task}, {episodes} episodes")
        try:
            run = run_robot_stack(out / f"{name}_{label}_{task}", episodes, seed, controller="policy" if path else name,
                                  policy=path, conditions=ROBOT_CONDITIONS[label], max_steps=max_steps, task=task,
                                  capture=True)
            cells.append(robot_cell(run, name, label))
        except Exception as error:  # noqa: BLE001 - one failing cell must not lose the others
            errors[f"{name}/{label}/{task}"] = f"{type(error).__name__}: {error}"
    return cells
