"""The PC's replay of the robot's fins (``observe_fins=True`` on the robot env) against the emulated fins."""

import copy
import time

import numpy as np
import pytest

from pectoral_gym.envs.observation import FIN_OBS_SIZE, OBS_FINS, OBS_SIZE, decode
from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.model import strokes
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import CHUNK, FirmwareConfig
from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.servo import ServoLimits

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop

SPEED = 2.0


def test_replay_follows_the_parameter_change_rule_when_the_firmware_passes_commands_through():
    # Servo limits far beyond the patterns (no clipping, no slewing): the replay must then be the model's own
    # parameter-change rule (docs/model.md section 5), run here by FullModel.command_array at the same times.
    wide = ServoLimits(max_speed=1e3, max_rate=(1e6, 1e6, 1e6, 1e6))
    patterns = [FinBeat.from_degrees(90, 10, 2.0, 1.0), FinBeat.from_degrees(100, 25, 1.0, 3.0),
                FinBeat.from_degrees(70, 15, 0.6, 4.0), FinBeat.from_degrees(95, 30, 1.4, 1.5)]
    rng = np.random.default_rng(0)
    replay, model = FinReplay(firmware=FirmwareConfig(limits=wide)), FullModel(1)
    model.reset()
    for k in range(12):
        t = 0.5 * k
        command = np.array([patterns[i].as_array() for i in rng.integers(0, len(patterns), 2)])
        replay.command(t, command)
        model.advance(t - model.time)
        model.command_array(command[None])
        replay.advance(t + 0.5)
        model.advance(t + 0.5 - model.time)
        # the wire's mrad and ms; the firmware applies a command at its next 10 ms tick, here the one at the
        # command's time (the model's swept-work accumulator is not the replay's business)
        np.testing.assert_allclose(replay.fins[..., :strokes.SWEPT], model.fins[..., :strokes.SWEPT], atol=2e-3,
                                   err_msg=f"step {k}")


def test_replay_with_the_robots_limits_follows_the_model_through_still_fins():
    # The robot's own limits, patterns that neither the rate rule nor the servos' peak rate bind, and still fins
    # (amplitude 0) among them: the firmware's fins must run what the model commanded at the same times runs,
    # advanced in the same 10 ms pieces. Two past faults: a still fin handed its pattern again at every tick
    # restarted its half-stroke each time; and a moving fin latched ran + (command - ran), 1e-16 rad off the
    # command, so the still half-stroke that followed counted as moving and missed its latch at once for up to
    # its whole duration (1.855 -> 0.785 rad below is such a pair).
    still = [np.array([1.855, 0.0, 1.534, 1.195]), np.array([0.785, 0.0, 1.786, 3.483]),
             np.array([1.765, 0.0, 1.914, 3.062]), np.array([1.2, 0.0, 1.3, 2.0])]
    moving = [FinBeat.from_degrees(90, 15, 1.6, 1.5).as_array(), FinBeat.from_degrees(100, 10, 1.3, 2.0).as_array(),
              FinBeat.from_degrees(75, 20, 1.8, 1.2).as_array()]
    patterns = still + moving
    order = [0, 1, 2, 2, 1, 4, 1, 5, 3, 3, 6, 0, 1, 2, 4, 4]  # the incident's sequence first, then a mix
    rng = np.random.default_rng(3)
    replay, model = FinReplay(), FullModel(1)
    model.reset()
    for k, first in enumerate(order):
        t = 0.5 * k
        command = np.array([patterns[first], patterns[order[(k + 3 + int(rng.integers(0, 5))) % len(order)]]])
        replay.command(t, command)
        while model.time < t - 1e-12:
            model.advance(min(CHUNK, t - model.time))
        model.command_array(command[None])
        replay.advance(t + 0.5)
        while model.time < t + 0.5 - 1e-12:
            model.advance(min(CHUNK, t + 0.5 - model.time))
        np.testing.assert_allclose(replay.fins[..., :strokes.SWEPT], model.fins[..., :strokes.SWEPT], atol=2e-3,
                                   err_msg=f"step {k}")


