"""Safety review, PC side, finding 7 (pose noise at rest trips the geofence), on the rules alone: the
least-squares speed estimate the geofence judges never trips it on a fish at rest under 5 mm of pose noise and
still sees one swimming at a wall, and the physical speed bound (``SpeedBound``) holds against the full model
over random commands.

The same finding against the emulated robot, and the review's other PC-side findings:
``tests/test_safety_supervisor.py``.
"""

import math

import numpy as np
import pytest

from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.safety.geofence import Geofence, SpeedBound
from pectoral_gym.hardware.safety.supervisor import ls_velocity
from pectoral_gym.model.finrules import apply_firmware
from pectoral_gym.model.params import TANK_LENGTH, FishParams
from pectoral_gym.model.servo import ServoLimits
from pectoral_gym.model.tank import StopRule

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")

P = FishParams()


# ---------------------------------------------------------------- 7: pose noise at rest
def _noisy_poses(rng, n, noise, dt=1 / 30):
    t = np.arange(n) * dt
    return [(ti, 2.0 + rng.normal(0, noise), 0.5 + rng.normal(0, noise)) for ti in t]


def test_speed_estimate_at_rest_with_5_mm_noise_never_trips_the_geofence():
    # A fish at rest with its centre 0.30 m from the +X wall, heading at it; fins running (bound far above).
    fence = Geofence(P, StopRule(0.05, 0.15, 0.03))
    rng = np.random.default_rng(0)
    x0 = TANK_LENGTH - 0.30
    before = after = 0
    trials = 4000
    for _ in range(trials):
        poses = _noisy_poses(rng, 31, 0.005)  # 1 s of 30 frames/s
        psi = rng.normal(0, math.radians(2))
        x, y = x0 + poses[-1][1] - 2.0, 0.575 + poses[-1][2] - 0.5
        # Before: raw difference of two poses 0.2 s apart.
        old = poses[-7]
        raw = ((poses[-1][1] - old[1]) / 0.2, (poses[-1][2] - old[2]) / 0.2)
        before += fence.breached(x, y, psi, *raw, age=0.03)
        (vx, vy), (sx, sy) = ls_velocity(poses, 0.005)
        after += fence.breached(x, y, psi, vx, vy, age=0.03, spread=(2 * sx, 2 * sy), bound=0.88)
    assert before > 0.05 * trials  # reproduces finding 7
    assert after == 0


def test_speed_estimate_still_sees_a_fish_swimming_at_a_wall():
    fence = Geofence(P, StopRule(0.05, 0.15, 0.03))
    t = np.arange(19) / 30
    poses = [(ti, TANK_LENGTH - 0.45 + 0.2 * ti, 0.575) for ti in t]  # 0.2 m/s towards +X, nose 0.23 m away
    (vx, vy), (sx, sy) = ls_velocity(poses, 0.005)
    assert vx == pytest.approx(0.2, abs=1e-9)
    assert fence.breached(poses[-1][1], 0.575, 0.0, vx, vy, spread=(2 * sx, 2 * sy), bound=0.88)
    assert not fence.breached(poses[-1][1], 0.575, 0.0, vx, vy, spread=(2 * sx, 2 * sy), bound=0.0)  # bound caps


def _drive(commands, dwell, lease=1.0):
    """Commands straight into an emulated robot's firmware and physics; returns the trace and the command times."""
    robot = EmulatedRobot(speed=1.0)
    robot.trace = []
    t, times = 0.0, []
    for k, beats in enumerate(commands, start=1):
        msg = pr.Message(pr.MsgType.SET_FINS, k, 1, fins=tuple(np.ravel(beats)), command=k, lease=lease)
        with robot._lock:
            robot.firmware.receive(msg, t)
            apply_firmware(robot.firmware, robot.model)
        times.append(t)
        t += dwell[k - 1]
        robot._advance(t)
    robot._advance(t + 6.0)  # coast
    robot.stop()
    return robot.trace, times


def test_physical_speed_bound_holds_against_the_full_model_over_random_commands():
    lim = ServoLimits()
    bound = SpeedBound(P, lim)
    rng = np.random.default_rng(3)
    for trial in range(4):
        commands, dwell = [], []
        for _ in range(25):
            bias = rng.choice([math.radians(90), rng.uniform(0.4, 2.7)], size=2)
            beats = np.stack([bias, rng.uniform(0, 1.2, 2), rng.uniform(0.3, 3, 2), rng.uniform(0.4, 7, 2)], axis=1)
            commands.append(beats)
            dwell.append(rng.choice([rng.uniform(0.1, 0.5), rng.uniform(1.0, 3.0)]))  # with lease gaps
        trace, times = _drive(commands, dwell)
        bound.reset(0.0)
        k = 0
        worst = 0.0
        for t, state, *_ in trace:
            while k < len(times) and times[k] <= t:
                bound.running(times[k], times[k] + 1.0 + 0.011)  # lease, plus one firmware tick
                k += 1
            speed = math.hypot(state[3], state[4])
            assert speed <= bound(t) + 1e-9, (trial, t, speed, bound(t))
            worst = max(worst, speed / max(bound(t), 1e-12))
        assert worst > 0.1  # the bound is not absurdly loose everywhere
    # By hand (docs/guide/safety.md, "Physical speed bound"): F = 2.53 N, kappa_P = c1 / m2^2 - leak = 6.50 / (kg m),
    # top = sqrt(F / kappa_P) / m1 = 0.70 m/s; growth F / m1 = 2.85 m/s^2.
    assert bound.top == pytest.approx(0.70, abs=0.01) and bound.accel == pytest.approx(2.85, abs=0.01)
