"""Task logic of the fish environments as batched numba kernels.

Every function here works on arrays of ``n`` environments, so the single
environment (``n = 1``) and the native vector environment run the same code
and cannot drift apart. Nothing here imports Gymnasium.

The kernels take the packed arrays ``cfg`` (settings), ``ep`` (episode
state), ``fish`` (values derived from the parameters), ``out`` (reward, terms
and flags), ``beats`` (fin patterns) and ``obs`` (observations): every field,
with its unit, is listed in :mod:`pectoral_gym.envs.layout` (``obs`` in
:mod:`pectoral_gym.envs.observation`), whose index constants are re-exported here.

Here: the step (actions, observation, reward, the fused step's pieces and the fin block) and the
reset's observation. The start of an episode (its draws, start states and the task geometry) is
:mod:`pectoral_gym.envs.tasks.episode_start`, the track task's moving point
:mod:`pectoral_gym.envs.tasks.reference_ellipse`; their names are re-exported here too
(``tk.draw_episode``, ``tk.START_INSET``, ...).

Units: metres, seconds, radians; the tank frame has its origin at a corner.
"""

from __future__ import annotations

import math

from pectoral_gym.envs.layout import *  # noqa: F403 - the index constants, re-exported: tk.E_TX, tk.O_REWARD, ...
from pectoral_gym.envs.layout import (
    ACTION_SIZE,
    C_BAND,
    C_BAND_CONTACT,
    C_BAND_MARGIN,
    C_BAND_REACTION,
    C_DT,
    C_FIN_RATE,
    C_GOAL_BONUS,
    C_GOAL_RADIUS,
    C_RANGES,
    C_REF_SPEED,
    C_TASK,
    C_TIME,
    C_W_ENERGY,
    C_W_PROGRESS,
    C_W_TRACKING,
    C_WALL,
    E_DPREV,
    E_TVX,
    E_TVY,
    E_TX,
    E_TY,
    F_KCOAST,
    F_KDRAG,
    F_LENGTH,
    F_SPAN,
    F_WIDTH,
    FIN_ACTIONS,
    GOAL,
    O_COST,
    O_DISTANCE,
    O_ENERGY,
    O_GOAL,
    O_PROGRESS,
    O_REWARD,
    O_SUCCESS,
    O_TERMINATED,
    O_TIME,
    O_TRACKING,
    O_WALL,
    TRACK,
)
from pectoral_gym.envs.observation import (  # noqa: F401 - OBS_SIZE re-exported: tk.OBS_SIZE
    FIN_OBS_FIELDS,
    OBS_COS_PSI,
    OBS_FIN_ANGLE,
    OBS_FIN_ANGLE_TO,
    OBS_FIN_POWER,
    OBS_FIN_TIME_LEFT,
    OBS_LAST_ACTION,
    OBS_OMEGA,
    OBS_SIN_PSI,
    OBS_SIZE,
    OBS_TARGET_VX,
    OBS_TARGET_VY,
    OBS_TARGET_X,
    OBS_TARGET_Y,
    OBS_VX,
    OBS_VY,
    OBS_X,
    OBS_Y,
)
from pectoral_gym.envs.tasks.episode_start import (  # noqa: F401 - re-exported: tk.draw_episode, tk.START_INSET, ...
    GOAL_CANDIDATES,
    GOAL_MAX_BLOCKS,
    GOAL_MAX_DISTANCE,
    GOAL_MIN_DISTANCE,
    START_INSET,
    TANK_X,
    TANK_Y,
    TRACK_A_RANGE,
    TRACK_B_RANGE,
    TRACK_HEADING_NOISE,
    TRACK_START_RADIUS,
    draw_episode,
    start_states,
)
from pectoral_gym.envs.tasks.reference_ellipse import (  # noqa: F401 - TRACK_SUBSTEPS re-exported
    TRACK_SUBSTEPS,
    move_reference,
)
from pectoral_gym.model.averaging import mean_fin_power
from pectoral_gym.model.jit import kernel_pair, njit
from pectoral_gym.model.servo import servo_period
from pectoral_gym.model.strokes import ANGLE_FROM, ANGLE_TO, DURATION, ELAPSED, POWER
from pectoral_gym.model.tank import band_shortfall, nose_tail_contact

# Reward terms reported in ``info`` per task: (name, out index), in the order they are summed.
TERMS = {
    GOAL: (("reward_progress", O_PROGRESS), ("reward_goal", O_GOAL), ("reward_wall", O_WALL),
           ("reward_energy", O_ENERGY), ("reward_time", O_TIME)),
    TRACK: (("reward_tracking", O_TRACKING), ("reward_wall", O_WALL), ("reward_energy", O_ENERGY)),
}



# ---------------------------------------------------------------- actions
@njit
def first_non_finite(actions, skip):
    """The first env not in ``skip`` with a non-finite action entry, or -1."""
    for i in range(actions.shape[0]):
        if skip[i]:
            continue
        for j in range(actions.shape[1]):
            if not math.isfinite(actions[i, j]):
                return i
    return -1


