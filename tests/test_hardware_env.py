"""HardwareFishEnv against the emulated robot and its rendered camera; PC-side safety rules."""

import math
import os
import signal

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.safety.geofence import Geofence, in_geofence
from pectoral_gym.hardware.safety.rules import CommandFilter, SafetyConfig, TrackingWatch, install_stop_handlers
from pectoral_gym.hardware.vision.scene import SceneConditions
from pectoral_gym.model import tank
from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.servo import ServoLimits
from pectoral_gym.model.tank import StopRule

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

SPEED = 2.0  # accelerated clock: a 0.5 s control period takes 0.25 s of wall time


@pytest.fixture
def rig():
    """An emulated robot at the tank centre and an env on it (generous tracking timeout for a loaded machine)."""
    robot = EmulatedRobot(speed=SPEED, seed=0, start_pose=(1.15, 0.575, 0.3)).start()
    env = HardwareFishEnv(robot.url, robot.camera(seed=1), speed=SPEED,
                          safety=SafetyConfig(tracking_timeout=1.5, link_timeout=2.0))
    yield robot, env
    env.close()
    robot.stop()


def _count_calls(monkeypatch, obj, name):
    calls = []
    original = getattr(obj, name)
    monkeypatch.setattr(obj, name, lambda *a, **k: calls.append(a) or original(*a, **k))
    return calls


def test_check_env_against_the_emulator(rig):
    robot, env = rig
    # Render and close checks would rebuild the env from its spec, which needs a port and a camera.
    check_env(env, skip_render_check=True, skip_close_check=True)
    obs, info = env.reset(seed=0)
    assert obs.shape == (19,) and obs.dtype == np.float32
    x, y, psi = robot.pose()
    # The tracked pose is the emulated fish's (tracker accuracy is hardware-vision's test; here: plumbing).
    assert obs[0] == pytest.approx(x, abs=0.01) and obs[1] == pytest.approx(y, abs=0.01)
    assert math.atan2(obs[3], obs[2]) == pytest.approx(psi, abs=math.radians(3))


def test_step_sends_the_command_and_reports_health(rig, monkeypatch):
    robot, env = rig
    env.reset(seed=1)
    sent = _count_calls(monkeypatch, env.link, "set_fins")
    action = np.array([0.0, 1.0, -1.0, 1.0, 0.0, 1.0, -1.0, 1.0], dtype=np.float32)
    obs, reward, terminated, truncated, info = env.step(action)
    assert len(sent) == 1
    # Action -> pattern as in simulation: bias 90 deg, amplitude 30 deg, period 0.5 s, ratio 5; its power
    # stroke peaks at pi A (zeta + 1) / T_p = 19.7 rad/s > 13: the period is stretched to pi A 6 / 13.
    assert np.allclose(info["command"], [[math.pi / 2, math.radians(30), math.pi * math.radians(30) * 6 / 13, 5.0]] * 2)
    assert not (terminated or truncated) and info["safety_stop"] == ""
    assert info["link"]["acked"] >= 1 and info["tracking"]["frames"] >= 1
    assert reward == pytest.approx(sum(info[k] for k in ("reward_progress", "reward_goal", "reward_wall",
                                                        "reward_energy", "reward_time")))
    assert np.allclose(robot.firmware.command, info["command"], atol=1e-3)


