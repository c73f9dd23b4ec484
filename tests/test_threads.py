"""model.threads: numba's threads started with passive waiting, the environment left as it was."""

import os
import subprocess
import sys
import textwrap

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
    seen = []  # the wait policy in force when the layer starts: the user's, never ours
    fresh.setattr(threads, "_START", lambda x: seen.append(os.environ.get("OMP_WAIT_POLICY")))
    threads.start_passive_threads()
    assert seen == [value if name == "OMP_WAIT_POLICY" else None]  # started all the same (pin_torch_threads)
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


def test_training_keeps_the_torch_thread_count_it_was_given(tmp_path):
    # numba's threads started mid-training used to reset torch's count to one per core: 1 thread when PPO.learn
    # began, 2 on a 2-core machine after its first env step. A fresh process, so no earlier test started them.
    script = tmp_path / "train_threads.py"
    script.write_text(textwrap.dedent(f"""
        import torch
        from stable_baselines3 import PPO

        learn = PPO.learn

        def learn_and_report(self, *args, **kwargs):
            result = learn(self, *args, **kwargs)
            print("torch threads after learn:", torch.get_num_threads())
            return result

        PPO.learn = learn_and_report
        from pectoral_gym.agents.training import train

        train.main(["--quick", "--env", "PectoralFish-Averaged-v2", "--out", {str(tmp_path / "runs")!r},
                    "--torch-threads", "1", "--no-progress"])
    """))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "MPLBACKEND": "Agg"})
    assert run.returncode == 0, run.stderr[-2000:]
    assert "torch threads after learn: 1" in run.stdout, run.stdout[-2000:]