@njit(inline="always")
def apply_one(i, actions, cfg, beats, obs, out, fish):
    """Map env ``i``'s action to fin patterns (``servo_limit``: as the servos run them), store it, price its energy."""
    energy = 0.0
    for f in range(2):
        for k in range(FIN_ACTIONS):
            x = min(max(float(actions[i, FIN_ACTIONS * f + k]), -1.0), 1.0)
            low = cfg[C_RANGES + 2 * k]
            high = cfg[C_RANGES + 2 * k + 1]
            beats[i, f, k] = min(low + 0.5 * (x + 1.0) * (high - low), high)
            obs[i, OBS_LAST_ACTION + FIN_ACTIONS * f + k] = x
        if cfg[C_FIN_RATE] > 0.0:  # servo_limit: the robot's servos run a too fast pattern slower
            beats[i, f, 2] = servo_period(beats[i, f, 1], beats[i, f, 2], beats[i, f, 3], cfg[C_FIN_RATE])
        energy += mean_fin_power(beats[i, f, 1], beats[i, f, 2], beats[i, f, 3], fish[i, F_SPAN], fish[i, F_KDRAG])
    out[i, O_ENERGY] = -cfg[C_W_ENERGY] * energy * cfg[C_DT]  # E = sum of mean fin power * control period [J]


# Serial and prange loops over the envs (pectoral_gym.model.jit.kernel_pair): a non-finite action anywhere stops
# the step before anything is written.
APPLY_KERNELS = kernel_pair(apply_one, "actions, skip, cfg, beats, obs, out, fish",
                            item_args="actions, cfg, beats, obs, out, fish", skip="skip",
                            guard=first_non_finite, guard_args="actions, skip")


# ---------------------------------------------------------------- observation and reward
@njit(inline="always")
def observe_one(i, state, ep, fish, obs):
    """Write the observation of env ``i`` up to the last action; return the distance to the target and the wall flag."""
    x, y, psi = state[i, 0], state[i, 1], state[i, 2]
    c, s = math.cos(psi), math.sin(psi)
    dx = ep[i, E_TX] - x
    dy = ep[i, E_TY] - y
    obs[i, OBS_X] = x
    obs[i, OBS_Y] = y
    obs[i, OBS_COS_PSI] = c
    obs[i, OBS_SIN_PSI] = s
    obs[i, OBS_VX] = state[i, 3]
    obs[i, OBS_VY] = state[i, 4]
    obs[i, OBS_OMEGA] = state[i, 5]
    obs[i, OBS_TARGET_X] = c * dx + s * dy  # target in the body frame (x forward, y left)
    obs[i, OBS_TARGET_Y] = -s * dx + c * dy
    obs[i, OBS_TARGET_VX] = c * ep[i, E_TVX] + s * ep[i, E_TVY]
    obs[i, OBS_TARGET_VY] = -s * ep[i, E_TVX] + c * ep[i, E_TVY]
    wall = nose_tail_contact(x, y, c, s, 0.5 * fish[i, F_LENGTH])
    return math.sqrt(dx * dx + dy * dy), wall


@njit(inline="always")
def reward_one(i, state, cfg, ep, fish, obs, out):
    """Observation, reward terms and termination of env ``i`` after a control period."""
    task = int(cfg[C_TASK])
    if task == TRACK:
        move_reference(i, ep, cfg[C_DT], cfg[C_REF_SPEED])
    d, wall = observe_one(i, state, ep, fish, obs)
    band = cfg[C_BAND] > 0.5 and in_band(i, state, cfg, fish)
    r_wall = -cfg[C_WALL] if (wall or band) else 0.0
    r_energy = out[i, O_ENERGY]
    if task == GOAL:
        success = d < cfg[C_GOAL_RADIUS]
        r_progress = cfg[C_W_PROGRESS] * (ep[i, E_DPREV] - d)
        r_goal = cfg[C_GOAL_BONUS] if success else 0.0
        r_time = -cfg[C_TIME]
        out[i, O_PROGRESS] = r_progress
        out[i, O_GOAL] = r_goal
        out[i, O_TIME] = r_time
        out[i, O_TRACKING] = 0.0
        out[i, O_REWARD] = r_progress + r_goal + r_wall + r_energy + r_time  # the order of TERMS[GOAL]
    else:
        success = False
        r_tracking = -cfg[C_W_TRACKING] * d
        out[i, O_PROGRESS] = 0.0
        out[i, O_GOAL] = 0.0
        out[i, O_TIME] = 0.0
        out[i, O_TRACKING] = r_tracking
        out[i, O_REWARD] = r_tracking + r_wall + r_energy  # the order of TERMS[TRACK]
    out[i, O_WALL] = r_wall
    out[i, O_DISTANCE] = d
    out[i, O_TERMINATED] = 1.0 if (wall or band or success) else 0.0
    out[i, O_SUCCESS] = 1.0 if success else 0.0
    out[i, O_COST] = 1.0 if band else 0.0
    ep[i, E_DPREV] = d


