"""One row of the task table: a :class:`Task`, what a fish task is, and the ``info`` entries it gives.

A :class:`Task` names the functions of one task (how its episode is drawn and started, its compiled
reward kernel and the builds of the observation loop with that kernel) and the keys of its ``info``:
the reward terms in summation order, ``"distance"``, then its :class:`InfoField` extras. The contract
of each function is in :mod:`pectoral_gym.envs.tasks.table`, which holds the rows (``TASK_TABLE``) and
adds new ones (``register_task``). A row's ``info`` function is built from its fields, or, when given by
hand (the built-in tasks' faster dict displays), checked against them.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from pectoral_gym.envs.layout import N_OUT, O_DISTANCE
from pectoral_gym.model.jit import KernelPair

__all__ = ["InfoField", "Task"]


class InfoField(NamedTuple):
    """One ``info`` entry after the reward terms: ``key`` reads ``out[index]`` (``flag``: ``out[index] > 0.5``)."""

    key: str
    index: int
    flag: bool = False


@dataclass(frozen=True)
class Task:
    """One row of the task table (:mod:`pectoral_gym.envs.tasks.table`'s docstring: the contract of each function).

    Attributes:
        name: The ``task=`` value.
        id: ``cfg[C_TASK]``; 0 and 1 are the built-in ``goal`` and ``track``.
        terms: ``(info key, out index)`` of the reward terms, in summation order.
        extra_info: The ``info`` entries after ``"distance"``.
        draw: ``draw(rng, cfg) -> (8,)`` random numbers of one episode.
        start: ``start(index, draws, cfg, ep, start)``: targets into ``ep``, start states into ``start``.
        reward_one: The task's kernel ``reward_one(i, state, cfg, ep, fish, obs, out)`` (its contract: the table);
            the simulated envs' step calls it (``envs.fused.step_builds``).
        observe: Serial/parallel builds of :func:`pectoral_gym.envs.tasks.table.observe_body` with ``reward_one``:
            ``observe.run(state, skip, cfg, ep, fish, obs, out)`` (the robot env's step).
        fit_start: ``fit_start(draws, x, y, rng, cfg)``: adapt the draws to a measured start pose (or ``None``).
        info: ``info(out_row) -> dict``: the env's ``info`` (:attr:`info_fields` as numpy scalars, flags as
            ``np.bool_``). Built from the fields when not given; a given one must agree with them on probe
            rows (keys in order, values, types), else ``ValueError``.
    """

    name: str
    id: int
    terms: tuple[tuple[str, int], ...]
    extra_info: tuple[InfoField, ...]
    draw: Callable[[np.random.Generator, np.ndarray], np.ndarray]
    start: Callable[..., Any]
    reward_one: Callable[..., Any]
    observe: KernelPair
    fit_start: Callable[[np.ndarray, float, float, np.random.Generator, np.ndarray], None] | None = None
    info: Callable[[np.ndarray], dict] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        built = _info_builder(self.info_fields)
        if self.info is None:
            object.__setattr__(self, "info", built)
        elif not _same_info(self.info, built):
            raise ValueError(f"task {self.name!r}: its info function does not give info_fields")

    @property
    def info_fields(self) -> tuple[InfoField, ...]:
        """Every ``info`` entry in order: the reward terms, ``"distance"``, then ``extra_info``."""
        return (*(InfoField(k, i) for k, i in self.terms), InfoField("distance", O_DISTANCE), *self.extra_info)


def _same_info(info: Callable[[np.ndarray], dict], built: Callable[[np.ndarray], dict]) -> bool:
    """Whether ``info`` gives the same keys in the same order, values and types as ``built`` on probe rows."""
    for row in (np.arange(N_OUT) * 0.25, np.arange(N_OUT)[::-1] * 0.5 - 1.0):
        a, b = info(row), built(row)
        if list(a) != list(b) or any(type(a[k]) is not type(b[k]) or a[k] != b[k] for k in b):
            return False
    return True


def _info_builder(fields: Sequence[InfoField]) -> Callable[[np.ndarray], dict]:
    """``out_row -> info``: the fields' values as numpy scalars (flags as ``np.bool_``)."""
    for f in fields:
        if not (isinstance(f.key, str) and f.key.isidentifier() and 0 <= int(f.index) < N_OUT):
            raise ValueError(f"info field {f!r}: the key must be an identifier and the index an out slot "
                             f"0..{N_OUT - 1}")
    keys = tuple(f.key for f in fields)
    values = operator.itemgetter(*(int(f.index) for f in fields), N_OUT - 1)  # a tuple even for one field
    flags = tuple(f.key for f in fields if f.flag)

    def info(out: np.ndarray) -> dict:
        entries = dict(zip(keys, values(out), strict=False))  # numpy scalars; the padding entry is left out
        for key in flags:
            entries[key] = entries[key] > 0.5
        return entries

    return info
