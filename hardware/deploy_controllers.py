"""The controllers ``pectoral-deploy`` builds by name, and the figures of a solving controller's run.

Below both the deploy (:mod:`pectoral_gym.hardware.deploy_runs`) and its lockstep workers
(:mod:`pectoral_gym.hardware.lockstep_jobs`), which build the same controllers.
"""

from __future__ import annotations

import numpy as np

from pectoral_gym.hardware.deploy_checks import shipped_k_problem
from pectoral_gym.hardware.safety.rules import SafetyConfig

__all__ = ["make_controller", "solver_summary"]


def make_controller(name: str, config, step_budget: float, safety: SafetyConfig | None = None,
                    scaling: str | None = None):
    """The ``nmpc`` or ``hand`` baseline for the robot's env config; NMPC steps end within ``step_budget`` [s].

    ``scaling``: the K file they plan with (:func:`pectoral_gym.agents.controllers.fin_map.planning_spec`), the
    robot's own where ``config.params`` are not Table 1's; ``None``: the shipped K.

    Both keep out of the stopping band of the env's geofence (``safety``, default
    :class:`pectoral_gym.hardware.safety.rules.SafetyConfig`) widened as the robot-ready envs widen the robot's
    (:func:`pectoral_gym.versions.with_measurement_margin`; :data:`pectoral_gym.versions.ROBOT`'s ``stop_rule`` for
    the default ``safety``), the band they train and evaluate them with: the
    NMPC plans with it (``pectoral_gym.agents.controllers.stop_band``) and both filter their commands through
    the backup shield (``pectoral_gym.agents.controllers.band_shield``) with it, predicting through the firmware's
    command path; the NMPC's shield there also keeps a backup's side and wants
    :data:`pectoral_gym.agents.nmpc.shield.ROBOT_RESERVE` safe backups after a command. The NMPC plans no on-the-spot
    spins here (``spin=False``: through the robot's command path the spin cycle drifts where the planning model
    turns it on the spot); the shield keeps its spin backups. The measurements behind these choices are in the
    research notes (``docs/notes/2026-12-03-robot-stack-rounds.md``, ``docs/notes/2026-12-04-nmpc-stops-2.md``).
    """
    from pectoral_gym.agents.baselines import make_baseline
    from pectoral_gym.versions import with_measurement_margin

    safety = safety or SafetyConfig()
    band = with_measurement_margin(safety.stop_rule)
    if (problem := shipped_k_problem(name, config.params, scaling)) is not None:
        raise ValueError(problem)
    if name == "nmpc":
        return make_baseline("nmpc", config, step_budget=step_budget, stop_band=band, spin=False,
                             scaling=scaling)
    if name == "hand":
        return make_baseline("hand", config, shield={"band": band}, scaling=scaling)
    return make_baseline(name, config)


def solver_summary(controller) -> dict:
    """Solve times (p50/p95/max [ms]), failed and late steps of an NMPC controller."""
    times = np.asarray(controller.solve_times, dtype=float) * 1e3
    if times.size == 0:
        return {"solves": 0, "failures": int(controller.failures), "late": int(controller.late)}
    return {"solves": int(times.size), "p50_ms": float(np.percentile(times, 50)),
            "p95_ms": float(np.percentile(times, 95)), "max_ms": float(times.max()),
            "failures": int(controller.failures), "late": int(controller.late)}
