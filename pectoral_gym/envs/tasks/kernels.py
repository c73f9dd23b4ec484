"""Task logic of the fish environments as batched numba kernels.

Every function here works on arrays of ``n`` environments, so the single
environment (``n = 1``) and the native vector environment run the same code
and cannot drift apart. Nothing here imports Gymnasium.

The kernels take the packed arrays ``cfg`` (settings), ``ep`` (episode
state), ``fish`` (values derived from the parameters), ``out`` (reward, terms
and flags), ``beats`` (fin patterns) and ``obs`` (observations): every field,
with its unit, is listed in :mod:`pectoral_gym.envs.layout` (``obs`` in
:mod:`pectoral_gym.envs.observation`), whose index constants are re-exported here.

Units: metres, seconds, radians; the tank frame has its origin at a corner.
"""

from __future__ import annotations

import math

import numpy as np

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
    C_GOAL_INSET,
    C_GOAL_RADIUS,
    C_RANGES,
    C_REF_SPEED,
    C_START_INSET,
    C_TASK,
    C_TIME,
    C_W_ENERGY,
    C_W_PROGRESS,
    C_W_TRACKING,
    C_WALL,
    E_A,
    E_B,
    E_CX,
    E_CY,
    E_DIR,
    E_DPREV,
    E_PHASE,
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
from pectoral_gym.model.averaging import mean_fin_power
from pectoral_gym.model.jit import kernel_pair, njit
from pectoral_gym.model.servo import servo_period
from pectoral_gym.model.strokes import ANGLE_FROM, ANGLE_TO, DURATION, ELAPSED, POWER
from pectoral_gym.model.tank import TANK_LENGTH, TANK_WIDTH, band_shortfall, nose_tail_contact

# Tank and task geometry [m], [rad].
TANK_X = TANK_LENGTH  # tank length along X [m], one source: pectoral_gym.model.tank
TANK_Y = TANK_WIDTH  # tank width along Y [m]
START_INSET = 0.3  # goal task: start this far from the walls [m] (EnvConfig.start_inset's default)
GOAL_INSET = 0.2  # goal task: goal this far from the walls [m] (EnvConfig.goal_inset's default)
GOAL_MIN_DISTANCE = 0.3  # goal task: least start-goal distance [m]
GOAL_MAX_DISTANCE = 1.0  # goal task: largest start-goal distance [m]
GOAL_CANDIDATES = 16  # goal candidates drawn per rejection-sampling block
GOAL_MAX_BLOCKS = 64  # bounded rejection sampling
TRACK_A_RANGE = (0.5, 0.8)  # track task: semi-axis along X [m]
TRACK_B_RANGE = (0.25, 0.4)  # track task: semi-axis along Y [m]
TRACK_START_RADIUS = 0.1  # track task: start within this distance of the reference point [m]
TRACK_HEADING_NOISE = 0.3  # track task: start heading = tangent +- this [rad]
TRACK_SUBSTEPS = 4  # RK4 steps per control period for the reference point's phase

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
def _phase_rate(phase, a, b, direction, speed):
    """d(phase)/dt for a point moving at ``speed`` along the ellipse (a cos phase, b sin phase)."""
    sp, cp = math.sin(phase), math.cos(phase)
    return direction * speed / math.sqrt(a * a * sp * sp + b * b * cp * cp)


@njit(inline="always")
def _set_reference(i, ep, speed):
    """Target position and velocity from the ellipse phase of env ``i``."""
    a, b, phase, direction = ep[i, E_A], ep[i, E_B], ep[i, E_PHASE], ep[i, E_DIR]
    sp, cp = math.sin(phase), math.cos(phase)
    ep[i, E_TX] = ep[i, E_CX] + a * cp
    ep[i, E_TY] = ep[i, E_CY] + b * sp
    tx, ty = -a * sp, b * cp  # tangent d/dphase
    norm = math.sqrt(tx * tx + ty * ty)
    ep[i, E_TVX] = direction * speed * tx / norm
    ep[i, E_TVY] = direction * speed * ty / norm


@njit(inline="always")
def _move_reference(i, ep, duration, speed):
    """Advance the reference point of env ``i`` by ``duration`` along its ellipse (RK4 on the phase)."""
    a, b, direction = ep[i, E_A], ep[i, E_B], ep[i, E_DIR]
    h = duration / TRACK_SUBSTEPS
    p = ep[i, E_PHASE]
    for _ in range(TRACK_SUBSTEPS):
        k1 = _phase_rate(p, a, b, direction, speed)
        k2 = _phase_rate(p + 0.5 * h * k1, a, b, direction, speed)
        k3 = _phase_rate(p + 0.5 * h * k2, a, b, direction, speed)
        k4 = _phase_rate(p + h * k3, a, b, direction, speed)
        p += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    ep[i, E_PHASE] = (p + math.pi) % (2.0 * math.pi) - math.pi
    _set_reference(i, ep, speed)


