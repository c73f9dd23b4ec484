"""Batched fish models: the full blade-element model and the averaged model.

Both classes hold ``n`` fish and advance them together with the same compiled
code path, whether ``n`` is 1 or 4096::

    from pectoral_gym import FinBeat, FullModel
    model = FullModel(n=1)
    model.reset()
    model.command(right=FinBeat.from_degrees(90, 20, 1.0, 4))
    model.advance(10.0)
    model.state  # (1, 6): X, Y, psi, vx, vy, omega
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pectoral_gym.model import forcing_cache, stepping, stroke_corrections, strokes
from pectoral_gym.model.averaging import EXACT, TAYLOR
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.kloading import load_scaling
from pectoral_gym.model.ktables import KTables
from pectoral_gym.model.params import COEF_NAMES, FinBeat, FishParams, coefficient_vector

__all__ = ["FishModel", "FullModel", "AveragedModel", "FULL_INTEGRATION", "validate_beats", "REST"]

REST = FinBeat.rest()
#: The full model's integration presets, ``name: (dt_max [s], min_substeps)``. ``"reference"`` is
#: converged (halving both moves steady states by < 0.02 %); ``"fast"`` takes 8 RK4 substeps per
#: half-stroke, at most 0.05 s, and runs about 3x faster, within 0.2 % (p90; median 0.02-0.04 %) of the
#: reference on the fidelity benchmark's open-loop runs and within 1 % on its steady states
#: (``python -m pectoral_gym.scaling fidelity --candidate full-fast``; docs/model.md section 6).
FULL_INTEGRATION = {"reference": (0.01, 16), "fast": (0.05, 8)}
_FIELDS = ("bias", "amplitude", "period", "ratio")
BeatLike = FinBeat | np.ndarray | Sequence[float] | None


def validate_beats(beats: np.ndarray) -> None:
    """Check an array ``(..., 4)`` of fin patterns; raise ``ValueError`` naming the field.

    Rules: finite values, amplitude >= 0, period > 0, ratio > 0, and a stroke
    ``[bias - amplitude, bias + amplitude]`` inside ``[0, pi]``.
    """
    beats = np.asarray(beats, dtype=np.float64)
    if beats.shape[-1] != 4:
        raise ValueError(f"fin patterns need 4 values (bias, amplitude, period, ratio), got shape {beats.shape}")
    checks = (
        (~np.isfinite(beats), None, "must be finite"),
        (beats[..., 1] < 0, "amplitude", "must be >= 0 rad"),
        (beats[..., 2] <= 0, "period", "must be > 0 s"),
        (beats[..., 3] <= 0, "ratio", "must be > 0"),
        ((beats[..., 0] - beats[..., 1] < 0) | (beats[..., 0] + beats[..., 1] > np.pi), "bias",
         "with amplitude leaves [0, pi]: the fin would pass through the body"),
    )
    for bad, field, message in checks:
        if np.any(bad):
            where = np.argwhere(bad)[0]
            name = field or _FIELDS[int(where[-1])]
            row = beats[tuple(where[: beats.ndim - 1])] if field is None else beats[tuple(where)]
            raise ValueError(
                f"invalid fin pattern {np.round(row, 6).tolist()} at index {where.tolist()}: {name} {message}"
            )


def _fin_power_coef(params: FishParams) -> np.ndarray:
    """``(2,)`` each fin's ``(3 k_f S_p / 4) a_1^3``: the fin power of eq. (14) per commanded ``|g'|^3``.

    ``docs/model.md`` 3.5, with the fin's force factor in ``k_f`` and its servo scale ``a_1`` (the actual
    rate is ``a_1`` times the commanded one).
    """
    return np.array([0.75 * (params.fin_drag_constant * getattr(params, f"fin_force_scale_{side}")) * params.fin_span
                     * getattr(params, f"fin_angle_scale_{side}") ** 3 for side in ("right", "left")])


def _as_beat_array(beat: BeatLike, n: int) -> np.ndarray:
    if beat is None:
        return np.broadcast_to(REST.as_array(), (n, 4)).copy()
    if isinstance(beat, FinBeat):
        return np.broadcast_to(beat.as_array(), (n, 4)).copy()
    arr = np.asarray(beat, dtype=np.float64)
    if arr.shape == (4,):
        arr = np.broadcast_to(arr, (n, 4))
    if arr.shape != (n, 4):
        raise ValueError(f"expected a FinBeat, 4 values or an array of shape ({n}, 4), got shape {arr.shape}")
    return arr.copy()


def _setting(name: str, doc: str) -> property:
    """A model setting the kernels take: a plain attribute whose every assignment bumps ``settings_revision``."""
    private = "_" + name

    def get(self):
        return self.__dict__[private]

    def set(self, value) -> None:
        self.__dict__[private] = value
        self.settings_revision += 1

    return property(get, set, doc=doc)


class FishModel:
    """Common state and interface of the batched models.

    Args:
        n: Number of fish.
        params: One :class:`FishParams` for all fish, or one per fish.
        dt_max: Largest integration substep [s].

    Attributes:
        state: ``(n, 6)`` ``X, Y, psi, vx, vy, omega`` (m, m, rad, m/s, m/s, rad/s).
        integral: ``(n, 3)`` running integrals of ``vx, vy, omega`` since :meth:`reset` (m, m, rad).
        coef: ``(n, len(COEF_NAMES))`` packed coefficients (``params.COEF_NAMES``, indices ``params.Coef``).
        fins: ``(n, 2, strokes.FIN_FIELDS)`` half-strokes in progress (:mod:`pectoral_gym.model.strokes`).
        pending: ``(n, 2, 4)`` commanded patterns, latched at the next turning point.
        forcing_cache: ``(n, 2, forcing_cache.CACHE_FIELDS)`` the averaged model's per-fin forcing
            (:mod:`pectoral_gym.model.forcing_cache`).
        time: Simulated time since :meth:`reset` [s].
    """

    averaged: bool = False
    #: The settings the step kernels take besides the tables; setting one bumps :attr:`settings_revision`.
    SETTINGS = ("dt_max", "min_substeps", "mode", "transitions", "ripple_offsets", "fast_step")
    dt_max = _setting("dt_max", "Largest integration substep [s].")
    min_substeps = _setting("min_substeps", "Full model: least number of substeps per half-stroke.")
    mode = _setting("mode", "Averaged forcing form (``averaging.EXACT`` or ``averaging.TAYLOR``).")
    transitions = _setting("transitions", "Averaged model's ``transitions`` option (:class:`AveragedModel`).")
    ripple_offsets = _setting("ripple_offsets", "Averaged model's ``ripple_offsets`` option (:class:`AveragedModel`).")
    fast_step = _setting("fast_step", "Averaged model's ``fast_step`` option (:class:`AveragedModel`).")

    def __init__(self, n: int = 1, params: FishParams | Sequence[FishParams] | None = None, dt_max: float = 0.02):
        if int(n) < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        if not dt_max > 0:
            raise ValueError(f"dt_max must be > 0 s, got {dt_max}")
        self.n = int(n)
        self.dt_max = float(dt_max)
        self.state = np.zeros((self.n, 6))
        self.fins = np.zeros((self.n, 2, strokes.FIN_FIELDS))
        self.forcing_cache = np.zeros((self.n, 2, forcing_cache.CACHE_FIELDS))
        self.pending = np.zeros((self.n, 2, 4))
        self.integral = np.zeros((self.n, 3))
        self.coef = np.zeros((self.n, len(COEF_NAMES)))
        self.fin_power_coef = np.zeros((self.n, 2))  # per fin, 3 k S_p / 4 [W s^3/rad^3] of eq. (14)'s fin power
        self.time = 0.0
        self.min_substeps = 1
        self.mode = EXACT
        self.transitions = False
        self.ripple_offsets = False
        self.fast_step = False
        unit = ScalingFunctions.unit()
        self.tables = unit.kernel_arrays()
        self.set_params(params or FishParams())
        self.reset()

    def set_params(self, params: FishParams | Sequence[FishParams], index: np.ndarray | None = None) -> None:
        """Set model parameters for all fish, or for the fish in ``index``."""
        if isinstance(params, FishParams):
            self.coef[slice(None) if index is None else index] = coefficient_vector(params)
            self.fin_power_coef[slice(None) if index is None else index] = _fin_power_coef(params)
        else:
            rows = np.array([coefficient_vector(p) for p in params])
            target = np.arange(self.n) if index is None else np.asarray(index)
            if rows.shape[0] != target.size:
                raise ValueError(f"got {rows.shape[0]} FishParams for {target.size} fish")
            self.coef[target] = rows
            self.fin_power_coef[target] = np.array([_fin_power_coef(p) for p in params])
        forcing_cache.invalidate(self.forcing_cache, index)  # the forcing depends on them

    def reset(self, state: np.ndarray | None = None, right: BeatLike = None, left: BeatLike = None,
              index: np.ndarray | None = None) -> None:
        """Reset fish to ``state`` (default: at rest at the origin), fins at the start of a power stroke.

        Args:
            state: ``(6,)`` or ``(n, 6)`` initial states.
            right, left: Initial patterns (default: fin at rest at 90 deg).
            index: Reset only these fish (boolean mask or indices).
        """
        idx = slice(None) if index is None else index
        if isinstance(right, FinBeat | None) and isinstance(left, FinBeat | None):  # every fish the same patterns
            fins, pending = self.start_rows(right, left)
            self.state[idx] = 0.0 if state is None else state
            self.integral[idx] = 0.0
            self.fins[idx] = fins
            self.pending[idx] = pending
            forcing_cache.clear(self.forcing_cache, index)
            if index is None:
                self.time = 0.0
            return
        rows = self.n if index is None else int(np.count_nonzero(np.ones(self.n, dtype=bool)[index]))
        beats = np.stack([self._rows(right, rows, index), self._rows(left, rows, index)], axis=1)
        validate_beats(beats)
        self.state[idx] = 0.0 if state is None else state
        self.integral[idx] = 0.0
        strokes.init_fins(self.fins, self.pending, beats, None if index is None else index)
        forcing_cache.clear(self.forcing_cache, index)
        if index is None:
            self.time = 0.0

    def start_rows(self, right: FinBeat | None, left: FinBeat | None) -> tuple[np.ndarray, np.ndarray]:
        """One fish's fins ``(2, FIN_FIELDS)`` and pending patterns ``(2, 4)`` at the start of ``right, left``.

        Made by ``strokes.init_fins`` (the one rule) for the last pair of objects asked for and kept: an env
        resets to the same patterns (``REST``) every episode, and copying two rows costs less than the rule's
        assignments. Kept by identity (a ``FinBeat`` is frozen): equal patterns may differ in a zero's sign.
        """
        kept = self.__dict__.get("_start")
        if kept is None or kept[0] is not right or kept[1] is not left:
            fins, pending = np.zeros((1, 2, strokes.FIN_FIELDS)), np.zeros((1, 2, 4))
            strokes.init_fins(fins, pending, np.stack([_as_beat_array(right, 1), _as_beat_array(left, 1)], axis=1))
            kept = self._start = (right, left, fins[0], pending[0])
        return kept[2], kept[3]

    def _rows(self, beat: BeatLike, rows: int, index: np.ndarray | None) -> np.ndarray:
        """Patterns ``(rows, 4)`` for the selected fish; per-fish arrays of all ``n`` fish are indexed."""
        if index is not None and not isinstance(beat, FinBeat) and beat is not None:
            arr = np.asarray(beat, dtype=np.float64)
            if arr.shape == (self.n, 4):
                return arr[index].copy()
        return _as_beat_array(beat, rows)

    def command(self, right: BeatLike = None, left: BeatLike = None, validate: bool = True) -> None:
        """Command new fin patterns (``None`` keeps a fin at rest), applied by the parameter-change rule."""
        beats = np.stack([_as_beat_array(right, self.n), _as_beat_array(left, self.n)], axis=1)
        self.command_array(beats, validate=validate)

    def command_array(self, beats: np.ndarray, mask: np.ndarray | None = None, validate: bool = True) -> None:
        """Command patterns from an array ``(n, 2, 4)`` (right fin first) for the fish in ``mask``."""
        if validate:
            if beats.shape != (self.n, 2, 4):
                raise ValueError(f"beats must have shape ({self.n}, 2, 4), got {beats.shape}")
            validate_beats(beats)
        strokes.command_fins(self.fins, self.pending, beats, np.ones(self.n, dtype=np.bool_) if mask is None else mask)

    def advance(self, duration: float) -> np.ndarray:
        """Integrate all fish for ``duration`` seconds; returns :attr:`state`."""
        if not duration >= 0:
            raise ValueError(f"duration must be >= 0 s, got {duration}")
        stepping.advance(self.state, self.fins, self.forcing_cache, self.pending, self.integral, self.coef, duration,
                         self.dt_max, self.min_substeps, self.averaged, self.mode, self._packed_tables,
                         self.corrections)
        self.time += duration
        return self.state

    #: Bumped whenever a setting the kernels take (:data:`SETTINGS`) or :attr:`tables` is set, so a
    #: caller that keeps them (``envs.fused.FusedStep``) sees the change by one comparison.
    settings_revision: int = 0

    @property
    def corrections(self) -> int:
        """The averaged model's corrections as the kernels take them (:func:`~.stroke_corrections.corrections`)."""
        return (stroke_corrections.corrections(self.transitions, self.ripple_offsets, self.fast_step)
                if self.averaged else 0)

    @property
    def tables(self) -> KTables:
        """The scaling-function tables the averaged forcing uses (:class:`pectoral_gym.model.ktables.KTables`)."""
        return self._tables

    @property
    def packed_tables(self) -> tuple:
        """:attr:`tables` as the plain tuple the compiled kernels take (the same object until ``tables`` is set)."""
        return self._packed_tables

    @tables.setter
    def tables(self, tables: KTables) -> None:
        self._tables = tables
        self.settings_revision += 1
        self._packed_tables = tuple(tables)  # what the kernels take (ktables.as_tables)
        forcing_cache.invalidate(self.forcing_cache)  # the cached forcing depends on them

    def fin_work(self) -> np.ndarray:
        """Hydrodynamic work of each fin since :meth:`reset` [J], ``(n, 2)`` (right fin first).

        The power of eq. (14), ``(3 k S_p / 4) |g'|^3``, integrated over the strokes the fins
        actually swept (transitional and parking strokes included), in closed form per
        half-stroke (``strokes.swept_cube``). The same in both models, which follow the same
        strokes; the envs' energy term prices the commanded patterns' regular beat instead.
        """
        return self.fins[:, :, strokes.SWEPT] * self.fin_power_coef

    def fin_angles(self) -> tuple[np.ndarray, np.ndarray]:
        """Current commanded fin angles and rates, ``(n, 2)`` each (right fin first) [rad, rad/s].

        The angles the firmware and the servo limits see; a fin with a servo map (``FishParams.fin_angle_*``)
        is actually at ``a_0 + a_1`` times them.
        """
        return strokes.fin_angles(self.fins)

    def active_beats(self) -> np.ndarray:
        """Patterns of the half-strokes in progress, ``(n, 2, 4)``."""
        return self.fins[:, :, strokes.BIAS:strokes.RATIO + 1].copy()


