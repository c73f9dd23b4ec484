"""model.threads: numba's threads started with passive waiting, the environment left as it was."""

import os
import subprocess
import sys

import numpy as np
import pytest

from pectoral_gym.model import threads


@pytest.fixture
def fresh(monkeypatch):
    """A process whose threading layer has not started yet (as seen by threads), with no user setting."""
    monkeypatch.setattr(threads, "threads_started", lambda: False)
    for name in threads._USER_SETTINGS:
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_the_policy_is_set_for_the_start_only(fresh):
    seen = []
    fresh.setattr(threads, "_START", lambda x: seen.append(os.environ.get("OMP_WAIT_POLICY")))
    threads.start_passive_threads()
    assert seen == ["PASSIVE"]
    assert "OMP_WAIT_POLICY" not in os.environ


def test_the_environment_is_restored_when_the_start_fails(fresh):
    def fail(x):
        raise RuntimeError("no threads")

    fresh.setattr(threads, "_START", fail)
    with pytest.raises(RuntimeError):
        threads.start_passive_threads()
    assert "OMP_WAIT_POLICY" not in os.environ


@pytest.mark.parametrize("name, value", [("OMP_WAIT_POLICY", "ACTIVE"), ("GOMP_SPINCOUNT", "100000")])
def test_a_user_setting_wins(fresh, name, value):
    fresh.setenv(name, value)
    seen = []
    fresh.setattr(threads, "_START", seen.append)
    threads.start_passive_threads()
    assert seen == []
    assert os.environ[name] == value
    assert "OMP_WAIT_POLICY" not in os.environ or name == "OMP_WAIT_POLICY"


def test_started_threads_are_left_alone(monkeypatch):
    monkeypatch.setattr(threads, "threads_started", lambda: True)
    seen = []
    monkeypatch.setattr(threads, "_START", seen.append)
    threads.start_passive_threads()
    assert seen == []


def test_a_fresh_process_starts_its_threads_and_keeps_its_environment():
    code = ("import os; from pectoral_gym.model import threads; "
            "assert not threads.threads_started(); threads.start_passive_threads(); "
            "assert threads.threads_started(); assert 'OMP_WAIT_POLICY' not in os.environ; print('ok')")
    env = {k: v for k, v in os.environ.items() if k not in threads._USER_SETTINGS}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


@pytest.mark.parametrize("n, started", [(1, False), (64, True)])
def test_the_parallel_env_step_starts_passive_threads(monkeypatch, n, started):
    from pectoral_gym.envs import fused
    from pectoral_gym.envs.core import EnvConfig, EnvCore

    calls = []
    monkeypatch.setattr(fused, "start_passive_threads", lambda: calls.append(1))
    core = EnvCore(n, EnvConfig(model="averaged"))
    core.reset(range(n), [np.random.default_rng(i) for i in range(n)])
    core.step(np.zeros((n, 8)))
    assert bool(calls) == started
