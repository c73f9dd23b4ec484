"""The band shield's choices on the robot (docs/notes/2026-12-04-nmpc-stops-2.md): a backup keeps its kind and side
while one of them is safe, and the NMPC's command must leave several safe backups.

The selection is checked with the rollouts' shortfalls replaced by chosen rows (the physics of the rollouts is
tests/test_nmpc_shield.py's and tests/test_firmware_path.py's); the expected patterns come from the spin cycle's
table and its mirror, not from the shield.
"""

import numpy as np
import pytest

from pectoral_gym.agents.baselines import make_baseline
from pectoral_gym.agents.controllers.band_shield import BACKUP_SPINS, BACKUP_TURNS, BandShield
from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.controllers.turning import SPIN_CYCLE, mirror
from pectoral_gym.agents.nmpc.shield import ROBOT_RESERVE
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.deploy import make_controller
from pectoral_gym.hardware.safety.rules import SafetyConfig
from pectoral_gym.registration import registered_settings

CONFIG = EnvConfig(model="full", task="goal")
STATE = np.array([1.15, 0.5, 0.0, 0.0, 0.0, 0.0])
N_TURNS, N_SPINS = 1 + 2 * len(BACKUP_TURNS), len(BACKUP_SPINS)
LEFT_SPIN, RIGHT_SPIN = N_TURNS, N_TURNS + N_SPINS  # the first left and right spin backups (4 periods)


def _shield(**kwargs) -> BandShield:
    return BandShield(CONFIG, FinMap(CONFIG), band=(0.05, 0.2, 0.01), firmware=True, **kwargs)


def _rows(shield: BandShield, safe_after: int, safe_now: list[int]):
    """Shortfalls with ``safe_after`` safe backups after each first command and ``safe_now`` safe from now."""
    n = len(shield.sides)

    def shortfalls(state, firsts):
        rows = np.ones((len(firsts) + 1, n))
        rows[:-1, :safe_after] = 0.0
        rows[-1, safe_now] = 0.0
        return rows

    return shortfalls


def _spin(phase: int, side: float) -> np.ndarray:
    """The spin's patterns ``(2, 4)`` [bias, amplitude, period, ratio] for ``phase``, from the cycle's table."""
    u = SPIN_CYCLE[phase] if side > 0 else mirror(SPIN_CYCLE[phase])  # amplitude R/L, bias R/L
    return np.array([[u[2], u[0], 0.5, 5.0], [u[3], u[1], 0.5, 5.0]])


def test_backup_table_is_coast_turns_then_spins():
    shield = _shield()
    assert shield.spins
    assert list(shield.sides[LEFT_SPIN:LEFT_SPIN + N_SPINS]) == [1.0] * N_SPINS
    assert list(shield.sides[RIGHT_SPIN:RIGHT_SPIN + N_SPINS]) == [-1.0] * N_SPINS
    assert shield.backups[1, RIGHT_SPIN, 0] == pytest.approx(_spin(1, -1.0))


@pytest.mark.parametrize("keep_side", [False, True])
def test_a_spin_under_way_keeps_its_side_while_one_remains_safe(monkeypatch, keep_side):
    """A right spin was sent; the law now wants the left and both spins are safe: the right spin goes on (kept),
    the old shield flipped to the left one (restarting the firmware's transitional strokes)."""
    shield = _shield(keep_side=keep_side)
    nominal = _spin(0, 1.0)
    monkeypatch.setattr(shield, "shortfalls", _rows(shield, 0, [LEFT_SPIN, RIGHT_SPIN]))
    first = shield.filter(STATE, nominal, side=-1.0)  # the law wants the right
    assert first == pytest.approx(_spin(0, -1.0))
    shield.applied(first)
    second = shield.filter(STATE, nominal, side=1.0)  # ... and now the left
    assert second == pytest.approx(_spin(1, -1.0) if keep_side else _spin(1, 1.0))
    shield.applied(second)
    monkeypatch.setattr(shield, "shortfalls", _rows(shield, 0, [LEFT_SPIN]))  # the right spin is no longer safe
    assert shield.filter(STATE, nominal, side=-1.0) == pytest.approx(_spin(2, 1.0))


def test_a_nominal_command_between_backups_ends_the_hold(monkeypatch):
    shield = _shield(keep_side=True)
    nominal = _spin(0, 1.0)
    monkeypatch.setattr(shield, "shortfalls", _rows(shield, 0, [LEFT_SPIN, RIGHT_SPIN]))
    shield.applied(shield.filter(STATE, nominal, side=-1.0))  # a right spin
    monkeypatch.setattr(shield, "shortfalls", _rows(shield, 3, []))
    shield.applied(shield.filter(STATE, nominal, side=-1.0))  # the nominal passes
    monkeypatch.setattr(shield, "shortfalls", _rows(shield, 0, [LEFT_SPIN, RIGHT_SPIN]))
    assert shield.filter(STATE, nominal, side=1.0) == pytest.approx(_spin(2, 1.0))  # the law's side again


@pytest.mark.parametrize("reserve, sent_nominal", [(1, True), (2, True), (3, False), (4, False)])
def test_the_nominal_command_must_leave_reserve_safe_backups(monkeypatch, reserve, sent_nominal):
    shield = _shield(reserve=reserve)
    nominal = np.array([[np.pi / 2, 0.2, 0.5, 5.0], [np.pi / 2, 0.2, 0.5, 5.0]])
    monkeypatch.setattr(shield, "shortfalls", _rows(shield, 2, [0]))  # two safe after it, the coast from now
    sent = shield.filter(STATE, nominal, side=1.0)
    if sent_nominal:
        assert sent == pytest.approx(nominal)
    else:
        assert sent == pytest.approx(shield.rest)  # the coast: both fins still
    assert shield.interventions == (0 if sent_nominal else 1)


def test_reserve_must_be_at_least_one():
    with pytest.raises(ValueError, match="reserve"):
        _shield(reserve=0)


def test_the_robot_nmpc_keeps_its_side_and_a_reserve_the_simulated_envs_do_not():
    assert ROBOT_RESERVE > 1
    robot = make_controller("nmpc", CONFIG, step_budget=1e6, safety=SafetyConfig()).shield.shield
    assert robot.firmware and robot.keep_side and robot.reserve == ROBOT_RESERVE
    v1 = make_baseline("nmpc", EnvConfig(**registered_settings("PectoralFish-Full-v1")), step_budget=1e6)
    sim = v1.shield.shield
    assert not sim.firmware and not sim.keep_side and sim.reserve == 1  # PectoralFish-Full-v1's shield unchanged
    hand = make_controller("hand", CONFIG, step_budget=1e6, safety=SafetyConfig()).shield
    assert hand.firmware and not hand.keep_side and hand.reserve == 1  # the hand law's shield unchanged
