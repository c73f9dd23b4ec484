"""The single-fish Gymnasium environment ``PectoralFish-{Full,Averaged}-v*`` (:mod:`pectoral_gym.versions`)."""

from __future__ import annotations

import inspect
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from pectoral_gym.envs.core import EnvConfig, EnvCore, env_signature
from pectoral_gym.envs.layout import (
    ACTION_SIZE,
    O_COST,
    O_REWARD,
    O_TERMINATED,
    FishConstants,
    ReferenceEllipse,
)
from pectoral_gym.envs.observation import OBS_X, OBS_Y, observation_bounds, observation_structure
from pectoral_gym.envs.tasks.episode_start import pin_start
from pectoral_gym.model.params import FishParams
from pectoral_gym.versions import LATEST

__all__ = ["PectoralFishEnv"]

_ZERO_INDEX = np.zeros(1, dtype=np.int64)
#: Attributes bound by ``PectoralFishEnv._bind_rows``, left out of a pickle.
_BOUND = ("_action_row", "_obs_row", "_out_row", "_buffer_step", "_row_info")


class PectoralFishEnv(gym.Env):
    r"""A robotic fish rowing with two pectoral fins in a tank, seen from above.

    ## Description

    The fish of the reference paper (body 0.198 m, two rowing pectoral fins)
    swims in a 2.30 m x 1.15 m tank. Every ``control_period`` the agent sets
    the beat pattern of each fin, ``(bias, amplitude, period, ratio)`` of
    eq. (21); a fin switches to a new pattern at the next turning point of its
    stroke (the parameter-change rule of :mod:`pectoral_gym.model.strokes`). Two
    models drive the same environment: ``PectoralFish-Full-v*`` integrates the
    blade-element model through every fin beat, ``PectoralFish-Averaged-v*``
    the cycle-averaged model with identified scaling functions (and, beyond
    the paper, its yaw damping averaged over the in-beat yaw oscillation,
    ``docs/model.md`` section 3.6). Spaces, tasks and rewards are identical;
    only the model differs.

    Tasks: ``"goal"`` (reach a point) and ``"track"`` (follow a point that
    moves along an ellipse at ``ref_speed``).

    ## Action Space

    ``Box(-1, 1, (8,), float32)``. Entry ``x`` maps linearly to ``[low, high]``
    of its range; finite values outside [-1, 1] are clipped; a non-finite
    action raises ``ValueError``.

    | Num | Action              | Fin   | Range (x = -1 .. 1), default | Unit |
    |-----|---------------------|-------|------------------------------|------|
    | 0   | bias ``gamma_0``    | right | ``bias_range``, 45 .. 135 deg | rad |
    | 1   | amplitude ``gamma_A`` | right | ``amplitude_range``, 0 .. 30 deg | rad |
    | 2   | period ``T_p``      | right | ``period_range``, 0.5 .. 2.0  | s    |
    | 3   | ratio ``zeta``      | right | ``ratio_range``, 1 .. 5       | -    |
    | 4-7 | same                | left  | same                          |      |

    ## Observation Space

    ``Box(low, high, (19,), float32)`` with finite, physical bounds
    (:func:`pectoral_gym.envs.observation.observation_bounds`): the tank grown by
    ``MAX_SPEED * control_period`` for the position, +-1 for heading and last
    action, +-2 m/s and +-10 rad/s for the velocities, +-``ref_speed`` for the
    target velocity. Tank frame: origin at a tank corner,
    X along the 2.30 m side. Body frame: x forward, y to the left.

    | Num   | Observation                                   | Unit  |
    |-------|-----------------------------------------------|-------|
    | 0     | X, position in the tank                       | m     |
    | 1     | Y, position in the tank                       | m     |
    | 2     | cos psi (heading)                             | -     |
    | 3     | sin psi                                       | -     |
    | 4     | vx, surge velocity (body frame), mean over the last control period | m/s |
    | 5     | vy, sway velocity (body frame), same mean     | m/s   |
    | 6     | omega, yaw rate (> 0: turning left), same mean | rad/s |
    | 7-8   | target position relative to the fish, body frame | m  |
    | 9-10  | target velocity, body frame (zero for ``goal``) | m/s |
    | 11-18 | the last action, normalised and clipped (after a reset: the encoding of the rest pattern) | - |

    ``env.unwrapped.observation_structure`` lists the blocks in order
    (``position`` 2, ``heading`` 2, ``velocity`` 3, ``target`` 2,
    ``target_velocity`` 2, ``last_action`` 8), as Swimmer-v5 does;
    :func:`pectoral_gym.envs.observation.decode` gives the named view.

    ## Rewards

    The reward is the sum of named terms, each reported in ``info`` (terms of
    the other task are absent). ``d`` is the distance from the fish's centre of
    mass to the target after the step, ``E`` the fin work of the commanded
    patterns over the control period, ``E = sum_fins mean_fin_power * control_period``
    (:func:`pectoral_gym.model.averaging.mean_fin_power`).

    | Term              | Task  | Value                                    |
    |-------------------|-------|------------------------------------------|
    | ``reward_progress`` | goal | ``progress_weight * (d_prev - d)``       |
    | ``reward_goal``   | goal  | ``goal_bonus`` if ``d < goal_radius``, else 0 |
    | ``reward_wall``   | both  | ``-wall_penalty`` if the fish hit a wall (``stop_band``: or the band), else 0 |
    | ``reward_energy`` | both  | ``-energy_weight * E``                   |
    | ``reward_time``   | goal  | ``-time_penalty``                        |
    | ``reward_tracking`` | track | ``-tracking_weight * d``               |

    ``info`` also holds ``"distance"`` (``d`` [m]), ``"is_success"`` (goal)
    and ``"tracking_error"`` (track, ``d`` [m]), and with ``stop_band`` ``"cost"``: 1.0 on a step
    that ends inside the stopping band, else 0.0 (Safety-Gymnasium's per-step cost, for constrained
    RL; :class:`pectoral_gym.envs.cost.BandCost` adds ``"band_cost"``, a cost that rises before the band). Every
    value is a numpy scalar
    (``np.float64``, ``np.bool_``). ``reset()`` returns the same keys: zero
    reward terms, the real distance, ``is_success = False``.

    ## Starting State

    The fish is at rest with both fins held still at 90 deg
    (``FinBeat.rest()``). ``goal``: position uniform in the tank inset by
    ``start_inset`` (0.3 m), heading uniform in [-pi, pi); the goal uniform in the tank inset by
    ``goal_inset`` (0.2 m; 0.3 m in v1) at a distance in [0.3, 1.0] m from the start. ``track``: an ellipse
    centred in the tank with semi-axes ``U(0.5, 0.8)`` m (X) and
    ``U(0.25, 0.4)`` m (Y), a random direction of travel and start phase; the
    fish starts uniformly within 0.1 m of the reference point, heading along
    the tangent +- U(0.3) rad. With ``randomize``, each reset first draws the
    model parameters. All randomness comes from ``self.np_random``. ``reset(options={"start": (X, Y, psi),
    "goal": (X, Y)})`` (goal task, either or both) starts the episode there instead (a deploy's logged
    episode, a scenario of one's own).

    ## Episode End

    * Termination: the nose or the tail (``X +- L/2 cos psi``, ``Y +- L/2 sin psi``,
      ``L = params.body_length``) leaves the tank; with ``stop_band``, any part of the fish (body
      and fin tips) is closer to a wall than it needs to stop (the robot's geofence:
      ``margin + v t_r + ln(1 + k v T) / k`` with ``v`` the speed towards that wall,
      :func:`pectoral_gym.model.tank.stop_need`, checked after each control period); or, ``goal``,
      ``d < goal_radius`` (``info["is_success"] = True``).
    * Truncation: 240 steps (2 min at the default control period), set by
      ``max_episode_steps`` in the registry.

    ## Arguments

    ``gym.make(LATEST_AVERAGED, task="track", randomize={"drag_coef": 0.2})`` (``from pectoral_gym.versions
    import LATEST_AVERAGED``, the recommended averaged id)

    | Argument          | Default          | Unit | Description |
    |-------------------|------------------|------|-------------|
    | ``model``         | ``"full"``       |      | ``"full"`` or ``"averaged"`` (set by the id) |
    | ``task``          | ``"goal"``       |      | ``"goal"`` or ``"track"`` |
    | ``control_period``| 0.5              | s    | time between actions |
    | ``bias_range``    | (45, 135) deg    | rad  | fin bias; ``bias +- amplitude`` must stay in [0, pi] |
    | ``amplitude_range`` | (0, 30) deg    | rad  | amplitude, >= 0 |
    | ``period_range``  | (0.5, 2.0)       | s    | fin-beat period, > 0 |
    | ``ratio_range``   | (1.0, 5.0)       | -    | power/recovery speed ratio, > 0 |
    | ``params``        | ``None``         |      | :class:`FishParams`, dict of fields or parameters file (Table 1) |
    | ``randomize``     | ``None``         |      | ``{field: w}``: each reset scales the field by ``U(1-w, 1+w)`` |
    | ``scaling``       | ``"identified"`` |      | averaged only: ``"identified"``, ``"none"`` (K = 1), or a K file |
    | ``check_scaling_params`` | ``True`` |   | averaged only: raise if the K file is for other ``params`` |
    | ``transitions``   | ``False``        |      | averaged only: transitional-stroke forcing (docs/model.md 3.7) |
    | ``ripple_offsets``| ``False``        |      | averaged only: beat-mean ripple offset (docs/model.md 3.8)     |
    | ``fast_step``     | ``False``        |      | averaged only: the fast step (docs/model.md section 6)         |
    | ``integration``   | ``"reference"``  |      | full only: ``"fast"``: fewer substeps (model.md 6)         |
    | ``observe_fins``  | ``False``        |      | observe each fin's half-stroke in progress (8 more entries) |
    | ``progress_weight`` | 10.0           | 1/m  | goal: reward per metre of approach |
    | ``goal_bonus``    | 10.0             |      | goal: reward on reaching the goal |
    | ``wall_penalty``  | 10.0             |      | penalty for hitting a wall |
    | ``energy_weight`` | 1.0              | 1/J  | penalty per joule of fin work |
    | ``time_penalty``  | 0.01             |      | goal: penalty per step |
    | ``tracking_weight`` | 1.0            | 1/m  | track: penalty per metre of distance per step |
    | ``goal_radius``   | 0.08             | m    | goal: success radius |
    | ``ref_speed``     | 0.03             | m/s  | track: speed of the reference point |
    | ``start_inset``   | 0.3              | m    | goal: least distance of a start from the walls |
    | ``goal_inset``    | 0.2              | m    | goal: least distance of a goal from the walls |
    | ``stop_band``     | False            |      | end the episode in the robot's stopping band; ``info["cost"]`` |
    | ``stop_rule``     | (0.05, 0.15, 0.03) |    | the band's margin [m], reaction time [s], contact speed [m/s] |
    | ``servo_limit``   | ``None``         | rad/s | fastest fin rate: faster patterns run slower, as on the robot |
    | ``sensing``       | ``None``         |      | observe through a simulated camera and observer (below) |
    | ``timing``        | ``None``         |      | the robot's command delay and late ticks (below) |
    | ``render_mode``   | ``None``         |      | ``"rgb_array"`` or ``"human"`` |

    All arguments are keywords. The defaults are those of
    :class:`~pectoral_gym.envs.core.EnvConfig` (the one place they are
    written; this table is checked against it), the v0 ids' settings; an id sets
    its version's (:data:`pectoral_gym.versions.ENV_VERSIONS`), and the class
    constructed without an id (``PectoralFishEnv(model="averaged")``) starts from
    the latest id's of that model (:data:`pectoral_gym.versions.LATEST`;
    ``model`` defaults to ``"full"``), with the arguments on top. Ranges must be finite with
    ``low <= high``; invalid settings raise ``ValueError``.

    ``sensing`` (``True``, ``{}`` for the defaults, or a dict of
    :class:`~pectoral_gym.sensing.camera.SensingConfig` fields) shows the observation's pose and velocities as the
    robot env does: camera frames at 30 frames/s with per-episode pose noise (0.3-5 mm, 0.2-2 deg), frame drops
    (0-10 %) and latency (0-0.1 s), through the robot's high-gain observer (:mod:`pectoral_gym.envs.sensed`).
    Rewards, episode ends and ``info`` stay computed on the true state.

    ``timing`` (``True``, ``{}`` for the defaults, or a dict of :class:`~pectoral_gym.envs.timing.TimingConfig`
    fields) runs the control loop as the robot's does: each command reaches the fins after a delay (a per-episode
    level of 0-0.12 s plus up to 0.03 s per step) and each observation comes up to 0.01 s after its tick, the
    ticks staying on the ``control_period`` grid (:mod:`pectoral_gym.envs.timing`).

    The unwrapped env reads its task state through ``target``,
    ``target_velocity``, ``reference`` (track ellipse), ``fish_state``,
    ``fin_patterns``, ``fish_constants`` and ``last_observation``, and
    ``set_target`` / ``set_fish_state`` place the goal or the fish for scripted tests.

    ## Version History

    * Unversioned additions (no id changes its episodes): ``reset(options={"start": ..., "goal": ...})``;
      the class constructed without an id (``PectoralFishEnv(model=...)``, ``PectoralFishVectorEnv``) builds the
      latest id of its model (:data:`pectoral_gym.versions.LATEST`; it built ``EnvConfig``'s defaults, v0's,
      while the model classes and specs default to the latest averaged model); the ids' settings live in one
      table, :data:`pectoral_gym.versions.ENV_VERSIONS`.
    * v2: ``PectoralFish-Averaged-v2`` adds ``ripple_offsets=True``: the averaged model with both of its
      corrections, the model's own defaults (the beat-mean ripple offset, ``docs/model.md`` 3.8, on top of v1's
      transitional half-strokes); the PPO recipe trained on it reaches more goals on the full model for every
      training seed (``docs/notes/2026-12-04-ripple-offsets-training.md``). ``PectoralFish-Full-v2`` is
      ``PectoralFish-Full-v1`` (the full model did not change; it moves with the averaged id so the two ids of a
      version go together; its table entry is v1's, marked ``same_as``). Every other setting is v1's.
    * v1: Prepares a policy for the robot stack (:data:`pectoral_gym.versions.ROBOT`):
      ``observe_fins=True``, ``stop_band=True`` (the robot's geofence ends the episode, with
      ``info["cost"]``; ``stop_rule`` the robot's with 5 cm more margin, ``(0.10, 0.15, 0.03)``),
      ``servo_limit`` = the robot's 13 rad/s, ``goal_inset=0.3`` (goals the band leaves reachable);
      ``PectoralFish-Averaged-v1`` adds ``transitions=True`` (the shipped PPO recipe's training model),
      ``PectoralFish-Full-v1`` runs the fast integration (``integration="fast"``). Every other default is
      v0's.
    * v0: Initial version. Later, with the same id and dynamics: ``reset()`` returns the step's
      ``info`` keys, ``info`` values are numpy scalars, finite observation bounds,
      ``params`` as a dict or file, ``scaling`` as a file, ``render_fps = 1 / control_period``.
      Stays as it was; Gymnasium notes on ``make`` that v1 exists.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 2}  # per instance: 1 / control_period

    def __init__(self, *, render_mode: str | None = None, **kwargs: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.config = EnvConfig.recommended(**kwargs)  # the latest version's settings, then the arguments
        # One frame per control period, so a recorded video plays in real time.
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / self.config.control_period}
        self.render_mode = render_mode
        self.core = EnvCore(1, self.config)
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)
        low, high = observation_bounds(self.config.control_period, self.config.ref_speed,
                                       self.config.observe_fins)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.observation_structure = observation_structure(self.config.observe_fins)
        # info["cost"], by the task state's rule (TaskState.info_fields), read here once instead of every step
        self._cost = any(f.key == "cost" for f in self.core.task_state.info_fields)
        self._renderer = None
        self.trail: list[tuple[float, float]] = []
        self._bind_rows()

    def _bind_rows(self) -> None:
        """Bind what every step reads once: this env's rows of the core, its step, the task's ``info`` builder.

        Bound again after unpickling (to the copy's own core).
        """
        core = self.core
        self._action_row = core.action_buffer[0]
        self._obs_row = core.obs[0]
        self._out_row = core.out[0]
        self._buffer_step = core.buffer_step()  # the core's step of its action buffer (envs.fused)
        self._row_info = core.task_state.task.info  # task_info's builder for this env's task

    @property
    def model(self):
        """The underlying batched fish model (one fish)."""
        return self.core.model

    @property
    def fish_params(self) -> FishParams:
        """The model parameters of the current episode (after randomisation)."""
        return self.core.params[0]

    @property
    def last_observation(self) -> np.ndarray:
        """The observation returned by the last ``reset`` or ``step`` (a copy)."""
        return self.core.obs[0].copy()

    @property
    def target(self) -> tuple[float, float]:
        """Target position in the tank frame [m]."""
        return self.core.target(0)

    @property
    def target_velocity(self) -> tuple[float, float]:
        """Target velocity in the tank frame [m/s] (zero for ``goal``)."""
        return self.core.target_velocity(0)

    def set_target(self, x: float, y: float) -> None:
        """Move the target to ``(x, y)`` [m] (tank frame), e.g. to script a test; seen from the next step on."""
        self.core.set_target(0, x, y)

    @property
    def reference(self) -> ReferenceEllipse:
        """The reference ellipse of the ``track`` task (all zero for ``goal``)."""
        return self.core.reference(0)

    @property
    def fish_constants(self) -> FishConstants:
        """Body length, fin span and fin drag constant of the current episode, as the task kernels use them."""
        return self.core.fish_constants(0)

    @property
    def fish_state(self) -> np.ndarray:
        """Model state ``(X, Y, psi, vx, vy, omega)`` (a copy) [m, m, rad, m/s, m/s, rad/s]."""
        return self.core.fish_state(0)

    def set_fish_state(self, state) -> None:
        """Overwrite the model state ``(X, Y, psi, vx, vy, omega)``; takes effect at the next step."""
        self.core.set_fish_state(0, state)

    @property
    def fin_patterns(self) -> np.ndarray:
        """Commanded fin patterns ``(2, 4)``: ``(bias, amplitude, period, ratio)``, right fin first (a copy)."""
        return self.core.fin_patterns(0)

    def __getstate__(self) -> dict[str, Any]:
        """Pickle and deepcopy without the renderer (it holds pygame); a copy draws with its own."""
        state = self.__dict__.copy()
        state["_renderer"] = None
        for name in _BOUND:  # rebound to the copy's own core (a registered task's info builder may not pickle)
            del state[name]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore a pickled or deep-copied env; the row views are bound to its own core again."""
        self.__dict__.update(state)
        self._bind_rows()

    def _info(self) -> dict[str, Any]:
        """The ``info`` of the last reset or step (:meth:`~pectoral_gym.envs.tasks.table.TaskState.info`).

        A new dict every time: wrappers add keys to it (``RecordEpisodeStatistics``).
        """
        o = self._out_row
        info = self._row_info(o)
        if self._cost:
            info["cost"] = o[O_COST]
        return info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode (see "Starting State"); returns ``(observation, info)``, ``info`` with the step's keys.

        ``options`` (goal task): ``{"start": (X, Y, psi), "goal": (X, Y)}``, either or both, in m and rad:
        the episode starts there instead of at its draws (the generator draws as without them).

        Raises:
            ValueError: If ``options`` has other keys, the task is ``track``, or a position is outside the tank.
        """
        pinned = pin_start(options, self.config.task_id)  # checked before the generator moves
        super().reset(seed=seed)
        self.core.reset(_ZERO_INDEX, (self.np_random,), None if pinned is None else pinned[None])
        if self.render_mode is not None:
            self.trail = [(float(self.core.obs[0, OBS_X]), float(self.core.obs[0, OBS_Y]))]
            if self.render_mode == "human":
                self.render()
        return self._obs_row.copy(), self._info()

    def step(self, action):
        """Advance one control period; returns ``(observation, reward, terminated, truncated, info)``."""
        self._action_row[...] = action  # the core's own buffer: its one-call step (envs.fused)
        if (bad := self._buffer_step()) >= 0:
            self.core.raise_non_finite(bad)
        o = self._out_row
        info = self._row_info(o)  # as _info(), inlined on this hot path
        if self._cost:
            info["cost"] = o[O_COST]
        if self.render_mode is not None:
            self.trail.append((float(self._obs_row[OBS_X]), float(self._obs_row[OBS_Y])))
            if self.render_mode == "human":
                self.render()
        # o.item: the Python float of a float64 entry, as float(o[k])
        return self._obs_row.copy(), o.item(O_REWARD), o.item(O_TERMINATED) > 0.5, False, info

    def render(self):
        """Draw the tank from above: ``rgb_array`` returns an ``(H, W, 3)`` uint8 image; ``human`` shows a window."""
        if self.render_mode is None:
            env_id = self.spec.id if self.spec is not None else LATEST[self.config.model]  # this env's own id
            from pectoral_gym.envs.rendering import warn_no_render_mode
            warn_no_render_mode(env_id)
            return None
        if self._renderer is None:
            from pectoral_gym.envs.rendering import FishRenderer

            self._renderer = FishRenderer(self.render_mode, self.metadata["render_fps"])
        return self._renderer.render(self.core, 0, self.trail, self.config)

    def close(self):
        """Close the window and quit pygame if it was started."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


PectoralFishEnv.__init__.__signature__ = env_signature(
    inspect.Parameter("render_mode", inspect.Parameter.KEYWORD_ONLY, default=None, annotation="str | None"))
