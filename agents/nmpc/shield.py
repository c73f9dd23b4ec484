"""The NMPC's commands through the hand law's backup shield: a hard guard against the stopping band.

The NLP prices the band only as a soft term (:func:`pectoral_gym.agents.controllers.stop_band.band_violation`)
on the averaged model's cycle-mean velocity over a horizon of a few seconds; the fish cannot brake and
turns on a ~0.25 m circle, so a plan that is clear now can still leave no way out later. The shield
(:class:`pectoral_gym.agents.controllers.band_shield.BandShield`, the one the hand law uses) lets a command
through only if, after it, some backup (coast, a slow one-fin turn, an on-the-spot spin) keeps a 16 s
rollout out of the band; otherwise it sends the best backup's first interval. :class:`CommandShield`
translates between the NMPC's :class:`~pectoral_gym.agents.nmpc.problem.FinInputs` rows and the shield's
fin patterns, and keeps the shield's shadow fins in step with every command sent. On the robot (the shield through
the firmware's command path) it also keeps a backup's side and wants :data:`ROBOT_RESERVE` safe backups after a
command, not one (``docs/notes/2026-12-04-nmpc-stops-2.md``).
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.agents.controllers.band_shield import BandShield, through_firmware
from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.nmpc.handover import goal_bearing
from pectoral_gym.agents.nmpc.problem import FinInputs
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.tank import StopRule

__all__ = ["ROBOT_RESERVE", "CommandShield"]

ROBOT_RESERVE = 4  # safe backups the plan's command must leave on the robot (docs/notes/2026-12-04-nmpc-stops-2.md)


class CommandShield:
    """Filters NMPC commands (``FinInputs`` rows, amplitudes and biases [rad]) through a :class:`BandShield`.

    Args:
        config: The environment settings.
        fins: The controller's fin map (its period and ratio are the patterns' own).
        band: The :class:`~pectoral_gym.model.tank.StopRule` of the band kept out of; ``None``:
            ``BandShield``'s default (the env's ``stop_rule`` where its ``stop_band`` is on, else the robot's).
        extra_margin: Clearance [m] added to the band's margin in the shield's rollouts.
        speed_spread: Speed [m/s] added towards every wall in the rollouts (``BandShield``'s).
        spin: Back up with the on-the-spot spin too (``BandShield``'s).
        firmware: Predict the commands through the robot firmware's command path (``BandShield``'s; ``None``: its
            default).
        keep_side: Keep a backup's kind and side while one of them is safe (``BandShield``'s); ``None``: where the
            shield predicts through the firmware (the robot).
        reserve: Safe backups the plan's command must leave to be sent (``BandShield``'s); ``None``:
            :data:`ROBOT_RESERVE` where the shield predicts through the firmware, else 1.

    Attributes:
        shield: The :class:`BandShield` (its ``interventions`` and ``slowed`` count this episode's replaced and
            half-amplitude commands).
    """

    def __init__(self, config: EnvConfig, fins: FinMap, band: StopRule | None,
                 extra_margin: float = 0.02, speed_spread: float = 0.0, spin: bool = True,
                 firmware: bool | None = None, keep_side: bool | None = None, reserve: int | None = None):
        self.fins = fins
        robot = through_firmware(config, band, firmware)  # the robot's command path: its spins drift, so hold
        self.shield = BandShield(  # them and react earlier
            config, fins, band=band, extra_margin=extra_margin, speed_spread=speed_spread, spin=spin, firmware=robot,
            keep_side=robot if keep_side is None else keep_side,
            reserve=(ROBOT_RESERVE if robot else 1) if reserve is None else reserve)

    def reset(self) -> None:
        """Start of an episode (the shadow fins at rest)."""
        self.shield.reset()

    def patterns(self, u: np.ndarray) -> np.ndarray:
        """Fin patterns ``(2, 4)`` (bias, amplitude, period, ratio per fin, right first) of inputs ``u (4,)``."""
        u, f = FinInputs(*np.asarray(u, dtype=np.float64)), self.fins
        return np.array([[u.bias_right, u.amplitude_right, f.period, f.ratio],
                         [u.bias_left, u.amplitude_left, f.period, f.ratio]])

    def filter(self, state: np.ndarray, u: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The inputs ``(4,)`` to send instead of ``u``: ``u``, slowed, or a backup's first interval.

        Args:
            state: Body state ``(X, Y, psi, vx, vy, omega)`` [m, m, rad, m/s, m/s, rad/s].
            u: The plan's inputs (``FinInputs`` order).
            goal: The target ``(X, Y)`` [m]: a backup turns towards its side when the command itself does not turn.
        """
        u = np.asarray(u, dtype=np.float64)
        a = FinInputs(*u)
        turn = a.amplitude_right - a.amplitude_left  # > 0: the right fin rows harder, a left turn
        side = turn if abs(turn) > 1e-9 else math.copysign(1.0, math.sin(goal_bearing(state, goal)[1]))
        p = self.shield.filter(np.asarray(state, dtype=np.float64), self.patterns(u), side)
        return np.array(FinInputs(p[0, 1], p[1, 1], p[0, 0], p[1, 0]))

    def spun(self, u: np.ndarray, sent: np.ndarray) -> bool:
        """Whether ``sent`` replaced ``u`` by a backup spin (biases off the middle): no motion the NLP predicts."""
        return not np.array_equal(sent, u) and not np.allclose(np.asarray(sent)[2:], self.fins.bias_mid)

    def applied(self, u: np.ndarray) -> None:
        """Follow the inputs ``u (4,)`` sent, for one control period."""
        self.shield.applied(self.patterns(u))
