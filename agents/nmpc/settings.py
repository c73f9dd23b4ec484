"""Settings of the NMPC baseline: one frozen dataclass.

Read by :mod:`pectoral_gym.agents.nmpc.controller` and :mod:`pectoral_gym.agents.nmpc.problem`.
Every field is documented with what it does and, where it was chosen on measurements, with the
development runs behind its default (``docs/notes/2026-12-01-nmpc-rounds.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

from pectoral_gym.agents.nmpc.reference import PREDICTIONS
from pectoral_gym.model.tank import StopRule

__all__ = ["NMPCSettings"]

_SOLVERS = ("ipopt", "sqp")


@dataclass(frozen=True)
class NMPCSettings:
    """Settings of the NMPC baseline (fixed once the problem is built).

    Attributes:
        horizon: Number of control intervals predicted.
        substeps: RK4 steps per control interval (the yaw damping needs steps below ~0.1 s).
        latch_delay: Seconds the previous command still acts in the first interval; ``None``: the
            mean wait until a stroke turning point.
        w_distance: Weight of the distance to the goal/reference at each interval end [1/m].
        w_terminal: Extra weight of the distance at the end of the horizon [1/m].
        distance_scale: The distance cost is ``sqrt(|e|^2 + distance_scale^2)`` [m]: the distance far
            out, quadratic within ``distance_scale`` (its curvature there is ``1 / distance_scale``,
            which a few SQP iterations must handle). ``None``: 1 mm for ``goal``, 5 cm for ``track``
            (``pectoral_gym.agents.nmpc.compare`` on the full model: ``track`` seeds 100-101, 17.7 cm at 1 mm, 12.5 cm
            at 2 cm, 8.1 cm at 5 cm; ``goal`` seeds 100-109, 10 of 10 at 1 mm, 9 of 10 at 5 cm).
        w_heading: Weight of ``1 - cos(bearing of the aim point)`` at each interval end; the aim point is
            the target, for ``track`` its predicted position ``heading_lookahead`` seconds further on.
        heading_scale: Distance [m] below which the heading term fades out (towards ``w_heading``, the cost
            of a target abeam). ``None``: 5 cm for ``goal``, 1 mm for ``track``.
        heading_lookahead: Seconds [s] the aim point of the heading term lies ahead of the reference along
            its predicted velocity (``track``); ``None``: 0 for ``goal``, 5 s for ``track``. Aimed at the
            reference point itself, with the 5 cm fade, the heading term paid the fish to hang back: 8 cm behind
            the reference cost less than on it, and the fish lagged 7-9 cm on straight stretches
            (docs/notes/2026-12-01-nmpc-rounds.md, ``track`` fifth round; development seeds 106-119: 6.7 cm at
            2.5 s, 5.0 at 5 s and 10 s).
        reference: How the moving target is predicted over the horizon
            (:class:`pectoral_gym.agents.nmpc.reference.ReferencePredictor`): ``"line"`` (straight on with its
            velocity), ``"arc"`` (its velocity turning at the observed rate) or ``"conic"`` (along the ellipse fitted to
            its observed path, the arc before); ``None``: ``"conic"`` for ``track``, ``"line"`` for ``goal``.
        turn_then_straight: Also screen the turns held for 2 s then straight; ``None``: for ``goal`` only
            (for ``track`` the turn-then-straight candidates almost never won the steps they were screened
            in; four rollouts fewer per step).
        w_change: Weight of squared input changes between intervals (inputs scaled to [0, 1]).
        w_reach: Weight of the terminal reachability term: how far the target lies inside the fish's
            turning circle at the end of the horizon [1/m]. The horizon is far shorter than a loop
            (tens of seconds), so without it the fish circles a target it passed closely.
        turn_radius: Smallest turning radius assumed by the reachability term [m] (the full model
            turns no tighter than about 0.23 m; see docs/notes/2026-12-01-nmpc-rounds.md).
        w_wall: Weight of the squared wall violation [1/m^2].
        wall_margin: Keep nose and tail this far from the walls [m].
        energy_weight: Weight of the fin work [1/J]; ``None``: the env's ``energy_weight``.
        smoothing: Speed scale [m/s] smoothing ``|V|``, ``alpha`` and ``|omega|`` at rest
            (:func:`pectoral_gym.model.symbolic.body_accel_sx`).
        max_solves: Solves per control step at most. Each step first screens candidate plans (the
            shifted last plan; swim straight; turn left or right, held or for 2 s then straight) by
            the cost of their model rollouts, then solves from the cheapest ``max_solves`` of them: a
            discrete choice of the turn direction that a few SQP iterations from one guess cannot make.
        adapt_rate: Rate of the online correction of the thrust and yaw-moment gains from the measured
            motion (0: no adaptation). The averaged model with placeholder or imperfect K, or a
            randomised fish, turns and swims at other rates than predicted; the gains absorb that.
        gain_bounds: Bounds of the two gains.
        initial_gains: The thrust and yaw-moment gains at the start of an episode.
        blocks: Move blocking: the number of control intervals each planned input is held for
            (``None``: one input per interval). ``sum(blocks)`` must equal ``horizon``. Fewer distinct
            inputs make fewer evaluations of the forcing (the identified K's splines, most of the
            NLP's cost) and let a long horizon stay cheap with coarse late intervals.
        solver: ``"ipopt"`` (interior point, solved to convergence or the limits below) or ``"sqp"``
            (CasADi's ``sqpmethod`` with the ``qrqp`` active-set QP solver, exact Hessian regularised
            to be convex, warm-started with the shifted primal and dual solution: with a small
            ``max_iter`` this is the real-time-iteration scheme).
        max_iter: Iteration limit per solve (IPOPT or SQP iterations).
        hessian: SQP only: ``"exact"`` (Hessian of the Lagrangian) or ``"cost"`` (of the objective
            alone, without the model's curvature: far cheaper, slower to converge).
        max_cpu_time: IPOPT time limit per solve [s].
        step_budget: Wall time allowed for the whole control step [s]: no further solve starts after
            it, and a step whose solves end later than it uses the fallback (a late plan is not applied).
        velocity: ``"obs"``: body velocities from the observation (the envs report their means over
            the control period); ``"difference"``: mean velocities over the last control period from
            the change of pose, for observation sources that give instantaneous velocities (the full
            model's swing within each fin beat and alias when sampled once per period); ``"auto"``:
            ``"difference"`` on the full model, ``"obs"`` on the averaged model.
        observer: Turn those period-mean velocities into current ones: the model's velocities at the
            end of the last period plus the offset between the measured and the model's period means.
        transitions: Let the NLP plan with the expected impulse of transitional strokes (module docstring).
            ``None``: as the planning model does (``transitions`` of
            :func:`pectoral_gym.agents.controllers.fin_map.planning_spec`: the env version's on the averaged model,
            :data:`pectoral_gym.model.spec.AVERAGED`'s on the full model). Off by default whatever the planning model
            (a planner's choice, not the model's; the spin candidates' rollouts keep the planning model as it is):
            on seeds 100-109 (``pectoral_gym.agents.nmpc.compare``, no step budget) the NLP with the impulse
            reached 6 of 10 goals on the full model against 10 of 10 without, and 8 of 10 on the averaged env
            either way: the optimiser leans on an impulse whose real value depends on the unobserved phase.
        hand_candidate: Also screen the plan of :class:`pectoral_gym.agents.baselines.HandController` in closed loop
            on the planning model (its deadlock escape and long way round near walls). ``None``: for
            ``goal`` only (``pectoral_gym.agents.nmpc.compare --task track --seeds 100-101``: 14.7 cm with it, 8.1 cm
            without).
        w_togo: Weight [1/m] of the cost-to-go beyond the horizon in the screening and in the choice
            between a solution and its guess: the turn-then-straight path from the horizon's end to
            the target (radius ``turn_radius``, :func:`pectoral_gym.agents.controllers.turning.turn_path_length`) minus
            the straight distance (already in the NLP's terminal cost). ``None``: 3 for ``goal``
            (``w_distance + w_terminal``), 0 for ``track`` (a moving reference).
        togo_wall_margin: Room [m] a turning circle of the cost-to-go must leave to the walls (beyond
            half a body; the hand law's ``wall_margin``); a turn with less is charged up to a full
            extra circle (0: walls ignored).
        togo_steps: ``goal``: intervals the hand law is continued on the model after the horizon to
            price a candidate (the NLP's distance and wall terms;
            :meth:`pectoral_gym.agents.nmpc.controller.NMPCController._continuation`);
            0: the turn-then-straight cost-to-go alone.
        deep_candidates: With ``togo_steps``: how many of the cheapest screened candidates (plus the hand
            law's) are priced with the continuation.
        reach_fraction: ``goal``: a rollout whose interval end comes within this fraction of the goal
            radius is priced up to there only (:meth:`pectoral_gym.agents.nmpc.pricing.PlanPricing._reach_cost`); 0:
            off. Development seeds 100-199 (``docs/notes/2026-12-01-nmpc-rounds.md``, fourth round): on the full
            model 0.94 against 0.90 without (0.93 at 1.0: one wall hit more).
        bias_span: Largest planned bias offset from the middle of the bias range [rad] (0: both biases
            held at 90 deg, as the hand law holds them); ``None``: the whole identified range; ``"auto"``:
            0 (both tasks; before the ``track`` fifth round ``None`` for ``track``). Tilted biases planned on
            the averaged model did not act on the full model as planned (seed 149: 112/45 deg just before a
            wall hit); held at 90 deg, with the reach pricing, the time to goal on seeds 100-199 fell from
            23.7 to 20.2 s (full model); ``track`` on seeds 106-119: 2.4 cm against 4.4 cm with the range.
            With ``solver="ipopt"``, biases fixed by equal bounds kept one solve in the tests from
            converging in 300 iterations (it converges in 27 with them free); pass ``None`` there.
        spin: Also screen on-the-spot turns (:mod:`pectoral_gym.agents.nmpc.spin`: a fin cycle whose transitional
            strokes turn the fish within ~0.1 m, rolled out on the averaged model with its transitional strokes);
            a spin candidate that costs less than the solved plan is applied as it is. ``None``: for
            ``goal`` only.
        stop_band: The :class:`~pectoral_gym.model.tank.StopRule` (or its ``(margin, reaction_time,
            contact_speed)``) of the robot env's stopping-distance band
            (:mod:`pectoral_gym.agents.controllers.stop_band`, the rule of
            ``pectoral_gym.hardware.safety.geofence.Geofence``): the wall terms then keep the fish's whole outline out
            of the band instead of its nose and tail ``wall_margin`` (and ``togo_wall_margin``) from the walls. ``None``
            (the simulated envs, which have no such band): off. ``pectoral_gym.hardware.deploy`` passes its safety
            settings.
        shield: Filter every command through the hand law's backup shield
            (:class:`pectoral_gym.agents.nmpc.shield.CommandShield`): a command is sent only if some backup
            manoeuvre keeps the planning model's rollout out of the band after it, else the best backup's first
            interval. ``None``: on where ``stop_band`` is set.
        shield_margin: Clearance [m] the shield adds to the band's margin in its rollouts.
        shield_spread: Speed [m/s] the shield adds towards every wall in its rollouts.
        shield_spin: Let the shield back up with the on-the-spot spin (``BandShield``'s ``spin``).
        shield_firmware: Let the shield predict the commands through the robot firmware's command path
            (``BandShield``'s ``firmware``: the rate rule at the latch, stretched transitions); ``None``: where
            ``stop_band`` is given on an env without a band of its own (the robot's deploy).
        shield_keep_side: Let the shield keep a backup's kind and side while one of them is safe (``BandShield``'s
            ``keep_side``); ``None``: where it predicts through the firmware.
        shield_reserve: Safe backups the plan's command must leave for the shield to send it (``BandShield``'s
            ``reserve``); ``None``: ``pectoral_gym.agents.nmpc.shield.ROBOT_RESERVE`` through the firmware, else 1.
        stall_steps: ``goal``: consecutive plans that rest both fins, with the fish slower than ``stall_speed``
            and outside the goal, after which the hand law drives until a plan moves again
            (:meth:`pectoral_gym.agents.nmpc.handover.HandOver._unstall`); 0: off.
        stall_speed: Speed [m/s] below which a resting plan counts towards ``stall_steps``.
        circle_steps: ``goal``: with the goal inside the turning circle (radius ``turn_radius``) and its distance
            fallen by less than ``circle_progress`` over this many steps, the hand law drives for the rest of the
            episode (swims on out of the circle, turns back, steers in; :mod:`pectoral_gym.agents.nmpc.handover`);
            0: off.
        circle_progress: Distance [m] the fish must close on a goal inside its turning circle over
            ``circle_steps`` steps for the plan to keep driving.
    """

    horizon: int = 10
    substeps: int = 6
    latch_delay: float | None = None
    w_distance: float = 1.0
    w_terminal: float = 2.0
    distance_scale: float | None = None
    w_heading: float = 0.3
    heading_scale: float | None = None
    heading_lookahead: float | None = None
    reference: str | None = None
    turn_then_straight: bool | None = None
    w_change: float = 0.02
    w_reach: float = 2.0
    turn_radius: float = 0.25
    w_wall: float = 1000.0
    wall_margin: float = 0.03
    energy_weight: float | None = None
    smoothing: float = 1e-3
    adapt_rate: float = 0.3
    gain_bounds: tuple[float, float] = (0.1, 3.0)
    initial_gains: tuple[float, float] = (1.0, 1.0)
    max_solves: int = 1
    blocks: tuple[int, ...] | None = (1, 1, 2, 2, 4)
    solver: str = "sqp"
    max_iter: int = 8
    hessian: str = "cost"
    max_cpu_time: float = 0.35
    step_budget: float = 0.25
    velocity: str = "obs"
    observer: bool = True
    transitions: bool | None = False
    hand_candidate: bool | None = None
    w_togo: float | None = None
    togo_wall_margin: float = 0.15
    togo_steps: int = 10
    deep_candidates: int = 1
    reach_fraction: float = 0.75
    bias_span: float | str | None = "auto"
    spin: bool | None = None
    stop_band: StopRule | None = None
    shield: bool | None = None
    shield_margin: float = 0.02
    shield_spread: float = 0.0
    shield_spin: bool = True
    shield_firmware: bool | None = None
    shield_keep_side: bool | None = None
    shield_reserve: int | None = None
    stall_steps: int = 6
    stall_speed: float = 0.02
    circle_steps: int = 4
    circle_progress: float = 0.02

    def __post_init__(self) -> None:
        if min(int(self.horizon), int(self.substeps), int(self.max_iter), int(self.max_solves)) < 1:
            raise ValueError("horizon, substeps, max_iter and max_solves must be >= 1")
        if self.velocity not in ("auto", "obs", "difference"):
            raise ValueError(f"velocity must be 'auto', 'obs' or 'difference', got {self.velocity!r}")
        if self.latch_delay is not None and not self.latch_delay >= 0:
            raise ValueError(f"latch_delay must be >= 0 s or None, got {self.latch_delay!r}")
        if not self.max_cpu_time > 0:
            raise ValueError(f"max_cpu_time must be > 0 s, got {self.max_cpu_time!r}")
        if not self.step_budget > 0:
            raise ValueError(f"step_budget must be > 0 s, got {self.step_budget!r}")
        if self.hessian not in ("exact", "cost"):
            raise ValueError(f"hessian must be 'exact' or 'cost', got {self.hessian!r}")
        if self.bias_span not in (None, "auto") and not (isinstance(self.bias_span, float | int)
                                                         and self.bias_span >= 0):
            raise ValueError(f"bias_span must be >= 0 rad, None or 'auto', got {self.bias_span!r}")
        if not 0.0 <= self.reach_fraction <= 1.0:
            raise ValueError(f"reach_fraction must be in [0, 1], got {self.reach_fraction!r}")
        if int(self.togo_steps) < 0 or int(self.deep_candidates) < 1 or not self.togo_wall_margin >= 0:
            raise ValueError(f"togo_steps must be >= 0, deep_candidates >= 1 and togo_wall_margin >= 0 m, got "
                             f"{self.togo_steps!r}, {self.deep_candidates!r}, {self.togo_wall_margin!r}")
        if self.reference not in (None, *PREDICTIONS):
            raise ValueError(f"reference must be None or one of {PREDICTIONS}, got {self.reference!r}")
        if self.heading_lookahead is not None and not self.heading_lookahead >= 0:
            raise ValueError(f"heading_lookahead must be >= 0 s or None, got {self.heading_lookahead!r}")
        if self.solver not in _SOLVERS:
            raise ValueError(f"solver must be one of {_SOLVERS}, got {self.solver!r}")
        if self.stop_band is not None:
            try:
                object.__setattr__(self, "stop_band", StopRule.coerce(self.stop_band))  # the rule checks itself
            except ValueError as err:
                raise ValueError(f"stop_band: {err}") from None
        if not (self.shield_margin >= 0 and self.shield_spread >= 0):
            raise ValueError(f"shield_margin and shield_spread must be >= 0, got {self.shield_margin!r}, "
                             f"{self.shield_spread!r}")
        if min(int(self.stall_steps), int(self.circle_steps)) < 0 or not (self.stall_speed >= 0
                                                                       and self.circle_progress >= 0):
            raise ValueError(f"stall_steps, stall_speed, circle_steps and circle_progress must be >= 0, got "
                             f"{self.stall_steps!r}, {self.stall_speed!r}, {self.circle_steps!r}, "
                             f"{self.circle_progress!r}")
        if self.blocks is not None and (min(self.blocks, default=0) < 1 or sum(self.blocks) != int(self.horizon)):
            raise ValueError(f"blocks must be positive interval counts summing to horizon={self.horizon}, "
                             f"got {self.blocks!r}")
