"""How far a cubic Hermite curve between a period's end states is from the model's pose at frame instants.

The study behind ``pectoral_gym.envs.sensed``'s choice (docs/notes/2026-12-03-sensing-randomisation.md): 16 fish,
60 control periods of 0.5 s with random actions, the model advanced in pieces of 1/30 s; at each of the 14 interior
frame instants of a period, the pose of the Hermite curve through the period's end states of that same run
(poses and world-frame rates) against the model's pose. Usage::

    python docs/validation/sensing/hermite_error.py PectoralFish-Averaged-v1
"""

from __future__ import annotations

import math
import sys

import numpy as np

from pectoral_gym.envs.config import EnvConfig
from pectoral_gym.registration import registered_settings


def hermite_pose(a: np.ndarray, b: np.ndarray, h: float, s: float) -> tuple[float, float, float]:
    """Pose at fraction ``s`` of a period ``h`` [s] from state ``a`` to ``b`` (X, Y, psi, vx, vy, omega)."""
    h00, h10 = (1 + 2 * s) * (1 - s) ** 2, s * (1 - s) ** 2
    h01, h11 = s * s * (3 - 2 * s), s * s * (s - 1)

    def rates(state):
        c, si = math.cos(state[2]), math.sin(state[2])
        return c * state[3] - si * state[4], si * state[3] + c * state[4], state[5]

    ra, rb = rates(a), rates(b)
    return tuple(h00 * a[k] + h10 * h * ra[k] + h01 * b[k] + h11 * h * rb[k] for k in range(3))


def main(env_id: str, n: int = 16, periods: int = 60, pieces: int = 15, period: float = 0.5) -> None:
    """Print the position [mm] and heading [deg] errors' maximum, rms and 99th percentile on ``env_id``'s model."""
    config = EnvConfig(**registered_settings(env_id))
    model = config.model_spec().build(n, config.params)
    rng = np.random.default_rng(1)
    start = np.zeros((n, 6))
    start[:, 0], start[:, 1], start[:, 2] = 1.15, 0.57, rng.uniform(-3, 3, n)
    model.reset(start)
    position, heading = [], []
    for _ in range(periods):
        model.command_array(config.decode(rng.uniform(-1, 1, (n, 2, 4))))
        a = model.state.copy()
        path = [model.advance(period / pieces).copy() for _ in range(pieces)]
        for k in range(1, pieces):
            for i in range(n):
                x, y, psi = hermite_pose(a[i], path[-1][i], period, k / pieces)
                position.append(math.hypot(x - path[k - 1][i, 0], y - path[k - 1][i, 1]))
                heading.append(math.degrees(abs(psi - path[k - 1][i, 2])))
        model.state[:, :2] = 1.15, 0.57  # back to the tank's centre: the fish never meets a wall
    for name, errors, unit, scale in (("position", position, "mm", 1e3), ("heading", heading, "deg", 1.0)):
        e = scale * np.asarray(errors)
        print(f"{env_id} {name}: max {e.max():.3g} {unit}, rms {np.sqrt(np.mean(e**2)):.3g} {unit}, "
              f"99th percentile {np.percentile(e, 99):.3g} {unit}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "PectoralFish-Averaged-v1")
