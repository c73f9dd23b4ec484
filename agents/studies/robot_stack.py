"""The robot stack as agents/ sees it: an interface, and its implementation found through an entry point.

The benchmark's robot columns (:mod:`pectoral_gym.agents.studies.benchmark`) and the demo's robot-stack stage
(:mod:`pectoral_gym.agents.training.demo`) run controllers through the robot stack, which lives in
``pectoral_gym.hardware``: a layer above agents/, which must not import it. So agents/ names what it needs
(:class:`RobotStack`) and finds an implementation the way Gymnasium finds env plugins, through the entry point
group :data:`ENTRY_POINT_GROUP` of the installed distributions. This project declares one, ``emulated``
(``pyproject.toml``: the emulated robot in lockstep, :mod:`pectoral_gym.hardware.studies.deployment`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

__all__ = ["DEFAULT_STACK", "ENTRY_POINT_GROUP", "ROBOT_COLUMNS", "PreparingRobotStack", "RobotStack",
           "RobotStackNotFoundError", "prepared_workers", "robot_stack"]

ENTRY_POINT_GROUP = "pectoral_gym.robot_stacks"
DEFAULT_STACK = "emulated"
#: The benchmark's robot-stack column labels: ideal radio and camera, and the degraded target conditions.
ROBOT_COLUMNS = ("robot", "robot+degraded")


class RobotStackNotFoundError(LookupError):
    """No robot stack of that name is installed (the message says which group and how to install one)."""


class RobotStack(Protocol):
    """What the benchmark and the demo need of a robot stack (a module or an object).

    Attributes:
        ROBOT_CONTROLLERS: The baselines it drives by name (trained policies run through their folder).
    """

    ROBOT_CONTROLLERS: tuple[str, ...]

    def run_robot_stack(self, out: str | Path, episodes: int, seed: int, controller: str = "policy",
                        policy: str | Path | None = None, *, max_steps: int | None = None,
                        task: str | None = None, progress: bool = False, capture: bool = False,
                        jobs: int = 1) -> dict[str, Any]:
        """Run ``episodes`` seeded episodes (episode ``k``: ``seed + k``) into ``out``; returns their summary.

        The summary holds at least ``episodes``, ``seed``, ``success`` (mean and 95 % CI), ``safety_stops``
        (reason -> episodes), ``wall_time_s`` [s] and ``command`` (how to run the same from a shell).
        Raises ``RuntimeError`` if the run is refused or does not finish.
        """
        ...

    def robot_cells(self, label: str, task: str, controllers: tuple[str, ...],
                    policies: dict[str, tuple[Any, str]], episodes: int, seed: int, out: Path,
                    say: Callable[[str], None], errors: dict[str, str],
                    max_steps: int | None = None) -> list[dict[str, Any]]:
        """The benchmark cells of column ``label`` (one of :data:`ROBOT_COLUMNS`) and ``task``.

        One cell per controller it drives and per policy trained on ``task``; a failing cell's error is recorded in
        ``errors`` under ``controller/label/task`` instead of ending the benchmark.
        """
        ...


@runtime_checkable
class PreparingRobotStack(RobotStack, Protocol):
    """A robot stack whose worker processes can start before their run is known (optional for a stack).

    A caller with other work to do first (the demo trains the policy the run will drive) starts them with
    :meth:`prepare_workers`, and passes the context's value to :meth:`run_robot_stack` as ``workers``.
    """

    def prepare_workers(self, jobs: int) -> contextlib.AbstractContextManager[Any]:
        """Start ``jobs`` workers for a later ``run_robot_stack(..., jobs=jobs, workers=<this context's value>)``.

        They do their start-up while the caller works, then wait for the run, which ends them; the block's end
        ends them on every path.
        """
        ...

    def run_robot_stack(self, out: str | Path, episodes: int, seed: int, controller: str = "policy",
                        policy: str | Path | None = None, *, max_steps: int | None = None,
                        task: str | None = None, progress: bool = False, capture: bool = False,
                        jobs: int = 1, workers: Any = None) -> dict[str, Any]:
        """:meth:`RobotStack.run_robot_stack`, its episodes run by ``workers`` (``None``: workers of its own)."""
        ...


def prepared_workers(stack: RobotStack, jobs: int) -> contextlib.AbstractContextManager[Any]:
    """``stack``'s workers started now (:meth:`PreparingRobotStack.prepare_workers`); ``None`` for a stack without.

    The value is ``run_robot_stack``'s ``workers`` (pass it only if it is not ``None``).
    """
    if isinstance(stack, PreparingRobotStack):
        return stack.prepare_workers(jobs)
    return contextlib.nullcontext(None)


def robot_stack(name: str = DEFAULT_STACK) -> RobotStack:
    """The installed robot stack ``name`` (the object its entry point names, loaded).

    Raises:
        RobotStackNotFoundError: None of that name is installed in :data:`ENTRY_POINT_GROUP`.
    """
    found = entry_points(group=ENTRY_POINT_GROUP, name=name)
    if not found:
        known = sorted(e.name for e in entry_points(group=ENTRY_POINT_GROUP))
        raise RobotStackNotFoundError(f"no robot stack {name!r} is installed (entry point group {ENTRY_POINT_GROUP!r}; "
                                f"installed: {known or 'none'}): install pectoral-gym with its hardware package "
                                "(pip install -e .), which declares 'emulated'")
    return next(iter(found)).load()
