"""A graded per-step cost near the stopping band, for constrained (safe) RL.

An env with ``stop_band`` (the v1 and v2 ids) ends its episode when any part of the fish is inside the robot's
stopping band and reports ``info["cost"] = 1`` on that step only: an episode's cost is 0 or 1, and the step that
carries it also carries the wall penalty, so a constrained learner has nothing to trade. :class:`BandCost` adds
``info["band_cost"]``, a cost on every step that grows as the fish comes up to the band:

    ``band_cost = clip(1 + shortfall / width, 0, 1)``

``shortfall`` [m] is the band's own measure, :func:`pectoral_gym.model.tank.band_shortfall` (the same compiled
function the env's episode end uses, on the same state, rule and parameters): the largest of
``stop_need(v) - clearance`` over the outline's circles and the four walls, ``v`` the speed towards that wall;
> 0 inside the band. So ``band_cost`` is 0 while every part of the fish keeps ``width`` more than its speed needs
to stop, rises linearly to 1 at the band's edge, and is 1 inside it, on the step that ends the episode (where
``info["cost"]`` is 1 too). The hard limit stays the env's: the episode still ends in the band, with its penalty.

:data:`BAND_COST_WIDTH` is 0.10 m: half the fish's body length (0.198 m), and two control periods (0.5 s each)
at 0.1 m/s, a brisk speed for this fish (one at which the robot-ready band already asks for 0.30 m of clearance,
``stop_need(0.1)`` with the v2 rule). A fish approaching the band at 0.1 m/s so pays a rising cost over about two
steps before it, a slower one over more. :class:`BandCost` takes another width.

:class:`SafetyStep` is Safety-Gymnasium's interface: ``step`` returns ``(obs, reward, cost, terminated, truncated,
info)`` with ``band_cost`` as the cost.

Nothing here changes an env: the wrappers read its state after each step.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from pectoral_gym.envs.tasks.kernels import band_shortfall_of

__all__ = ["BAND_COST_WIDTH", "BandCost", "SafetyStep", "band_cost", "env_band_shortfall"]

#: Width [m] of the zone before the stopping band over which ``band_cost`` rises from 0 to 1 (module docstring).
BAND_COST_WIDTH = 0.10


def band_cost(shortfall: float | np.ndarray, width: float = BAND_COST_WIDTH) -> float | np.ndarray:
    """``clip(1 + shortfall / width, 0, 1)``: the cost of a band shortfall [m] (> 0: inside the band).

    Raises:
        ValueError: If ``width`` is not > 0.
    """
    if not width > 0.0:
        raise ValueError(f"width must be > 0 m, got {width!r}")
    return np.clip(1.0 + np.asarray(shortfall, dtype=np.float64) / width, 0.0, 1.0)


def env_band_shortfall(env: gym.Env, index: int = 0) -> float:
    """The band shortfall [m] of env ``index`` of a simulated env's core (``env.unwrapped.core``) in its state now.

    The env's episode end's own compiled function (``pectoral_gym.envs.tasks.kernels.band_shortfall_of``): the
    world-frame velocity from the body velocity, the outline and coasting rate of the episode's parameters, the
    env's stop rule.
    """
    core = env.unwrapped.core
    return float(band_shortfall_of(int(index), core.model.state, core.cfg, core.fish))


class BandCost(gym.Wrapper):
    """Adds ``info["band_cost"]`` (module docstring) to ``reset`` and every ``step`` of a stop-band env.

    Args:
        env: A simulated env (``gym.make`` of a registered id, or its wrappers) with ``stop_band``.
        width: :data:`BAND_COST_WIDTH` or another width [m], > 0.
        key: The ``info`` key it goes to: ``"band_cost"``, or ``"cost"`` for a library that reads only that key
            (the env's own 0/1 cost is then replaced; it is 1 exactly where the graded cost reaches 1 at the
            episode's end in the band).

    Raises:
        ValueError: If the env has no stopping band (the ``-v0`` ids), ``width`` is not > 0 or ``key`` is another.
    """

    def __init__(self, env: gym.Env, width: float = BAND_COST_WIDTH, key: str = "band_cost"):
        super().__init__(env)
        config = getattr(env.unwrapped, "config", None)
        if config is None or not hasattr(env.unwrapped, "core"):
            raise ValueError(f"BandCost needs a simulated pectoral_gym env, got {env.unwrapped!r}")
        if not config.stop_band:
            raise ValueError("BandCost needs an env with stop_band=True (the v1 and v2 ids); this one has no band")
        band_cost(0.0, width)  # checks the width
        if key not in ("band_cost", "cost"):
            raise ValueError(f"key must be 'band_cost' or 'cost', got {key!r}")
        self.width = float(width)
        self.key = key

    def _add(self, info: dict[str, Any]) -> dict[str, Any]:
        info[self.key] = np.float64(band_cost(env_band_shortfall(self.env), self.width))
        return info

    def reset(self, **kwargs: Any):
        """The env's ``reset``, its ``info`` with the cost of the first state."""
        obs, info = self.env.reset(**kwargs)
        return obs, self._add(info)

    def step(self, action):
        """The env's ``step``, its ``info`` with the cost of the state reached."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._add(info)


class SafetyStep(gym.Wrapper):
    """Safety-Gymnasium's step: ``(obs, reward, cost, terminated, truncated, info)``, the cost the graded one.

    ``reset`` is Gymnasium's. Wraps the env in :class:`BandCost` (``width``) unless it already is, and reads the
    cost from that wrapper's key.
    """

    def __init__(self, env: gym.Env, width: float = BAND_COST_WIDTH):
        inner = _band_cost_wrapper(env)
        super().__init__(env if inner is not None else BandCost(env, width))
        self._key = (inner or self.env).key

    def step(self, action):  # type: ignore[override]
        """``(obs, reward, cost, terminated, truncated, info)``, ``cost`` the graded cost as a float."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, float(info[self._key]), terminated, truncated, info


def _band_cost_wrapper(env: gym.Env) -> BandCost | None:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, BandCost):
            return env
        env = env.env
    return None