class FullModel(FishModel):
    """Blade-element model, eqs. (1)-(20), integrated through every fin beat.

    Args:
        n: Number of fish.
        params: Model parameters (one, or one per fish).
        dt_max: Largest RK4 substep [s]; default: the ``integration`` preset's (0.01 s for
            ``"reference"``). Larger steps stay stable: the step also shrinks where the fin's
            peak force would drive the body dynamics out of RK4's accurate range
            (``stepping._full_stable_step``).
        min_substeps: Least number of substeps per half-stroke; default: the preset's (16 for
            ``"reference"``, so the fastest default stroke, T_p = 0.5 s, zeta = 5: 0.083 s, gets
            steps of 5 ms). Halving both reference values changes the cycle-averaged steady state
            by < 0.02 % for the strongest patterns of the default action range (e.g. (60 deg, 30 deg,
            0.5 s, 5)), fourth-order convergence.
        integration: ``"reference"`` (default) or ``"fast"`` (:data:`FULL_INTEGRATION`: 8 substeps per
            half-stroke, at most 0.05 s; its speed and accuracy against the reference: docs/model.md section 6).
    """

    averaged = False

    def __init__(self, n: int = 1, params: FishParams | Sequence[FishParams] | None = None,
                 dt_max: float | None = None, min_substeps: int | None = None, integration: str = "reference"):
        if integration not in FULL_INTEGRATION:
            raise ValueError(f"integration must be one of {sorted(FULL_INTEGRATION)}, got {integration!r}")
        preset_dt, preset_substeps = FULL_INTEGRATION[integration]
        super().__init__(n, params, preset_dt if dt_max is None else dt_max)
        min_substeps = preset_substeps if min_substeps is None else min_substeps
        if int(min_substeps) < 1:
            raise ValueError(f"min_substeps must be >= 1, got {min_substeps}")
        self.min_substeps = int(min_substeps)


