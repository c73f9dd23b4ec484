"""Shared test helpers."""

import numpy as np
import pytest


@pytest.fixture
def rk4_symbolic():
    """Integrate a CasADi ``Function`` ``f(x) -> dx/dt`` with classical RK4: ``run(f, start, h, steps)``."""
    def run(f, start, h, steps):
        ca = pytest.importorskip("casadi")
        state = ca.DM(start)
        for _ in range(steps):
            k1 = f(state)
            k2 = f(state + h / 2 * k1)
            k3 = f(state + h / 2 * k2)
            k4 = f(state + h * k3)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return np.array(state).ravel()

    return run
