"""What the robot's sensing does to an observation, for the simulated envs and the robot stack alike.

``observer``: the high-gain observer of (X, Y, psi) as batched numba kernels (the robot's
:class:`pectoral_gym.hardware.vision.observer.HighGainObserver` is one row of them); ``camera``: the simulated
overhead camera's settings (:class:`SensingConfig`, ``EnvConfig.sensing``) and its frames within a control
period. The env's use of both is :mod:`pectoral_gym.envs.sensed`. Nothing here imports Gymnasium or the envs.
"""

from pectoral_gym.sensing.camera import SensingConfig

__all__ = ["SensingConfig"]
