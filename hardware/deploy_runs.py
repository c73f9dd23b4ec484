"""The two ways a deployment runs its episodes: on one rig in real time, or each on a fresh rig in lockstep.

:func:`pectoral_gym.hardware.library.run_deployment` checks a :class:`~pectoral_gym.hardware.library.DeployRequest`
and calls one of these. Both write the steps (``steps.jsonl``'s lines) to ``log`` and the run log (``run.jsonl``)
to ``run_log``: files when the request has an output folder, else text buffers. Both return
``(summaries, link health, solver summary or None, wall time [s], ended)``; ``ended`` is ``"taken_over"`` or
``"robot_busy"`` if the robot came to serve another session (the run then ended at once and sent nothing more),
else ``""``. A bad setting that only the devices or the env find raises ``ValueError``; a device or an episode
that fails raises :class:`DeployError`.
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.hardware.clock import REAL_CLOCK
from pectoral_gym.hardware.deploy_checks import check_frame_size, first_frame
from pectoral_gym.hardware.deploy_controllers import make_controller, solver_summary
from pectoral_gym.hardware.deploy_episodes import displaced_reason, random_start, run_episodes
from pectoral_gym.hardware.deploy_request import DeployRequest
from pectoral_gym.hardware.emurig import open_rig
from pectoral_gym.hardware.params_probe import check_on_lockstep_rig, check_on_robot, probe_start
from pectoral_gym.hardware.safety.rules import install_stop_handlers
from pectoral_gym.hardware.signal_latch import SignalLatch
from pectoral_gym.model.params import FishParams

__all__ = ["DeployError", "RunResult", "probe_lockstep", "probe_wanted", "run_lockstep_episodes", "run_real_time"]

# summaries, link health, solver summary, wall time [s], why the run ended early ("" or a DISPLACED reason)
RunResult = tuple[list[dict], dict, "dict | None", float, str]
# where the steps go: the output folder's steps.jsonl, or a text buffer (run.jsonl then a second one)
Sink = Path | io.StringIO


class DeployError(RuntimeError):
    """A device or an episode failed; the message says what and where (``pectoral-deploy``'s exit status 1)."""


def _where(log: Sink) -> str:
    """`` (log so far: PATH)`` for a log on disk, nothing for one in memory."""
    return f" (log so far: {log})" if isinstance(log, Path) else ""


def _open(sink: Sink | TextIO) -> contextlib.AbstractContextManager[TextIO]:
    """A file opened for writing, or the buffer itself (left open: the caller reads it back)."""
    return open(sink, "w", encoding="utf-8") if isinstance(sink, Path) else contextlib.nullcontext(sink)


def _run_log(sink: Sink | TextIO, request: DeployRequest, settings: dict):
    """The run's :class:`pectoral_gym.runlog.RunLogWriter` (header written) into ``sink``."""
    from pectoral_gym.runlog import RunLogWriter

    return RunLogWriter(sink, "robot" if request.rig == "robot" else "emulator", settings["control_period"])


def probe_wanted(request: DeployRequest, name: str) -> bool:
    """Whether the run checks its model against the robot first (:mod:`pectoral_gym.hardware.params_probe`).

    Every run on a real robot, and every emulated one whose robot or model is not Table 1's (``params``,
    ``emulate_params``; without either the emulated robot is the model by construction), but an identification
    run (controller ``excite``), whose purpose is to find the parameters the probe would check.
    """
    return name != "excite" and (request.rig == "robot" or request.params is not None
                                 or request.emulate_params is not None)


def _probe_note(result) -> str:
    return (f"note: --params checked against the robot: {result.excess * 1000:.1f} mm beyond the camera's noise "
            f"over a {result.duration:.0f} s probe")


def probe_lockstep(request: DeployRequest, settings: dict, model: Any, notify: Callable[[str], None]) -> None:
    """The model's check on a lockstep rig of its own (``ValueError`` if it misses, :class:`DeployError`)."""
    from pectoral_gym.hardware.vision.tracker import MarkerTracker

    try:
        notify(_probe_note(check_on_lockstep_rig(request.seed, request.conditions, request.emulate_params,
                                                 safety=request.safety, tracker=MarkerTracker(model),
                                                 take_over=request.take_over, **settings)))
    except (RuntimeError, OSError) as err:
        raise DeployError(str(err)) from err


def run_real_time(request: DeployRequest, name: str, controller: Any, settings: dict, model: Any, log: Sink,
                  run_log: Sink, notify: Callable[[str], None]) -> RunResult:
    """The episodes on one robot (real or emulated in real time), one after another on one rig and env.

    ``name``: the controller's name (``controller`` is ``None`` for a baseline built here once the env is up).
    """
    from pectoral_gym.hardware.env import HardwareFishEnv
    from pectoral_gym.hardware.radio.link import RadioLink
    from pectoral_gym.hardware.vision.tracker import MarkerTracker

    emulate = request.rig != "robot"
    robot = env = None
    clock = REAL_CLOCK
    with contextlib.ExitStack() as resources:  # released last in, first out, on every path
        try:
            if emulate:
                clock, robot, port, camera = open_rig(resources, request.seed, request.conditions, False,
                                                      request.speed, request.emulate_params, request.firmware)
                inset = settings.get("start_inset", tk.START_INSET)  # the policy's own, as it trained
                hook = lambda rng: robot.place(*random_start(rng, inset))  # noqa: E731 - a hand puts the fish back
            else:
                from pectoral_gym.hardware.vision.camera import open_source

                camera = open_source(request.camera)
                resources.callback(camera.close)  # idempotent: the env closes it too
                port = request.port
                if request.robot_address is not None:
                    extra = {"take_over": True} if request.take_over else {}
                    port = RadioLink(request.port, dest64=request.robot_address, **extra)
                    resources.callback(port.close)
                hook = None if not request.prompt else (
                    lambda rng: input("Place the fish in the tank and press Enter: "))
            check_frame_size(first_frame(camera, clock=clock), model, request.calibration)
            env = HardwareFishEnv(port, camera, safety=request.safety, speed=request.speed,
                                  max_episode_steps=request.max_episode_steps, reset_hook=hook,
                                  tracker=MarkerTracker(model), take_over=request.take_over, clock=clock, **settings)
            resources.callback(env.close)
            env.run_log = resources.enter_context(_run_log(run_log, request, settings))
            resources.callback(install_stop_handlers(env.stop))
            if controller is None:
                budget = request.solve_fraction * settings["control_period"] / request.speed
                controller = make_controller(name, env.config, budget, request.safety, request.scaling)
            if probe_wanted(request, name):
                notify(_probe_note(check_on_robot(
                    env, settings.get("params", FishParams()), (lambda rng: robot.place(*probe_start()))
                    if emulate else None if not request.prompt else (lambda rng: input(
                        "Place the fish near the tank's centre, heading along its length, for a 12 s check of "
                        "--params against the robot, and press Enter: ")), request.seed)))
        except (RuntimeError, OSError) as err:  # a device that does not answer or cannot be opened (a ValueError,
            raise DeployError(str(err)) from err  # the settings found wrong by the devices or the env, goes on)
        started = time.perf_counter()
        try:
            summaries = run_episodes(env, controller, request.episodes, log, request.seed, robot,
                                     progress=request.progress)
        except (RuntimeError, OSError) as err:  # e.g. no fish seen at reset, the robot not confirming a stop
            raise DeployError(f"{err}{_where(log)}") from err
        wall_time = time.perf_counter() - started
        ended = displaced_reason(env)
    solver = solver_summary(controller) if hasattr(controller, "solve_times") else None
    return summaries, env.link.health(), solver, wall_time, ended  # the link's health once the env closed it


def run_lockstep_episodes(request: DeployRequest, name: str, controller: Any, settings: dict, log: Sink,
                          run_log: Sink, workers: Any = None) -> RunResult:
    """The episodes in lockstep, each on a fresh rig (:mod:`pectoral_gym.hardware.lockstep_jobs`), in ``jobs``.

    ``workers``: a :class:`~pectoral_gym.hardware.lockstep_pool.LockstepPool` of ``jobs`` workers started before
    (:func:`~pectoral_gym.hardware.lockstep_jobs.start_pool`), which run the episodes; ``None``: started here.

    ``log`` gets each episode's steps in episode order as soon as the episodes before it are done. The link's
    counters are summed over the episodes (:func:`pectoral_gym.hardware.lockstep_jobs.merge_link`); ``ended`` is
    ``""``: a fresh rig per episode serves nobody else.
    """
    from pectoral_gym.hardware.lockstep_jobs import (
        EpisodeError,
        LockstepJob,
        merge_link,
        merge_solver,
        run_lockstep,
        shift_records,
    )

    job = LockstepJob(name, request.policy, request.seed, request.conditions, settings, request.safety,
                      request.max_episode_steps, request.calibration, request.take_over, request.emulate_params,
                      request.scaling, request.firmware)
    started = time.perf_counter()
    with _open(log) as steps, _run_log(run_log, request, settings) as run_log_writer, SignalLatch() as latch:
        written, last = 0, None

        def write(result) -> None:
            nonlocal written, last
            steps.write(result.log)
            steps.flush()
            records, last = shift_records(result.run_log, result.episode, last)
            for record in records:  # each through the writer's own check
                getattr(run_log_writer, record.pop("type"))(**record)
            run_log_writer.flush()
            written += 1
            latch.check()  # a signal whose exception the interpreter swallowed ends the run here

        try:
            results = run_lockstep(job, range(request.episodes), request.jobs, write, progress=request.progress,
                                   controller=controller, pool=workers)
            latch.check()  # a signal lost during the last episode's clean-up
        except EpisodeError as err:
            if err.setup:  # the settings, found wrong by the rig or the env
                raise ValueError(str(err)) from err
            if err.episode == written:  # the episodes before it are in: its own steps follow them
                steps.write(err.log)
            raise DeployError(f"episode {err.episode}: {err}{_where(log)}") from err
    wall_time = time.perf_counter() - started
    return ([r.summary for r in results], merge_link([r.link for r in results]),
            merge_solver([r.solver for r in results]), wall_time, "")
