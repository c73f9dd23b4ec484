"""The robot firmware's command path in the backup shield (pectoral_gym.agents.controllers.firmware_path).

The reference is the firmware's own code: :class:`pectoral_gym.model.finreplay.FinReplay` runs the full model
under :class:`pectoral_gym.hardware.radio.firmware.Firmware` (messages, ticks, ``clip_beats``, ``rate_limit``,
``stretch_transition``), as the emulated robot does.
"""

import math

import numpy as np
import pytest

from pectoral_gym.agents.controllers.band_shield import BandShield
from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.controllers.firmware_path import FirmwarePath
from pectoral_gym.agents.controllers.turning import SPIN_CYCLE
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.deploy import make_controller
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.model.finreplay import FinReplay
from pectoral_gym.model.finrules import stretch_transition
from pectoral_gym.model.servo import ServoLimits, clip_beats
from pectoral_gym.model.spec import FULL_REFERENCE
from pectoral_gym.model.tank import ROBOT_STOP_RULE
from pectoral_gym.registration import registered_settings

CONFIG = EnvConfig(model="full", task="goal")  # the robot env's (pectoral_gym.hardware.env.HardwareFishEnv)
DT = CONFIG.control_period
SWIM = np.radians([[90.0, 20.0], [90.0, 20.0]])  # both fins at 20 deg: straight swimming


def _patterns(fins: FinMap, bias_amp: np.ndarray) -> np.ndarray:
    """Patterns ``(2, 4)`` of ``((bias, amplitude) right, (bias, amplitude) left)``, as the env latches them."""
    p = np.array([[*bias_amp[0], fins.period, fins.ratio], [*bias_amp[1], fins.period, fins.ratio]])
    return CONFIG.decode(CONFIG.encode(p))


def _spin_sequence(fins: FinMap, swim: int, spin: int) -> list[np.ndarray]:
    """``swim`` control periods of straight swimming, then ``spin`` of the left spin (SPIN_CYCLE from phase 0)."""
    rows = [_patterns(fins, SWIM)] * swim
    for k in range(spin):
        u = SPIN_CYCLE[k % len(SPIN_CYCLE)]  # amplitude R/L, bias R/L
        rows.append(_patterns(fins, np.array([[u[2], u[0]], [u[3], u[1]]])))
    return rows


def test_batched_rules_are_the_firmware_functions():
    rng = np.random.default_rng(3)
    limits = ServoLimits()
    beats = np.stack([rng.uniform(0.2, 3.0, (50, 2)), rng.uniform(0.0, 1.5, (50, 2)), rng.uniform(0.2, 5.0, (50, 2)),
                      rng.uniform(0.3, 7.0, (50, 2))], -1)
    clipped, changed = clip_beats(beats, limits)  # the batch at once, as the shield's rollouts call it
    assert clipped.shape == (50, 2, 4) and changed
    turn, power = rng.uniform(0.2, 3.0, (50, 2)), rng.random((50, 2)) < 0.5
    stretched = stretch_transition(clipped, turn, power, limits)
    for i in range(50):
        np.testing.assert_allclose(clipped[i], clip_beats(beats[i], limits)[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(stretched[i], stretch_transition(clipped[i], turn[i], power[i], limits), atol=1e-12)


def test_full_model_through_the_path_follows_the_firmware():
    fins = FinMap(CONFIG)
    replay = FinReplay(CONFIG.params)
    model, path = FULL_REFERENCE.build(1, CONFIG.params), FirmwarePath(1)
    model.reset()
    replay.advance(DT)  # the firmware ticks from power-up, before the first command
    path.advance(model, DT)
    for k, p in enumerate(_spin_sequence(fins, 4, 12)):
        replay.command((k + 1) * DT, p)
        replay.advance((k + 2) * DT)
        path.command(p[None])
        path.advance(model, DT)
    # 8 s, 6 of them spinning: the wire rounds the command to 1 mrad, nothing else differs (the rate rule acts
    # where a fin latches, on the fins' own clock: on which grid the replay ticks does not matter)
    np.testing.assert_allclose(model.state[0, :2], replay.model.state[0, :2], atol=0.002)
    assert model.state[0, 2] == pytest.approx(replay.model.state[0, 2], abs=math.radians(0.5))


def test_shield_predicts_the_spin_drift_the_robot_has():
    """The shield's planning model through the firmware's rules moves as the full model through the firmware does.

    From 3 s of straight swimming, 10 s of the spin: through the firmware each latch is rate-limited
    (``slew_at_latch``: the spin's 0.083 s power strokes let the bias move 15 deg) and the transitional strokes
    stretched; a prediction that latches every pattern as sent misses that.
    """
    fins = FinMap(CONFIG)
    sequence = _spin_sequence(fins, 6, 20)
    replay = FinReplay(CONFIG.params)
    shield = BandShield(CONFIG, fins, band=ROBOT_STOP_RULE)
    as_sent = BandShield(CONFIG, fins, band=ROBOT_STOP_RULE, firmware=False)
    assert shield.firmware and not as_sent.firmware
    starts = {}
    for k, p in enumerate(sequence):
        if k == 6:
            starts = {"robot": replay.model.state[0, :2].copy(), "shield": shield._shadow.state[0, :2].copy(),
                      "as_sent": as_sent._shadow.state[0, :2].copy()}
        replay.command(k * DT, p)
        replay.advance((k + 1) * DT)
        shield.applied(p)
        as_sent.applied(p)
    robot = replay.model.state[0, :2] - starts["robot"]
    predicted = shield._shadow.state[0, :2] - starts["shield"]
    old = as_sent._shadow.state[0, :2] - starts["as_sent"]
    assert np.hypot(*robot) > 0.3  # the drift: 10 s at ~0.04 m/s, and the glide out of the swim
    assert np.hypot(*(predicted - robot)) < 0.03
    assert np.hypot(*(old - robot)) > 2 * np.hypot(*(predicted - robot))


def test_firmware_path_is_on_where_the_band_is_the_robot_supervisors():
    assert make_controller("hand", CONFIG, step_budget=1e6, safety=SafetyConfig()).shield.firmware
    assert make_controller("nmpc", CONFIG, step_budget=1e6, safety=SafetyConfig()).shield.shield.firmware
    v1 = EnvConfig(**registered_settings("PectoralFish-Full-v1"))
    assert not BandShield(v1, FinMap(v1)).firmware  # the simulated env latches the patterns as sent
    assert not BandShield(CONFIG, FinMap(CONFIG)).firmware