@njit(inline="always")
def band_shortfall_of(i, state, cfg, fish):
    """Env ``i``'s stopping-band shortfall [m] (> 0: inside the band; :func:`tank.band_shortfall`).

    The speeds towards the walls are the world-frame components of the body velocity ``state[i, 3:5]``; the
    outline and coasting rate are the episode's parameters ``fish[i]``, the rule the env's ``cfg``.
    """
    x, y, psi = state[i, 0], state[i, 1], state[i, 2]
    c, s = math.cos(psi), math.sin(psi)
    vx, vy = c * state[i, 3] - s * state[i, 4], s * state[i, 3] + c * state[i, 4]
    outline = (0.5 * fish[i, F_LENGTH], fish[i, F_WIDTH], fish[i, F_SPAN])
    return band_shortfall(x, y, c, s, (-vx, vx, -vy, vy), outline, fish[i, F_KCOAST], cfg[C_BAND_MARGIN],
                          cfg[C_BAND_REACTION], cfg[C_BAND_CONTACT])


@njit(inline="always")
def in_band(i, state, cfg, fish):
    """Whether any part of env ``i``'s fish is inside the stopping band (``stop_band``; :func:`band_shortfall_of`)."""
    return band_shortfall_of(i, state, cfg, fish) > 0.0


# ---------------------------------------------------------------- the simulated envs' step (envs.fused)
# What EnvCore adds around the task's kernels: keep the model's velocity integrals before the step, and
# observe the mean velocities over the control period after it.
@njit(inline="always")
def apply_keep_one(i, actions, skip, cfg, beats, obs, out, fish, integral, before):
    """Keep env ``i``'s velocity integrals in ``before``; unless ``skip[i]``, :func:`apply_one` its action."""
    before[i, 0], before[i, 1], before[i, 2] = integral[i, 0], integral[i, 1], integral[i, 2]
    if not skip[i]:
        apply_one(i, actions, cfg, beats, obs, out, fish)


@njit(inline="always")
def observe_mean_velocity(i, dt, obs, integral, before):
    """Observe env ``i``'s mean velocities over its last period of ``dt`` seconds: (integral now - ``before``) / dt."""
    obs[i, OBS_VX] = (integral[i, 0] - before[i, 0]) / dt
    obs[i, OBS_VY] = (integral[i, 1] - before[i, 1]) / dt
    obs[i, OBS_OMEGA] = (integral[i, 2] - before[i, 2]) / dt


def apply_actions(actions, skip, cfg, beats, obs, out, fish) -> int:
    """Map normalised actions ``(n, 8)`` to fin patterns ``beats`` for the envs not in ``skip``.

    Also writes the clipped actions to ``obs[:, OBS_ACTION]`` and the energy term to
    ``out[:, O_ENERGY]``. Returns -1, or the index of the first env whose
    action is not finite (then nothing has been written).
    """
    return APPLY_KERNELS.run(actions, skip, cfg, beats, obs, out, fish)


@njit
def observe_fins(fins, obs, period_max):
    """Write the fin block of the observation (``observe_fins=True``) from the models' half-strokes ``fins``.

    Per fin, at the block of :mod:`pectoral_gym.envs.observation`: the angle now on the half-cosine
    of its half-stroke (``docs/model.md`` 3.2), the half-stroke's end angle, its kind, and the time
    left to that turning point over ``period_max``; angles as ``(gamma - pi/2) / (pi/2)``.
    """
    half_pi = 0.5 * math.pi
    for i in range(fins.shape[0]):
        for f in range(2):
            g_from, g_to = fins[i, f, ANGLE_FROM], fins[i, f, ANGLE_TO]
            duration, elapsed = fins[i, f, DURATION], fins[i, f, ELAPSED]
            left = max(duration - elapsed, 0.0)
            g = g_to
            if left > 0.0:  # g = mid - half cos(pi s / d) on the half-stroke in progress
                g = 0.5 * (g_from + g_to) - 0.5 * (g_to - g_from) * math.cos(math.pi * elapsed / duration)
            base = OBS_SIZE + FIN_OBS_FIELDS * f
            obs[i, base + OBS_FIN_ANGLE] = (g - half_pi) / half_pi
            obs[i, base + OBS_FIN_ANGLE_TO] = (g_to - half_pi) / half_pi
            obs[i, base + OBS_FIN_POWER] = 1.0 if fins[i, f, POWER] > 0.5 else -1.0
            obs[i, base + OBS_FIN_TIME_LEFT] = min(left / period_max, 1.0)


# ---------------------------------------------------------------- reset (draws, start states: episode_start)
@njit
def observe_reset(index, state, ep, fish, obs, out, action_code):
    """Observations of freshly reset envs; the last-action entries get ``action_code``.

    ``out`` rows are zeroed except ``O_DISTANCE``, the distance to the target: the reset ``info``
    has the step's keys (zero reward terms, the real distance, no success).
    """
    for k in range(index.shape[0]):
        i = index[k]
        d, _ = observe_one(i, state, ep, fish, obs)
        ep[i, E_DPREV] = d
        for j in range(ACTION_SIZE):
            obs[i, OBS_LAST_ACTION + j] = action_code[j]
        out[i, :] = 0.0
        out[i, O_DISTANCE] = d
