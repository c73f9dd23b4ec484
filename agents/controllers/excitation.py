"""Identification runs: seeded random fin patterns that excite the model's parameters, kept out of the stopping band.

A model calibration (``python -m pectoral_gym.scaling calibrate``, docs/calibration.md) fits the fish's drag, lift,
moment and fin force coefficients and its added masses from logged runs. A run in which the fish only swims
straight at one speed tells the surge drag from the thrust at that speed and nothing else: the fit needs
accelerations and decelerations, turns of either sign and several speeds. :class:`ExcitationController` holds a
fin pattern drawn uniformly from the env's ranges (bias, amplitude, period and ratio of each fin, independently:
straight runs, turns, coasting) for a random 2-6 s, then draws the next, from the episode's seed.

Safely: each pattern goes through the hand law's backup shield
(:class:`pectoral_gym.agents.controllers.band_shield.BandShield`), which sends it only if a backup manoeuvre
out of the robot's stopping band remains afterwards, else the backup's first interval. On the robot the safety
supervisor still judges every frame; the shield only keeps its stops rare.
"""

from __future__ import annotations

import numpy as np

from pectoral_gym.agents.controllers.band_shield import BandShield
from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.observation import decode, one_observation

__all__ = ["EXTRA_MARGIN", "HOLD", "ExcitationController"]

HOLD = (2.0, 6.0)  # s a drawn pattern is held for, uniform in this range
# The shield's extra clearance [m]: random patterns (any period and ratio) are predicted less well by the planning
# model than the hand law's fixed ones. PectoralFish-Full-v1, episodes 300-319 (20 each): 0.02 m (the hand law's)
# 10 band ends, 0.06 m 6, 0.12 m none.
EXTRA_MARGIN = 0.12


class ExcitationController:
    """Seeded random fin patterns, each held for a random time, filtered by the band shield.

    Args:
        config: The environment settings (ranges, control period, parameters, stop band).
        hold: ``(shortest, longest)`` time a pattern is held [s], at least one control period.
        seed: Seed of the patterns and hold times; ``reset(seed)`` reseeds.
        shield: Filter through :class:`BandShield` (``False``: the raw patterns; the fish then meets the geofence).

    Raises:
        ValueError: For a ``hold`` range that is empty, not positive or not finite.
    """

    name = "excite"

    def __init__(self, config: EnvConfig, hold: tuple[float, float] = HOLD, seed: int | None = 0,
                 shield: bool = True):
        low, high = (float(v) for v in hold)
        if not (np.isfinite(low) and np.isfinite(high) and 0 < low <= high):
            raise ValueError(f"hold must be (shortest, longest) seconds with 0 < shortest <= longest, got {hold!r}")
        self.config = config
        self.hold = (low, high)
        self.fins = FinMap(config)
        self.shield = BandShield(config, self.fins, extra_margin=EXTRA_MARGIN) if shield else None
        self._seed = seed
        self.reset(seed)

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode: reseed (``None``: the constructor's seed) and draw a new pattern at the next step."""
        self._rng = np.random.default_rng(self._seed if seed is None else seed)
        self._pattern = np.zeros((2, 4))
        self._left = 0  # control periods the current pattern is still held for
        if self.shield is not None:
            self.shield.reset()

    def _draw(self) -> None:
        ranges = self.config.ranges  # (4, 2): bias, amplitude, period, ratio [rad, rad, s, -]
        self._pattern = self._rng.uniform(ranges[:, 0], ranges[:, 1], size=(2, 4))
        dt = self.config.control_period
        self._left = max(1, int(round(self._rng.uniform(*self.hold) / dt)))

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Action ``(8,)`` float32 for one observation (the shield reads the pose and velocities from it)."""
        obs = one_observation(obs)  # the fin block (observe_fins), if any, is not read
        if self._left <= 0:
            self._draw()
        self._left -= 1
        patterns = self._pattern
        if self.shield is not None:
            o = decode(obs)
            state = np.array([o.x, o.y, np.arctan2(o.sin_psi, o.cos_psi), o.vx, o.vy, o.omega])
            side = float(np.sign(patterns[0, 1] - patterns[1, 1]))  # > 0: the right fin rows harder, a left turn
            patterns = self.shield.filter(state, patterns, side)
            self.shield.applied(patterns)
        code = np.concatenate([self.config.encode(patterns[0]), self.config.encode(patterns[1])])
        return code.astype(np.float32)
