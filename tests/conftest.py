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


class _RowForward:
    """A fixed controller without torch: both fins row forward."""

    name = "forward"

    def reset(self, seed=None):
        pass

    def act(self, obs):
        return np.array([0.5, 0.5, 0.0, 0.5] * 2, dtype=np.float32)


@pytest.fixture(scope="session")
def warm_emulator_rig(tmp_path_factory):
    """Run one step of the emulated robot's whole pipeline once per test process, before any timed test.

    On a cold numba cache (a fresh clone) the first step compiles the emulator's, the env's and the observer's
    kernels; inside a timed test that stalls the control loop for seconds and the safety rules stop the fish
    (seen in CI: 2 of 6 steps, then a safety stop). Tests whose assertions depend on wall time use this fixture.
    """
    from pectoral_gym.hardware.deploy import run_episodes
    from pectoral_gym.hardware.emulator import EmulatedRobot
    from pectoral_gym.hardware.env import HardwareFishEnv

    robot = EmulatedRobot(speed=2.0, seed=1).start()
    env = HardwareFishEnv(robot.url, robot.camera(seed=1), speed=2.0, max_episode_steps=1)
    try:
        run_episodes(env, _RowForward(), 1, tmp_path_factory.mktemp("warmup") / "steps.jsonl", seed=1, robot=robot,
                     progress=False)
    finally:
        env.close()
        robot.stop()


@pytest.fixture
def default_signal_handlers():
    """Python's own SIGINT/SIGTERM handlers for the test's duration, whatever the process inherited.

    A process started in the background by a shell without job control inherits SIGINT ignored (POSIX), and
    Python then keeps it ignored: a test that checks what Ctrl-C does must not depend on how pytest was started.
    """
    import signal

    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)
