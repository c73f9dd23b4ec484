"""On-the-spot turns for the NMPC: a fin cycle that turns the fish within about a body length.

The NLP (:mod:`pectoral_gym.agents.nmpc.problem`) plans regular fin beats on their cycle averages, and its
tightest turn is the turning circle (radius ~0.25 m, docs/notes/2026-12-01-nmpc-rounds.md). Changing the pattern every
control period makes every half-stroke a transitional one: the fin sweeps from where it is to the
new pattern's turning point and exerts the forces of that sweep (docs/model.md 3.7). With the right
sequence the sweeps' surge impulses cancel and their yaw impulses add. :data:`SPIN_CYCLE` is such a
sequence of four control periods at the NMPC's fixed period (0.5 s) and ratio (5), found by a
cross-entropy search on the averaged model from rest (``docs/validation/nmpc/spin_cycle.py``, which
also checks it on the full model), among the cycles the robot's servos execute as commanded (the
rules of :mod:`pectoral_gym.model.finrules`: every stroke, transitional ones included, within the servos' peak
rate, each parameter within its rate limit): on the averaged model 103 deg in 6 s with the centre of
mass within 0.08 m of its start, on the full model 89-93 deg within 0.06-0.12 m from each phase. The
turning circle needs 0.5 m of room for a half turn. Without the servo rules the search finds a cycle
that turns 143-147 deg in 6 s on the full model, with sweeps up to 100 deg in a power stroke's
0.08 s: the servos would stretch its strokes, and on the emulated robot it turns 24-48 deg instead
(docs/notes/2026-12-01-nmpc-rounds.md, "Goal, fifth round"). The servo check takes a command as reaching the fins at
once; the firmware rate-limits what each turning point latches and stretches the transitional strokes
(:mod:`pectoral_gym.agents.controllers.firmware_path`; the robot's band shield predicts it so).

:class:`SpinTurns` prices such turns on the planning model
(:func:`pectoral_gym.agents.controllers.fin_map.planning_spec`: the env's averaged model, or on a full env the averaged
model with its transitional strokes and the identified K), whose transitional strokes the NLP's smooth model lacks. It
keeps a copy of that model whose fins follow every command the controller sends, so it knows each fin's
angle and stroke phase (both models latch patterns on the same schedule, docs/model.md 5); each
control step it rolls out, in one batch from the estimated body state, the spin left or right from
each phase of the cycle, either until the target lies straight ahead (within :data:`AIM`) or for 1 to 8
intervals (:data:`SPIN_LENGTHS`), then straight on. A half turn takes more than the 5 s horizon; the
aiming candidates carry the turn to where the planner's continuation (the hand law) can take over.
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.controllers.turning import SPIN_CYCLE, mirror  # re-exported: the cycle's home is CasADi-free
from pectoral_gym.agents.nmpc.problem import FinInputs
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.kloading import held_yaw_damping
from pectoral_gym.model.spec import AveragedSpec

__all__ = ["SPIN_CYCLE", "SPIN_LENGTHS", "SPIN_PERIOD", "SPIN_RATIO", "SpinTurns", "mirror"]

SPIN_PERIOD = 0.5  # s: the fin-beat period the cycle was found for (the NMPC's fixed period)
SPIN_RATIO = 5.0  # the speed ratio it was found for (the NMPC's fixed ratio)
# Intervals a candidate spins before it swims straight (besides the candidates that spin until they face
# the target): 2 x 4 x (6 + 1) = 56 candidates, below the batch size from which the model kernels run on
# all cores (pectoral_gym.model.jit.PARALLEL_MIN_ITEMS): the controller shares the machine with the robot's
# camera loop, and threads on busy cores made solve times spike.
SPIN_LENGTHS = (1, 2, 3, 4, 6, 8)
AIM = np.radians(10.0)  # an aiming candidate stops spinning once the target is this close to straight ahead


class SpinTurns:
    """The spin candidates of the NMPC's screening, rolled out on the averaged model with transitional strokes.

    Args:
        config: The environment settings (ranges, control period, parameters).
        fins: The controller's :class:`pectoral_gym.agents.controllers.fin_map.FinMap` (fixed period and ratio).
        scaling: Scaling functions of the planning model (``None``: K = 1).
        horizon: Control intervals per candidate.
        spec: The planning model's spec (default: ``fins.spec``,
            :func:`pectoral_gym.agents.controllers.fin_map.planning_spec`); its rollouts use ``scaling`` as K.
        straight: Inputs ``(4,)`` after the spin (FinInputs order).

    Attributes:
        available: ``False`` when the cycle does not fit the env's ranges, when the fins' fixed period and
            ratio differ from those it was found for, or when the env is the averaged model without
            transitional strokes (the spec's ``transitions`` off, the registered env's default): there the
            cycle's patterns act through their cycle averages alone and do not turn the fish on the spot.
        candidates: Number of candidates.
    """

    def __init__(self, config: EnvConfig, fins: FinMap, scaling: ScalingFunctions | None, horizon: int,
                 straight: np.ndarray, spec: AveragedSpec | None = None):
        self.config = config
        self.dt = float(config.control_period)
        self.horizon = int(horizon)
        self._period, self._ratio = fins.period, fins.ratio
        b_low, b_high = config.bias_range
        a_low, a_high = config.amplitude_range
        tol = 1e-9
        spec = (spec or fins.spec).replace(yaw_damping=held_yaw_damping(scaling))
        self.spec = spec if scaling is not None else spec.replace(scaling="none")
        self.available = bool(
            spec.transitions
            and math.isclose(fins.period, SPIN_PERIOD) and math.isclose(fins.ratio, SPIN_RATIO)
            and np.all(SPIN_CYCLE[:, :2] >= a_low - tol) and np.all(SPIN_CYCLE[:, :2] <= a_high + tol)
            and np.all(SPIN_CYCLE[:, 2:] >= b_low - tol) and np.all(SPIN_CYCLE[:, 2:] <= b_high + tol))
        self._straight = np.asarray(straight, dtype=np.float64)
        rows = []  # (turn, phase, length): length 0 spins until the target is ahead
        for turn in range(2):
            for phase in range(len(SPIN_CYCLE)):
                rows += [(turn, phase, n) for n in (0, *SPIN_LENGTHS) if n <= self.horizon]
        self._rows = np.array(rows)
        self.candidates = len(rows)
        self._shadow = self.spec.build(1, config.params, k=scaling)
        self._batch = self.spec.build(len(rows), config.params, k=scaling)
        self.reset()

    def _patterns(self, u: np.ndarray) -> np.ndarray:
        """Fin patterns ``(..., 2, 4)`` (right fin first) of inputs ``(..., 4)``, through the env's action mapping."""
        u = FinInputs(*np.moveaxis(np.asarray(u, dtype=np.float64), -1, 0))
        shape = np.shape(u.amplitude_right)
        period, ratio = np.full(shape, self._period), np.full(shape, self._ratio)
        right = np.stack([u.bias_right, u.amplitude_right, period, ratio], -1)
        left = np.stack([u.bias_left, u.amplitude_left, period, ratio], -1)
        beats = np.stack([right, left], -2)
        return self.config.decode(self.config.encode(beats))  # what the env latches (clipped to its ranges)

    def reset(self) -> None:
        """Start of an episode: the copy's fins at rest at the start of a power stroke, as the envs reset them."""
        self._shadow.reset()

    def applied(self, u: np.ndarray) -> None:
        """Follow the command ``u (4,)`` the controller sent for one control period."""
        self._shadow.command_array(self._patterns(u)[None], validate=False)
        self._shadow.advance(self.dt)

    def rollouts(self, state: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Inputs ``(candidates, horizon, 4)``, states ``(candidates, 6, horizon + 1)`` and fin work ``(candidates,)``.

        The fin work [J] is that of the strokes the fins actually sweep over the horizon, transitional ones
        included (:meth:`pectoral_gym.model.models.FishModel.fin_work`).

        From the body state ``(6,)``, the fins where the copy's are (angle, stroke phase, latched and
        pending patterns). ``target``: the position ``(2,)`` the aiming candidates turn to.
        """
        b, n = self._batch, self.horizon
        turn, phase, length = self._rows.T
        b.state[:] = state
        b.fins[:] = self._shadow.fins[0]
        b.pending[:] = self._shadow.pending[0]
        b.forcing_cache[:] = self._shadow.forcing_cache[0]
        x = np.empty((b.n, 6, n + 1))
        u = np.empty((b.n, n, 4))
        x[:, :, 0] = state
        work = -b.fin_work().sum(1)
        aiming = length == 0
        side = np.where(turn == 0, 1.0, -1.0)  # the sign of the bearing a turn reduces
        for k in range(n):
            bearing = np.arctan2(target[1] - b.state[:, 1], target[0] - b.state[:, 0]) - b.state[:, 2]
            bearing = (bearing + math.pi) % (2 * math.pi) - math.pi
            aiming &= side * bearing > AIM  # once ahead (or past it), straight on
            spins = aiming | (k < length)
            step = SPIN_CYCLE[(phase + k) % len(SPIN_CYCLE)]
            cycle = np.where(turn[:, None] == 0, step, mirror(step))
            u[:, k] = np.where(spins[:, None], cycle, self._straight)
            b.command_array(self._patterns(u[:, k]), validate=False)
            x[:, :, k + 1] = b.advance(self.dt)
        return u, x, work + b.fin_work().sum(1)

    def input_cost(self, u: np.ndarray, u_prev: np.ndarray, width: np.ndarray, w_change: float) -> np.ndarray:
        """The NLP's input-change term ``w_change |dz / width|^2`` of inputs ``(candidates, horizon, 4)``.

        ``z`` are the NLP's inputs (squared amplitudes, biases; :mod:`pectoral_gym.agents.nmpc.problem`), ``u_prev`` the
        command still acting.
        """
        u = np.asarray(u)
        z = np.concatenate([u[..., :2] ** 2, u[..., 2:]], -1)
        z_prev = np.concatenate([np.asarray(u_prev)[:2] ** 2, np.asarray(u_prev)[2:]])
        steps = np.diff(np.concatenate([np.broadcast_to(z_prev, z[:, :1].shape), z], 1), axis=1) / width
        return w_change * np.sum(steps**2, axis=(-1, -2))

    def beat_work(self, u: np.ndarray) -> np.ndarray:
        """Sum over intervals and fins of ``gA^3 dt`` [rad^3 s] of inputs ``(candidates, horizon, 4)``.

        The NLP prices the fin work of the commanded regular beats as ``energy_rate`` times this; a spin's
        real work is in its transitional strokes, which :meth:`rollouts` returns instead.
        """
        return self.dt * np.sum(np.asarray(u)[..., :2] ** 3, axis=(-1, -2))
