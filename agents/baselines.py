"""Baseline controllers: random actions, a hand-designed feedback law and NMPC.

All three implement :class:`pectoral_gym.agents.training.policy.Controller` and are built by
:func:`make_baseline` from the environment's :class:`~pectoral_gym.envs.core.EnvConfig`
(``env.unwrapped.config``), so they map physical fin patterns to normalised
actions through the same ranges as the environment (``EnvConfig.encode``).
The hand controller lives in :mod:`pectoral_gym.agents.controllers.hand` (the NMPC uses it as its base policy).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.controllers.hand import HandController
from pectoral_gym.envs.core import EnvConfig

__all__ = ["BASELINES", "FinMap", "HandController", "RandomController", "make_baseline"]

BASELINES = ("random", "hand", "nmpc", "excite")


class RandomController:
    """Uniform random actions in [-1, 1]^8 from a seeded generator.

    Args:
        seed: Seed of the generator; ``reset(seed)`` reseeds it.
    """

    name = "random"

    def __init__(self, seed: int | None = 0):
        self._seed = seed
        self._rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        """Reseed when ``seed`` is given (otherwise the stream continues)."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """A uniform random action (the observation is ignored)."""
        return self._rng.uniform(-1.0, 1.0, 8).astype(np.float32)


def scaling_flag_problem(controller: str | None, scaling: str | None) -> str | None:
    """Why a command line's ``--scaling FILE`` cannot drive ``controller`` (``None``: it can, or none was given).

    The file is the K the hand law and the NMPC plan with on a robot's averaged model; a policy carries its own.
    """
    if scaling is None:
        return None
    if controller not in ("hand", "nmpc"):
        return "--scaling is the K the hand law and the NMPC plan with: it needs --controller hand or nmpc"
    if not Path(scaling).is_file():
        return f"--scaling: no coefficients file at {scaling!r} (pectoral-scaling identify writes one)"
    return None


def make_baseline(name: str, config: EnvConfig, **kwargs: Any):
    """Build a baseline controller for an environment.

    Args:
        name: ``"random"``, ``"hand"``, ``"nmpc"`` or ``"excite"`` (identification runs,
            :class:`pectoral_gym.agents.controllers.excitation.ExcitationController`).
        config: ``env.unwrapped.config`` of the environment it will drive.
        **kwargs: Passed to the controller (``RandomController(seed)``, :class:`HandController` gains,
            :class:`pectoral_gym.agents.nmpc.controller.NMPCController` settings, ``ExcitationController``'s).

    Returns:
        A :class:`pectoral_gym.agents.training.policy.Controller`.

    Raises:
        ValueError: For an unknown name or a config that is not an ``EnvConfig``.
    """
    if not isinstance(config, EnvConfig):
        raise ValueError(f"config must be an EnvConfig (env.unwrapped.config), got {type(config).__name__}")
    if name == "random":
        return RandomController(**kwargs)
    if name == "hand":
        return HandController(config, **kwargs)
    if name == "nmpc":
        from pectoral_gym.agents.nmpc.controller import NMPCController  # CasADi is imported only when NMPC is asked for

        return NMPCController(config, **kwargs)
    if name == "excite":
        from pectoral_gym.agents.controllers.excitation import ExcitationController

        return ExcitationController(config, **kwargs)
    raise ValueError(f"unknown baseline {name!r}; choose one of {BASELINES}")