@njit(inline="always")
def reward_one(i, state, cfg, ep, fish, obs, out):
    """Observation, reward terms and termination of env ``i`` after a control period."""
    task = int(cfg[C_TASK])
    if task == TRACK:
        _move_reference(i, ep, cfg[C_DT], cfg[C_REF_SPEED])
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
def in_band(i, state, cfg, fish):
    """Whether any part of env ``i``'s fish is inside the stopping band (``stop_band``; :func:`tank.band_shortfall`).

    The speeds towards the walls are the world-frame components of the body velocity ``state[i, 3:5]``.
    """
    x, y, psi = state[i, 0], state[i, 1], state[i, 2]
    c, s = math.cos(psi), math.sin(psi)
    vx, vy = c * state[i, 3] - s * state[i, 4], s * state[i, 3] + c * state[i, 4]
    outline = (0.5 * fish[i, F_LENGTH], fish[i, F_WIDTH], fish[i, F_SPAN])
    shortfall = band_shortfall(x, y, c, s, (-vx, vx, -vy, vy), outline, fish[i, F_KCOAST], cfg[C_BAND_MARGIN],
                               cfg[C_BAND_REACTION], cfg[C_BAND_CONTACT])
    return shortfall > 0.0


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
def observe_mean_velocity(i, cfg, obs, integral, before):
    """Observe env ``i``'s mean velocities over the control period: (integral now - ``before``) / dt."""
    dt = cfg[C_DT]
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


# ---------------------------------------------------------------- reset
@njit
def _pick_goal(draws, candidates, inset):
    """Rejection sampling: the first candidate (uniforms in pairs) that is a valid goal for the start in ``draws``."""
    for k in range(candidates.shape[0] // 2):
        gx = inset + candidates[2 * k] * (TANK_X - 2.0 * inset)
        gy = inset + candidates[2 * k + 1] * (TANK_Y - 2.0 * inset)
        d = math.hypot(gx - draws[0], gy - draws[1])
        if GOAL_MIN_DISTANCE <= d <= GOAL_MAX_DISTANCE:
            draws[3] = gx
            draws[4] = gy
            return True
    return False


def draw_episode(rng: np.random.Generator, task: int, cfg: np.ndarray) -> np.ndarray:
    """Draw one episode's random start from ``rng``; the same sequence of draws for single and vector envs.

    Args:
        rng: The episode's generator.
        task: ``GOAL`` or ``TRACK``.
        cfg: The packed settings (``goal``: ``C_START_INSET``, ``C_GOAL_INSET``).

    Returns:
        8 numbers: for ``GOAL`` ``(X, Y, psi, goal X, goal Y, 0, 0, 0)``;
        for ``TRACK`` ``(a, b, direction, phase, offset radius, offset angle, heading noise, 0)``.
    """
    draws = np.zeros(8)
    if task == GOAL:
        u = rng.random(3 + 2 * GOAL_CANDIDATES)
        start_inset, goal_inset = cfg[C_START_INSET], cfg[C_GOAL_INSET]
        draws[0] = start_inset + u[0] * (TANK_X - 2.0 * start_inset)
        draws[1] = start_inset + u[1] * (TANK_Y - 2.0 * start_inset)
        draws[2] = -math.pi + 2.0 * math.pi * u[2]
        candidates = u[3:]
        for _ in range(GOAL_MAX_BLOCKS):
            if _pick_goal(draws, candidates, goal_inset):
                return draws
            candidates = rng.random(2 * GOAL_CANDIDATES)
        raise RuntimeError("could not place a goal at the required distance from the start")  # pragma: no cover
    u = rng.random(7)
    draws[0] = TRACK_A_RANGE[0] + u[0] * (TRACK_A_RANGE[1] - TRACK_A_RANGE[0])
    draws[1] = TRACK_B_RANGE[0] + u[1] * (TRACK_B_RANGE[1] - TRACK_B_RANGE[0])
    draws[2] = 1.0 if u[2] < 0.5 else -1.0
    draws[3] = -math.pi + 2.0 * math.pi * u[3]
    draws[4] = TRACK_START_RADIUS * math.sqrt(u[4])  # uniform in the disc
    draws[5] = -math.pi + 2.0 * math.pi * u[5]
    draws[6] = TRACK_HEADING_NOISE * (2.0 * u[6] - 1.0)
    return draws


@njit
def start_states(index, draws, cfg, ep, start):
    """Set the targets of the envs in ``index`` from ``draws`` (see :func:`draw_episode`); write start states.

    ``start`` ``(len(index), 6)`` receives the fish states (at rest).
    """
    task = int(cfg[C_TASK])
    for k in range(index.shape[0]):
        i = index[k]
        d = draws[k]
        start[k, 3:] = 0.0
        if task == GOAL:
            start[k, 0], start[k, 1], start[k, 2] = d[0], d[1], d[2]
            ep[i, E_TX], ep[i, E_TY], ep[i, E_TVX], ep[i, E_TVY] = d[3], d[4], 0.0, 0.0
            ep[i, E_CX] = ep[i, E_CY] = ep[i, E_A] = ep[i, E_B] = ep[i, E_DIR] = ep[i, E_PHASE] = 0.0
        else:
            ep[i, E_CX], ep[i, E_CY] = 0.5 * TANK_X, 0.5 * TANK_Y
            ep[i, E_A], ep[i, E_B], ep[i, E_DIR], ep[i, E_PHASE] = d[0], d[1], d[2], d[3]
            _set_reference(i, ep, cfg[C_REF_SPEED])
            tangent = math.atan2(d[2] * d[1] * math.cos(d[3]), -d[2] * d[0] * math.sin(d[3]))
            start[k, 0] = ep[i, E_TX] + d[4] * math.cos(d[5])
            start[k, 1] = ep[i, E_TY] + d[4] * math.sin(d[5])
            start[k, 2] = tangent + d[6]


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
