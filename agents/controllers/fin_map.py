"""Fin commands in physical units -> the environment's normalised actions.

:class:`FinMap` serves the model-based controllers (the hand baseline, the
NMPC): they steer with the biases and amplitudes of both fins and keep the
period and ratio at their most effective values. It encodes through
:meth:`pectoral_gym.envs.core.EnvConfig.encode`, the inverse of the
environment's own action mapping.
"""

from __future__ import annotations

import math
import os

import numpy as np

from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.averaging import averaged_forcing, bessel_j1
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.spec import AVERAGED, AveragedSpec, env_spec

__all__ = ["FinMap", "planning_spec"]


def planning_spec(config: EnvConfig, scaling: str | os.PathLike | None = None) -> AveragedSpec:
    """The averaged model the model-based controllers plan on for an env of ``config``.

    The env's own spec (:meth:`EnvConfig.model_spec`) on the averaged model; on the full model
    :data:`pectoral_gym.model.spec.AVERAGED` (both corrections, the shipped K, which were identified
    against the full model), with the env's ``check_scaling_params``. ``scaling``, the path of a coefficients file
    (``pectoral-scaling identify --params FILE``), replaces the K (and the yaw damping it holds): the K of a robot
    whose ``config.params`` differ from Table 1's, which the shipped K were not identified for.

    Raises:
        ValueError: ``scaling`` is no coefficients file, or (with the check on) it was identified for other
            parameters than ``config.params`` (when the controller loads its K).
    """
    spec = config.model_spec()
    if not isinstance(spec, AveragedSpec):
        spec = AVERAGED.replace(check_params=config.check_scaling_params)
    if scaling is None:
        return spec
    held = env_spec("averaged", scaling=os.fspath(scaling), check_scaling_params=spec.check_params)
    return spec.replace(scaling=held.scaling, yaw_damping=held.yaw_damping)

_AMPLITUDE_TABLE = 201  # samples of the thrust-level -> amplitude table


class FinMap:
    """Physical fin commands -> normalised actions, with period and ratio fixed at their most effective values.

    Args:
        config: The environment settings (ranges, parameters).
        spec: The planning model (default: :func:`planning_spec`); its K, checked against ``config.params``.

    Attributes:
        period: Fixed fin-beat period: the shortest of ``period_range`` [s].
        ratio: Fixed speed ratio: the largest of ``ratio_range`` [-].
        amplitude_max: Largest amplitude of ``amplitude_range`` [rad].
        max_thrust: Averaged thrust of one fin at ``bias = 90 deg``, ``amplitude_max``, with the
            planning model's scaling functions [N] (0 if the ranges allow no thrust).
        max_speed: Straight-swimming steady speed with both fins at ``max_thrust`` [m/s].
    """

    def __init__(self, config: EnvConfig, spec: AveragedSpec | None = None):
        self.config = config
        self.spec = spec or planning_spec(config)
        self.period = float(config.period_range[0])
        self.ratio = float(config.ratio_range[1])
        self.amplitude_max = float(config.amplitude_range[1])
        self.amplitude_min = float(config.amplitude_range[0])
        bias_mid = float(np.clip(math.pi / 2, *config.bias_range))
        self.bias_mid = bias_mid
        # The identified K describe the full model too (that is what they were identified for).
        scaling: ScalingFunctions | None = self.spec.scaling_functions(config.params)
        self.scaling = scaling
        fx, _, _ = averaged_forcing(FinBeat(bias_mid, self.amplitude_max, self.period, self.ratio),
                                    config.params, scaling=scaling)
        self.max_thrust = max(float(fx), 0.0)
        self.max_speed = math.sqrt(2.0 * self.max_thrust / config.params.c1)  # drag balance c1 v^2 = 2 f (eq. 20)
        amplitudes = np.linspace(self.amplitude_min, self.amplitude_max, _AMPLITUDE_TABLE)
        shape = np.array([a * bessel_j1(a) for a in amplitudes])  # thrust ~ gA J1(gA) (eq. 25, exact average)
        self._levels = shape / shape[-1] if shape[-1] > 0 else np.linspace(0.0, 1.0, amplitudes.size)
        self._amplitudes = amplitudes

    def amplitude(self, level: float) -> float:
        """Amplitude [rad] whose thrust is ``level`` (0..1) of the largest thrust."""
        return float(np.interp(float(np.clip(level, 0.0, 1.0)), self._levels, self._amplitudes))

    def level_for_speed(self, speed: float) -> float:
        """Thrust level (both fins) whose straight steady speed is ``speed`` [m/s], clipped to [0, 1]."""
        if self.max_speed <= 0:
            return 0.0
        return float(np.clip(speed / self.max_speed, 0.0, 1.0) ** 2)  # drag ~ v^2

    def action(self, bias_right: float, amplitude_right: float, bias_left: float, amplitude_left: float) -> np.ndarray:
        """Normalised action ``(8,)`` float32 of the two fin patterns (period and ratio fixed)."""
        right = self.config.encode(np.array([bias_right, amplitude_right, self.period, self.ratio]))
        left = self.config.encode(np.array([bias_left, amplitude_left, self.period, self.ratio]))
        return np.concatenate([right, left]).astype(np.float32)