class AveragedModel(FishModel):
    """Cycle-averaged model with scaled forcing, eq. (25).

    Args:
        n: Number of fish.
        params: Model parameters (one, or one per fish).
        scaling: Scaling functions K; ``"identified"`` (default) loads the
            shipped coefficients file, ``None``/``"none"`` uses K = 1.
        forcing: ``"exact"`` (closed-form Bessel averages, default) or
            ``"taylor"`` (the paper's eqs. 26-28).
        dt_max: Largest RK4 step [s]; default 0.25 s. The step also shrinks to
            stay well inside RK4's stability limit of the yaw and drag damping
            (``stepping._stable_step``): over 120 s of random fin commands the
            position differs by ~1 cm from a 0.002 s reference, the same order
            as the full model's own discretisation error.
        transitions: Add, during every transitional half-stroke (the first from rest, the
            first after each pattern change), the exact mean blade-element forcing of the
            half-stroke actually swept minus that of the latched pattern's regular
            half-stroke, and on a recovery stroke after a power stroke of another pattern
            the impulse offset that power stroke left (``docs/model.md`` section 3.7).
            Zero at periodic steady state, so K and the steady-state figures are
            unchanged. Default on; ``False`` gives the cycle averages alone
            (the model of ``PectoralFish-Averaged-v0``). Measured in ``docs/validation/fidelity/``.
        ripple_offsets: Keep the model's state at the beat mean of the full model's: when a fin
            starts a pattern (from rest, after a reset, at a change) or parks, spread over that
            half-stroke the change of its beat's mean impulse offset
            (:func:`pectoral_gym.model.averaging.ripple_offset`, ``docs/model.md`` section 3.8). Zero
            while a pattern is kept, so K and the steady states are unchanged. Default on.
        fast_step: Integrate with the fast step (:mod:`pectoral_gym.model.fast_step`: polynomial
            ``arctan`` and ``arcsin`` on their bounded ranges, the heading's ``cos, sin`` carried between
            substeps, substeps up to ``h * rate = 2`` instead of 1.5). Numerically different; default off.
    """

    averaged = True

    def __init__(self, n: int = 1, params: FishParams | Sequence[FishParams] | None = None,
                 scaling: ScalingFunctions | str | None = "identified", forcing: str = "exact",
                 dt_max: float = 0.25, transitions: bool = True, ripple_offsets: bool = True,
                 fast_step: bool = False):
        super().__init__(n, params, dt_max)
        self.fast_step = bool(fast_step)
        self.transitions = bool(transitions)
        self.ripple_offsets = bool(ripple_offsets)
        if forcing not in ("exact", "taylor"):
            raise ValueError(f"forcing must be 'exact' or 'taylor', got {forcing!r}")
        self.mode = EXACT if forcing == "exact" else TAYLOR
        if isinstance(scaling, str):
            if scaling not in ("identified", "none"):
                raise ValueError(f"scaling must be 'identified', 'none' or a ScalingFunctions, got {scaling!r}")
            if scaling == "identified":
                scaling = load_scaling("identified")  # the one K loader
            else:
                scaling = None
        self.scaling = scaling or ScalingFunctions.unit()
        self.tables = self.scaling.kernel_arrays()