def test_replay_halts_the_fins_where_they_are():
    replay = FinReplay()
    replay.command(0.0, np.array([FinBeat.from_degrees(90, 20, 1.0, 1.0).as_array()] * 2))
    replay.advance(0.6)
    angles = strokes.fin_angles(replay.fins)[0][0].copy()
    replay.stop(0.6)
    replay.advance(2.0)
    np.testing.assert_allclose(strokes.fin_angles(replay.fins)[0][0], angles, atol=1e-9)
    assert np.all(replay.fins[0, :, strokes.ANGLE_FROM] == replay.fins[0, :, strokes.ANGLE_TO])


@pytest.fixture
def rig():
    robot = EmulatedRobot(speed=SPEED, seed=0, start_pose=(1.15, 0.575, 0.3)).start()
    env = HardwareFishEnv(robot.url, robot.camera(seed=1), speed=SPEED, observe_fins=True,
                          safety=SafetyConfig(tracking_timeout=1.5, link_timeout=2.0))
    yield robot, env
    env.close()
    robot.stop()


def _robot_fins_mid_stroke(robot, tries=15):
    """The emulated fins and their time, read away from a turning point (where a tick decides the stroke).

    At most ``tries`` x 10 ms of wall time (0.3 s of robot time): well inside the command's 0.8 s lease.
    """
    for _ in range(tries):
        with robot._lock:
            fins, t = robot.model.fins.copy(), robot.model.time
        left = fins[0, :, strokes.DURATION] - fins[0, :, strokes.ELAPSED]
        moving = fins[0, :, strokes.ANGLE_FROM] != fins[0, :, strokes.ANGLE_TO]
        if np.all(~moving | ((fins[0, :, strokes.ELAPSED] > 0.05) & (left > 0.05))):
            return fins, t
        time.sleep(0.01)
    pytest.fail("the emulated fins were never away from a turning point")


def test_robot_env_fin_block_matches_the_emulated_fins(rig):
    # Commands that change by about ServoLimits.max_rate x 10 ms per step: where a command reaches the robot
    # a few ms (radio, poll, tick) before a turning point and the replay a few ms after it, the two latch
    # patterns one command apart, which differ by no more than that; the replay must follow the emulated fins
    # to the radio latency (the rate rule acts at the latch, on the fins' own clock: slew_at_latch).
    robot, env = rig
    obs, _ = env.reset(seed=0)
    assert obs.shape == (OBS_SIZE + FIN_OBS_SIZE,) and env.observation_space.contains(obs)
    config = env.config
    for k in range(8):
        right = FinBeat.from_degrees(90 + 0.8 * k, 1.5 * (k + 1), 1.0 + 0.03 * k, 1.0 + 0.05 * k).as_array()
        left = FinBeat.from_degrees(90 - 0.8 * k, 1.2 * (k + 1), 1.0 - 0.02 * k, 1.0 + 0.08 * k).as_array()
        action = np.concatenate([config.encode(right), config.encode(left)]).astype(np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        assert info["safety_stop"] == "" and not (terminated or truncated)
        assert decode(obs).fins.shape == (2, 4) and np.all(np.abs(obs[OBS_FINS]) <= 1)
        fins, robot_time = _robot_fins_mid_stroke(robot)
        # the same instant on the PC's experiment clock (both clocks: monotonic time since their origin x speed)
        replay = copy.deepcopy(env.fin_replay)
        replay.advance(robot_time + (robot._origin - env._origin) * SPEED)
        got = replay.fins[0]
        np.testing.assert_array_equal(got[:, strokes.POWER], fins[0, :, strokes.POWER], err_msg=f"step {k}")
        # to one command's change (ServoLimits.max_rate x CHUNK, above) and the wire's quantisation
        bias_rate, amplitude_rate, period_rate, ratio_rate = env.safety.limits.max_rate
        for field, rate in ((strokes.BIAS, bias_rate), (strokes.AMPLITUDE, amplitude_rate),
                            (strokes.PERIOD, period_rate), (strokes.RATIO, ratio_rate),
                            (strokes.ANGLE_FROM, bias_rate + amplitude_rate),
                            (strokes.ANGLE_TO, bias_rate + amplitude_rate), (strokes.DURATION, period_rate)):
            np.testing.assert_allclose(got[:, field], fins[0, :, field], atol=rate * CHUNK + 2e-3,
                                       err_msg=f"step {k}, field {field}")
        # the stroke clocks: the robot latched a few ms (radio, poll, tick) after the PC sent
        np.testing.assert_allclose(got[:, strokes.ELAPSED], fins[0, :, strokes.ELAPSED], atol=0.05,
                                   err_msg=f"step {k}")
