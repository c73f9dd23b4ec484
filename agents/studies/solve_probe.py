"""The time-to-solve probe: the wall time until a training run first reaches a success rate on the full model.

A :class:`SolveProbe` is passed to :func:`pectoral_gym.agents.training.train.train` as ``probe``: after every
``every``-th periodic evaluation it evaluates the current policy (deterministic, with its observation statistics at
that moment) on the latest full id (:data:`FULL_ID`) for ``episodes`` seeded episodes. The first probe at or above
``threshold`` marks the run solved at that evaluation's ``elapsed_s`` (training wall time, the probes'
own time left out) and ``timesteps``; that policy is then evaluated once more on ``confirm_episodes``
other episodes, because the first of several noisy probes to cross a threshold overestimates the
policy (the maximum of noisy estimates is biased upwards).

Three disjoint sets of episode seeds keep this honest (:func:`check_held_out` checks them):

* the periodic evaluation, which selects ``best_model.zip``: ``train seed + EVAL_SEED_OFFSET + k``
  (:data:`pectoral_gym.agents.training.train.EVAL_SEED_OFFSET`) on the training env;
* the probe: ``PROBE_SEED + k`` on the full model (it selects nothing; it only times);
* the confirmation and the reported results: ``REPORT_SEED + k`` (the demo's
  :data:`pectoral_gym.agents.training.demo.EVAL_SEED`).

Training episodes start from ``train seed + i`` (env slot ``i``) and then from each slot's generator.
:func:`pectoral_gym.agents.studies.solve_time.measure_time_to_solve` trains seeds with the probe.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pectoral_gym.agents.training.demo import EVAL_SEED as REPORT_SEED
from pectoral_gym.agents.training.train import EVAL_SEED_OFFSET
from pectoral_gym.versions import LATEST_FULL

__all__ = ["FULL_ID", "PROBE_SEED", "REPORT_SEED", "SOLVED", "SolveProbe", "check_held_out"]

FULL_ID = LATEST_FULL  # the full model in the demo's training version (seeds.TRAIN_ENV)
PROBE_SEED = 20_000  # probe episode k is reset with PROBE_SEED + k
SOLVED = 0.95  # the target: success on the full model


def check_held_out(train_seeds: list[int], n_envs: int, eval_episodes: int, probe_episodes: int,
                   report_episodes: int, probe_seed: int = PROBE_SEED, report_seed: int = REPORT_SEED) -> None:
    """Raise ``ValueError`` if two of the seed sets of the module docstring overlap.

    Args:
        train_seeds: Training seeds.
        n_envs: Training env slots (first resets ``seed + i``).
        eval_episodes: Episodes of each periodic evaluation.
        probe_episodes: Episodes of each probe (0: no probe).
        report_episodes: Reported (and confirmation) episodes.
        probe_seed: First probe episode seed.
        report_seed: First reported episode seed.
    """
    sets: dict[str, set[int]] = {
        "probe": set(range(probe_seed, probe_seed + probe_episodes)),
        "reported": set(range(report_seed, report_seed + report_episodes)),
    }
    for seed in train_seeds:
        sets[f"training resets of seed {seed}"] = set(range(seed, seed + n_envs))
        sets[f"periodic evaluation of seed {seed}"] = set(
            range(seed + EVAL_SEED_OFFSET, seed + EVAL_SEED_OFFSET + eval_episodes))
    held_out = ("probe", "reported")
    for name in held_out:
        for other, values in sets.items():
            if other != name and (other not in held_out or name < other):
                common = sets[name] & values
                if common:
                    raise ValueError(f"episode seeds of the {name} episodes and the {other} overlap "
                                     f"(e.g. {min(common)}); choose other --probe-seed/--eval-seed or seeds")


@dataclass
class SolveProbe:
    """Times a training run to a success rate on the full model (see the module docstring).

    Use ``train(..., probe=probe, on_evaluation=probe.on_evaluation)``; after training,
    :meth:`summary` has the result.

    Attributes:
        threshold: Success rate that counts as solved.
        episodes: Episodes per probe.
        every: Probe after every ``every``-th periodic evaluation (1: each).
        seed: Probe episode ``k`` is reset with ``seed + k``.
        confirm_episodes: Episodes of the confirmation of the solving policy (0: none).
        confirm_seed: Confirmation episode ``k`` is reset with ``confirm_seed + k``.
        stop_on_solve: Stop training once solved (``on_evaluation`` returns ``False``).
        keep_probing: Go on probing once solved (the history is then the learning curve on the full model).
        env_id: Environment of the probe.
        env_kwargs: Its arguments (``task`` must be ``goal``: success is defined there).
        history: One entry per probe: ``timesteps``, ``elapsed_s``, ``success``.
        solved: The first entry at or above ``threshold`` (with ``confirm_success``), else ``None``.
    """

    threshold: float = SOLVED
    episodes: int = 100
    every: int = 1
    seed: int = PROBE_SEED
    confirm_episodes: int = 100
    confirm_seed: int = REPORT_SEED
    stop_on_solve: bool = False
    keep_probing: bool = False
    env_id: str = FULL_ID
    env_kwargs: dict[str, Any] = field(default_factory=lambda: {"task": "goal"})
    history: list[dict[str, Any]] = field(default_factory=list)
    solved: dict[str, Any] | None = None
    _calls: int = 0

    def __post_init__(self) -> None:
        if not 0.0 < self.threshold <= 1.0:
            raise ValueError(f"threshold must be in (0, 1], got {self.threshold}")
        if self.episodes < 1 or self.every < 1 or self.confirm_episodes < 0:
            raise ValueError(f"episodes and every must be >= 1 and confirm_episodes >= 0, got {self.episodes}, "
                             f"{self.every}, {self.confirm_episodes}")
        if self.env_kwargs.get("task", "goal") != "goal":
            raise ValueError(f"time to solve needs the goal task (success), got {self.env_kwargs.get('task')!r}")
        self.env_kwargs = {k: v for k, v in self.env_kwargs.items() if k != "randomize"} | {"task": "goal"}

    def __call__(self, controller: Any, record: dict[str, Any]) -> dict[str, Any] | None:
        """Evaluate ``controller`` when due and not solved yet.

        The ``probe`` of :func:`pectoral_gym.agents.training.train.train`.
        """
        from pectoral_gym.agents.training.evaluate import evaluate

        self._calls += 1
        if (self.solved is not None and not self.keep_probing) or (self._calls - 1) % self.every:
            return None
        result = evaluate(controller, self.env_id, n_episodes=self.episodes, seed=self.seed,
                          env_kwargs=self.env_kwargs)
        entry = {"timesteps": int(record["timesteps"]), "elapsed_s": float(record["elapsed_s"]),
                 "success": float(result.metrics["success"].mean)}
        if self.solved is None and entry["success"] >= self.threshold:
            if self.confirm_episodes:
                confirm = evaluate(controller, self.env_id, n_episodes=self.confirm_episodes,
                                   seed=self.confirm_seed, env_kwargs=self.env_kwargs)
                entry["confirm_success"] = float(confirm.metrics["success"].mean)
            self.solved = entry
        self.history.append(entry)
        return entry

    def on_evaluation(self, record: dict[str, Any]) -> bool:
        """The ``on_evaluation`` of :func:`pectoral_gym.agents.training.train.train`: ``False`` (stop) once solved."""
        return not (self.stop_on_solve and self.solved is not None)

    def summary(self) -> dict[str, Any]:
        """The result as a JSON-ready dict.

        Returns:
            ``solved``, ``time_to_solve_s``, ``steps_to_solve``, ``probe_success``, ``confirm_success``
            (``None`` where not solved), ``best_probe_success``, ``threshold``, ``probe_episodes``,
            ``probes`` (the history).
        """
        solved = self.solved or {}
        return {"solved": self.solved is not None, "threshold": self.threshold,
                "time_to_solve_s": solved.get("elapsed_s"), "steps_to_solve": solved.get("timesteps"),
                "probe_success": solved.get("success"), "confirm_success": solved.get("confirm_success"),
                "best_probe_success": max((e["success"] for e in self.history), default=None),
                "probe_episodes": self.episodes, "probes": list(self.history)}