def test_nan_action_is_rejected_and_nothing_is_sent(rig, monkeypatch):
    robot, env = rig
    env.reset(seed=2)
    sent = _count_calls(monkeypatch, env.link, "set_fins")
    before = len([m for m in robot.received if m.type == pr.MsgType.SET_FINS])
    action = np.zeros(8, dtype=np.float32)
    action[3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        env.step(action)
    assert sent == [] and env.link.command is None  # still stopped since reset: no command was made
    assert len([m for m in robot.received if m.type == pr.MsgType.SET_FINS]) == before


def test_geofence_stops_and_ends_the_episode(rig, monkeypatch):
    robot, env = rig
    env.reset_hook = lambda rng: robot.place(0.12, 0.575, math.pi)  # nose 0.021 m from the wall < 0.05 m margin
    _, info = env.reset(seed=3)
    assert info["in_geofence"]
    sent = _count_calls(monkeypatch, env.link, "set_fins")
    _, _, terminated, truncated, info = env.step(np.zeros(8, dtype=np.float32))
    assert terminated and info["safety_stop"] == "geofence" and sent == []
    assert robot.firmware.state != pr.RobotState.RUNNING


def test_tracking_lost_stops_and_says_why(rig, monkeypatch):
    robot, env = rig
    env.reset(seed=4)
    env.step(np.zeros(8, dtype=np.float32))
    updates = _count_calls(monkeypatch, env.observer, "update")
    env.camera.conditions = SceneConditions(front_occlusion=1.0)  # the red marker disappears
    hidden = env.now()
    for _ in range(10):
        _, _, terminated, truncated, info = env.step(np.zeros(8, dtype=np.float32))
        if truncated:
            break
    assert truncated and not terminated and info["safety_stop"] == "tracking_lost"
    assert info["tracking"]["reason"] != "" and not info["tracking"]["ok"]
    assert all(t <= hidden for t, *_ in updates)  # the observer never got a made-up pose
    # The fins beat (15 deg): the geofence's worst-case motion of an unseen fish stops it before the 1.5 s
    # timeout (safety review, finding 9), never within the reaction budget of one missing frame.
    assert info["tracking"]["lost_for"] > SafetyConfig().stop_rule.reaction_time
    assert env.link.command is None


def test_link_lost_stops(rig):
    robot, env = rig
    env.reset(seed=5)
    env.safety = env.supervisor.safety = SafetyConfig(tracking_timeout=1.5, link_timeout=0.4)
    robot._handle = lambda data: None  # the radio goes silent; the camera still sees the fish
    for _ in range(6):
        _, _, _, truncated, info = env.step(np.zeros(8, dtype=np.float32))
        if truncated:
            break
    assert truncated and info["safety_stop"] == "link_lost"


def test_close_twice_sends_stop(rig):
    robot, env = rig
    env.reset(seed=6)
    env.step(np.full(8, 0.5, dtype=np.float32))
    env.close()
    env.close()
    assert any(m.type == pr.MsgType.STOP for m in robot.received[-5:])
    with pytest.raises(RuntimeError, match="closed"):
        env.step(np.zeros(8, dtype=np.float32))


def test_command_filter_clips_and_rate_limits():
    limits = ServoLimits(max_rate=(math.radians(90), math.radians(90), 1.0, 4.0))
    filt = CommandFilter(limits)
    filt.reset(np.array([[math.pi / 2, 0.0, 1.0, 1.0]] * 2))
    out = filt(np.array([[math.radians(135), math.radians(30), 2.0, 5.0]] * 2), dt=0.5)
    # 0.5 s: bias +45 deg, amplitude +30 deg (limit 45), period +0.5 s, ratio +2
    assert np.allclose(out[0], [math.radians(135), math.radians(30), 1.5, 3.0])
    assert filt.rate_limited and not filt.clipped
    out = filt(np.array([[math.radians(175), math.radians(30), 1.5, 3.0]] * 2), dt=10.0)
    assert out[0, 0] == pytest.approx(math.radians(140)) and filt.clipped  # 140 + 30 = 170 deg servo limit


def test_geofence_and_tracking_watch_by_hand():
    length = 0.2
    assert not in_geofence(1.0, 0.5, 0.0, length, 0.05)
    assert not in_geofence(2.30 - 0.16, 0.5, 0.0, length, 0.05)  # nose at 2.24 m: 0.06 m from the wall
    assert in_geofence(2.30 - 0.14, 0.5, 0.0, length, 0.05)  # nose at 2.26 m: 0.04 m from the wall
    assert not in_geofence(2.30 - 0.151, 0.5, math.pi / 2, length, 0.05)  # turned: the nose points along Y
    assert in_geofence(1.0, 0.14, -math.pi / 2, length, 0.05)  # nose at Y = 0.04
    assert in_geofence(math.nan, 0.5, 0.0, length, 0.05)
    watch = TrackingWatch(0.5)
    watch.reset(0.0)
    watch.update(0.3, False, "red marker not found")
    assert not watch.expired(0.5) and watch.expired(0.51) and watch.reason == "red marker not found"


def test_sigterm_handler_sends_stop(default_signal_handlers):
    calls = []
    restore = install_stop_handlers(lambda: calls.append("stop"))
    try:
        with pytest.raises(SystemExit):
            os.kill(os.getpid(), signal.SIGTERM)
            signal.sigtimedwait([], 0.1) if hasattr(signal, "sigtimedwait") else None
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            signal.sigtimedwait([], 0.1) if hasattr(signal, "sigtimedwait") else None
    finally:
        restore()
    assert calls == ["stop", "stop"]
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_ignored_sigint_still_sends_stop_and_stays_ignored(default_signal_handlers):
    calls = []
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # e.g. a deploy started with `&` from a script
    restore = install_stop_handlers(lambda: calls.append("stop"))
    try:
        os.kill(os.getpid(), signal.SIGINT)
        signal.sigtimedwait([], 0.1) if hasattr(signal, "sigtimedwait") else None
    finally:
        restore()
    assert calls == ["stop"]  # the fish stops; the process goes on, as the user asked by ignoring SIGINT
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_geofence_outline_clearance_by_hand():
    p = FishParams()
    fence = Geofence(p, StopRule(margin=0.05, reaction_time=0.0, contact_speed=0.03))
    half, cp, sp = 0.5 * p.body_length, p.fin_offset, p.fin_span
    # Heading +X at (1.0, 0.5): tail capsule end to X = 0; fin discs around (1.0, 0.5 -+ C_p) to Y = 0 and Y = W.
    assert np.allclose(fence.clearance(1.0, 0.5, 0.0),
                       [1.0 - half - cp, 2.30 - 1.0 - half - cp, 0.5 - cp - sp, 1.15 - 0.5 - cp - sp])
    y_tip = 0.05 + cp + sp + 0.001  # fin disc 1 mm beyond the margin: clear at rest, not when drifting to the wall
    assert not fence.breached(1.0, y_tip, 0.0)
    assert fence.breached(1.0, y_tip - 0.002, 0.0)
    # Below the contact speed a drift needs no coasting distance, only its reaction distance (0 here).
    assert not fence.breached(1.0, y_tip, 0.0, vy=-0.01) and not fence.breached(1.0, y_tip, 0.0, vy=0.01)
    assert fence.breached(1.0, y_tip, 0.0, vy=-0.031) and not fence.breached(1.0, y_tip, 0.0, vy=0.031)
    assert fence.breached(1.0, 0.5, 0.0, vx=math.nan)


def test_coasting_distance_closed_form_matches_the_full_model():
    # Independent check: the full model's RK4 integration of eq. (19) with the fins held still.
    p = FishParams()
    contact = 0.03
    fence = Geofence(p, StopRule(margin=0.0, reaction_time=0.0, contact_speed=contact))
    model = FullModel(1, p)
    coef = body_coefficients(p)
    k = coef.c1 / coef.m1
    model.reset(np.array([0.0, 0.0, 0.0, 0.2, 0.0, 0.0]))  # surge: m1 dv/dt = -c1 v |v| exactly
    model.advance(3.0)
    assert model.state[0, 0] == pytest.approx(math.log1p(k * 0.2 * 3.0) / k, rel=2e-3)
    # v(t) = v0 / (1 + k v0 t): down to the contact speed at t_c = (v0 / v_c - 1) / (k v0), after ln(v0 / v_c) / k.
    model.reset(np.array([0.0, 0.0, 0.0, 0.2, 0.0, 0.0]))
    model.advance((0.2 / contact - 1.0) / (k * 0.2))
    assert model.state[0, 3] == pytest.approx(contact, rel=2e-3)
    assert model.state[0, 0] == pytest.approx(math.log(0.2 / contact) / k, rel=2e-3)
    assert fence.coast(0.2) >= model.state[0, 0]  # the fence uses the slower (sway, m2) decay
    assert fence.coast(contact) == 0.0 and fence.coast(-0.1) == 0.0
    model.reset(np.array([0.0, 0.0, 0.0, 0.0, 0.2, 0.0]))  # sway: the lift term of (20) also drains it
    model.advance((0.2 / contact - 1.0) / (tank.coast_rate(coef) * 0.2))
    assert 0.5 * fence.coast(0.2) < model.state[0, 1] <= fence.coast(0.2)
