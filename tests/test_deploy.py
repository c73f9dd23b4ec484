"""End-to-end dry run: ``pectoral_gym.hardware.deploy --emulate`` with a PPO policy trained for a few steps.

Also the deploy's arguments (one-line errors), its priority and the resources it releases; the settings it gives a
controller: ``tests/test_deploy_settings.py``.
"""

import json
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.hardware.deploy import main, plot_trajectories, run_episodes
from pectoral_gym.hardware.emulator import EmulatedRobot
from pectoral_gym.hardware.env import HardwareFishEnv
from pectoral_gym.hardware.safety.rules import SafetyConfig

pytestmark = pytest.mark.usefixtures("warm_emulator_rig")  # no numba compile inside a timed loop


@pytest.fixture(scope="module")
def policy_zip(tmp_path_factory):
    from stable_baselines3 import PPO

    env = gym.make("PectoralFish-Averaged-v0")
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=32)
    path = tmp_path_factory.mktemp("policy") / "ppo.zip"
    model.save(path)
    env.close()
    return path


@pytest.mark.slow  # ~15 s: torch import and a short PPO run
def test_deploy_emulate_end_to_end(policy_zip, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["--policy", str(policy_zip), "--emulate", "--speed", "2", "--episodes", "2",
                 "--max-episode-steps", "3", "--out", str(out), "--no-progress", "--tracking-timeout", "1.5"])
    assert code == 0
    lines = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    steps = [r for r in lines if r.get("event") != "reset"]
    assert [r["episode"] for r in lines if r.get("event") == "reset"] == [0, 1]
    assert 2 <= len(steps) <= 6 and all(len(r["command"]) == 2 and len(r["estimate"]) == 6 for r in steps)
    assert all("true_pose" in r and r["link"]["sent"] > 0 for r in steps)
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["episodes"]) == 2
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert "episode 1:" in capsys.readouterr().out


def test_deploy_runs_a_policy_that_observes_the_fins_on_the_fin_replay(tmp_path):
    from stable_baselines3 import PPO

    env = gym.make("PectoralFish-Averaged-v0", observe_fins=True)  # 27 entries: the robot env replays the fins
    path = tmp_path / "fins.zip"
    PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu").save(path)
    out = tmp_path / "run"
    code = main(["--policy", str(path), "--emulate", "--speed", "2", "--episodes", "1", "--max-episode-steps", "3",
                 "--out", str(out), "--no-progress", "--tracking-timeout", "1.5"])
    assert code == 0
    steps = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    assert len([r for r in steps if r.get("event") != "reset"]) >= 1


def test_deploy_needs_port_and_camera_without_emulate(tmp_path):
    with pytest.raises(SystemExit):
        main(["--policy", str(tmp_path / "none.zip"), "--out", str(tmp_path)])


class _Forward:
    """A fixed controller (no torch): both fins row forward."""

    name = "forward"

    def reset(self, seed=None):
        pass

    def act(self, obs):
        return np.array([0.5, 0.5, 0.0, 0.5] * 2, dtype=np.float32)


def test_run_episodes_and_plot_on_the_emulator_fast(tmp_path):
    robot = EmulatedRobot(speed=2.0, seed=0, start_pose=(1.0, 0.575, 0.0)).start()
    # 3 s without a sighting before tracking_lost: a slow camera on a loaded machine must not stop the
    # fish before it rows (a loaded run once ended with the fish where it started).
    # 6 steps (3 s of emulated time): a fresh clone's first steps compile numba kernels, and with 3 steps a
    # CI run once ended before the fins had rowed (x 1.0 - 4e-7).
    env = HardwareFishEnv(robot.url, robot.camera(seed=0), speed=2.0, max_episode_steps=6,
                          safety=SafetyConfig(tracking_timeout=3.0))
    try:
        summaries = run_episodes(env, _Forward(), 1, tmp_path / "steps.jsonl", seed=0, robot=robot, progress=False)
    finally:
        env.close()
        robot.stop()
    assert summaries[0]["steps"] == 6 and summaries[0]["truncated"]
    lines = [json.loads(line) for line in (tmp_path / "steps.jsonl").read_text().splitlines()]
    assert len(lines) == 7 and lines[-1]["true_pose"][0] > 1.0  # rowed forward along +X
    plot_trajectories(tmp_path / "steps.jsonl", tmp_path / "trajectory.png")
    assert (tmp_path / "trajectory.png").stat().st_size > 10_000


@pytest.mark.parametrize(("episodes", "legend"), [(3, True), (10, True), (11, False)])
def test_plot_names_up_to_ten_episodes_in_a_legend(tmp_path, monkeypatch, episodes, legend):
    from matplotlib.figure import Figure

    seen = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: seen.append(fig.axes[0]))
    rows = [{"episode": k, "pose": [0.5 + 0.01 * i, 0.5, 0.0], "estimate": [0.5 + 0.01 * i, 0.5, 0.0],
             "target": [1.5, 0.6]} for k in range(episodes) for i in range(3)]
    (tmp_path / "steps.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    plot_trajectories(tmp_path / "steps.jsonl", tmp_path / "trajectory.png")
    (ax,) = seen
    assert (ax.get_legend() is not None) == legend
    assert (f"{episodes} episodes" in ax.get_title()) == (not legend)
    assert len(ax.lines) == 3 * episodes  # every episode drawn: estimate, start, targets

def _deploy(tmp_path, *extra):
    out = tmp_path / "run"
    code = main(["--emulate", "--speed", "2", "--episodes", "1", "--max-episode-steps", "4", "--out", str(out),
                 "--no-progress", "--tracking-timeout", "1.5", *extra])
    assert code == 0
    steps = [json.loads(line) for line in (out / "steps.jsonl").read_text().splitlines()]
    return [r for r in steps if r.get("event") != "reset"], json.loads((out / "summary.json").read_text())


def test_deploy_nmpc_on_the_emulator(tmp_path):
    """``--controller nmpc`` drives the emulated robot: one solve per step, recorded in the summary."""
    steps, summary = _deploy(tmp_path, "--controller", "nmpc")
    assert summary["controller"] == "nmpc" and summary["policy"] is None
    solver = summary["solver"]
    assert solver["solves"] == len(steps) >= 1 and solver["failures"] >= solver["late"] >= 0
    assert all(len(r["command"]) == 2 for r in steps)


def test_deploy_nmpc_sends_the_safe_fallback_when_every_solve_is_late(tmp_path):
    """A solve that ends after its share of the control period is not applied: the fins rest (no plan yet)."""
    steps, summary = _deploy(tmp_path, "--controller", "nmpc", "--solve-fraction", "1e-9")
    assert summary["solver"]["late"] == summary["solver"]["solves"] == len(steps) >= 1
    lowest = EnvConfig(model="full").amplitude_range[0]
    amplitudes = [beat[1] for r in steps for beat in r["command"]]  # command rows: bias, amplitude, period, ratio
    np.testing.assert_allclose(amplitudes, lowest, atol=1e-9)


def test_deploy_controller_and_policy_arguments_must_agree(tmp_path):
    with pytest.raises(SystemExit):
        main(["--controller", "nmpc", "--policy", str(tmp_path / "p.zip"), "--emulate", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        main(["--emulate", "--out", str(tmp_path)])  # --controller policy needs --policy


# ---------------------------------------------------------------- arguments, policy fit, resources
@pytest.fixture(autouse=True)
def _keep_the_test_process_priority(monkeypatch):
    """The deploy raises its own priority; here that would be the test worker's (its effect: a test of its own)."""
    asked = []
    monkeypatch.setattr("pectoral_gym.hardware.library.raise_priority", lambda nice: asked.append(nice) or "")
    return asked


def test_raise_priority_sets_the_nice_value_of_threads_started_after_it():
    code = ("import json, os, threading\n"
            "from pectoral_gym.hardware.deploy_checks import raise_priority\n"
            "start = os.getpriority(os.PRIO_PROCESS, 0)\n"
            "warning = raise_priority(-1)\n"
            "seen = []\n"
            "t = threading.Thread(target=lambda: seen.append(os.getpriority(os.PRIO_PROCESS, 0)))\n"
            "t.start(); t.join()\n"
            "print(json.dumps([start, warning, os.getpriority(os.PRIO_PROCESS, 0), seen[0], raise_priority(0)]))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    start, warning, main_nice, thread_nice, zero = json.loads(run.stdout)
    if start <= -1:  # already there: nothing to do
        assert not warning and main_nice == thread_nice == start
    elif not warning:  # allowed (root, or a nice limit): the thread started afterwards inherits it
        assert main_nice == thread_nice == -1
    else:  # not allowed: a warning naming the remedy, priority unchanged
        assert "limits.conf" in warning and main_nice == thread_nice == start
    assert zero == ""


def test_the_deploy_asks_for_its_priority_before_anything_runs(tmp_path, _keep_the_test_process_priority):
    assert main(["--controller", "hand", "--emulate", "--speed", "2", "--episodes", "1", "--max-episode-steps", "1",
                 "--no-progress", "--nice", "-3", "--out", str(tmp_path)]) == 0
    assert _keep_the_test_process_priority == [-3]


def test_a_lockstep_deploy_leaves_its_priority_alone(tmp_path, _keep_the_test_process_priority):
    # simulated time: no priority can change a result, and raising it would only starve the machine's other work
    import threading

    done = []
    # a lockstep clock takes its thread in: not pytest's
    thread = threading.Thread(target=lambda: done.append(main(
        ["--controller", "hand", "--emulate", "--lockstep", "--episodes", "1", "--max-episode-steps", "1",
         "--no-progress", "--nice", "-3", "--out", str(tmp_path)])))
    thread.start()
    thread.join(timeout=120)
    assert done == [0] and _keep_the_test_process_priority == []


def test_nice_zero_keeps_a_lower_priority_the_caller_chose():
    # nice 5 or lower, whatever priority this process has (an in-process deploy test may have raised it)
    code = ("import os\n"
            "from pectoral_gym.hardware.deploy_checks import raise_priority\n"
            "os.setpriority(os.PRIO_PROCESS, 0, max(5, os.getpriority(os.PRIO_PROCESS, 0)))\n"
            "before = os.getpriority(os.PRIO_PROCESS, 0)\n"
            "print(before, raise_priority(0) == '', os.getpriority(os.PRIO_PROCESS, 0))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    before, quiet, after = run.stdout.split()
    assert quiet == "True" and after == before and int(before) >= 5


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


@pytest.mark.parametrize(("args", "message"), [
    (["--tracking-timeout", "0"], "--tracking-timeout must be"),
    (["--tracking-timeout", "-1"], "--tracking-timeout must be"),
    (["--tracking-timeout", "nan"], "--tracking-timeout must be"),
    (["--speed", "1e-9"], "--speed must be in [0.1, 5.0]"),
    (["--speed", "50"], "--speed must be in [0.1, 5.0]"),
    (["--speed", "5", "--tracking-timeout", "0.4"], "--tracking-timeout must be"),  # 0.08 s of wall time
    (["--episodes", "0"], "--episodes must be >= 1"),
    (["--max-episode-steps", "0"], "--max-episode-steps must be >= 1"),
    (["--seed", "-1"], "--seed must be >= 0"),
    (["--control-period", "0.01"], "--control-period must be in [0.1, 2.0]"),
    (["--control-period", "30"], "--control-period must be in [0.1, 2.0]"),
    (["--geofence", "-0.1"], "--geofence: StopRule.margin must be a finite number >= 0"),
    (["--geofence", "nan"], "--geofence: StopRule.margin must be a finite number >= 0"),
    (["--nice", "5"], "--nice must be in [-20, 0]"),
    (["--port", "socket://127.0.0.1:1"], "cannot be used with --emulate"),
    (["--robot-address", "0013A20012345678"], "cannot be used with --emulate"),
    (["--calibration", "{tmp}/missing.json"], "--calibration: cannot load"),
    (["--calibration", "{tmp}/broken.json"], "not a camera calibration"),
])
def test_bad_arguments_are_one_line_errors_with_status_2(tmp_path, capsys, args, message):
    (tmp_path / "broken.json").write_text("{not json")
    argv = ["--controller", "hand", "--emulate", "--no-progress", "--out", str(tmp_path / "run")]
    with pytest.raises(SystemExit) as exit_info:
        main(argv + [a.replace("{tmp}", str(tmp_path)) for a in args])
    assert exit_info.value.code == 2
    line = _error_line(capsys)
    assert line.startswith("pectoral-deploy: error:") and message in line


@pytest.mark.parametrize("address", ["-1", "12345", "1FFFFFFFFFFFFFFFF", "0013A2001234567G", "0x-13A20012345678"])
def test_robot_address_must_be_16_hex_digits(tmp_path, capsys, address):
    with pytest.raises(SystemExit) as exit_info:
        main(["--controller", "hand", "--port", "/dev/null", "--camera", "0", "--robot-address", address,
              "--out", str(tmp_path)])
    assert exit_info.value.code == 2 and "16 hex digits" in _error_line(capsys)


def test_help_shows_examples_and_defaults(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    text = capsys.readouterr().out
    assert exit_info.value.code == 0 and "examples:" in text and "--take-over" in text and "exit status" in text
    assert "default 240" in text and "default 0.5" in text and "default deploy_out" in text


def _alive() -> tuple[set, set]:
    """Threads alive and socket descriptors open in this process."""
    import os
    import threading

    sockets = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            if os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                sockets.add(fd)
        except OSError:
            pass
    return {t for t in threading.enumerate() if t.is_alive()}, sockets


def _nothing_left(before) -> None:
    import time

    deadline = time.monotonic() + 3.0
    while True:
        threads, sockets = _alive()
        extra_threads, extra_sockets = threads - before[0], sockets - before[1]
        if not extra_threads and not extra_sockets or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert not extra_threads, f"threads left behind: {[t.name for t in extra_threads]}"
    assert not extra_sockets, f"sockets left behind: {sorted(extra_sockets)}"


def test_calibration_for_another_image_size_is_refused_before_the_first_episode(tmp_path, capsys):
    """The emulated camera gives 640x360 frames; a 1280x720 calibration is a one-line error, nothing left open."""
    calibration = tmp_path / "cal720.json"
    calibration.write_text(json.dumps({"width": 1280, "height": 720,
                                       "homography": [[500, 0, 80], [0, -500, 640], [0, 0, 1]]}))
    before = _alive()
    with pytest.raises(SystemExit) as exit_info:
        main(["--controller", "hand", "--emulate", "--no-progress", "--calibration", str(calibration),
              "--out", str(tmp_path / "run")])
    assert exit_info.value.code == 2
    line = _error_line(capsys)
    assert "640x360" in line and "1280x720" in line and str(calibration) in line
    assert not (tmp_path / "run" / "steps.jsonl").exists()  # refused before the first episode
    _nothing_left(before)


def test_a_failing_env_or_reset_is_exit_1_with_everything_released(tmp_path, capsys, monkeypatch):
    """RuntimeError while building the env (or at reset: "no fish seen") -> one line, exit 1, no thread/socket left."""
    import pectoral_gym.hardware.env

    before = _alive()
    real = pectoral_gym.hardware.env.HardwareFishEnv

    def no_fish(self, *, seed=None, options=None):
        raise RuntimeError("no fish seen for 5.0 s at reset (tracker: no frames); check the camera and the markers")

    monkeypatch.setattr(real, "reset", no_fish)
    assert main(["--controller", "hand", "--emulate", "--no-progress", "--out", str(tmp_path / "a")]) == 1
    assert "error: no fish seen" in _error_line(capsys)
    _nothing_left(before)

    class Broken:
        def __init__(self, *args, **kwargs):
            raise RuntimeError("supervisor could not start")

    monkeypatch.setattr(pectoral_gym.hardware.env, "HardwareFishEnv", Broken)
    assert main(["--controller", "hand", "--emulate", "--no-progress", "--out", str(tmp_path / "b")]) == 1
    assert _error_line(capsys) == "pectoral-deploy: error: supervisor could not start"
    _nothing_left(before)


def test_take_over_is_passed_to_the_env_or_refused_clearly(tmp_path, capsys, monkeypatch):
    import inspect

    import pectoral_gym.hardware.env

    if "take_over" not in inspect.signature(pectoral_gym.hardware.env.HardwareFishEnv).parameters:
        with pytest.raises(SystemExit) as exit_info:
            main(["--controller", "hand", "--emulate", "--no-progress", "--take-over", "--out", str(tmp_path)])
        assert exit_info.value.code == 2 and "no take_over option" in _error_line(capsys)
    seen = {}

    class Recorder:
        def __init__(self, port, camera, take_over=False, **kwargs):
            seen["take_over"] = take_over
            raise RuntimeError("recorded")

    monkeypatch.setattr(pectoral_gym.hardware.env, "HardwareFishEnv", Recorder)
    assert main(["--controller", "hand", "--emulate", "--no-progress", "--take-over", "--out", str(tmp_path)]) == 1
    assert seen == {"take_over": True}


def test_a_failed_start_exits_normally_in_a_fresh_process(tmp_path):
    """No SIGABRT, no traceback: the process ends with status 2 and the one-line reason."""
    import subprocess
    import sys

    calibration = tmp_path / "cal.json"
    calibration.write_text(json.dumps({"width": 320, "height": 180, "homography": [[100, 0, 10], [0, -100, 170],
                                                                                     [0, 0, 1]]}))
    done = subprocess.run([sys.executable, "-m", "pectoral_gym.hardware.deploy", "--controller", "hand", "--emulate",
                           "--no-progress", "--calibration", str(calibration), "--out", str(tmp_path / "run")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and "320x180" in done.stderr.strip().splitlines()[-1]


def test_a_goal_policy_is_refused_under_track_and_bad_statistics_are_named(policy_zip, tmp_path, capsys):
    import pickle
    import shutil

    from pectoral_gym.agents.training.policy import load_policy

    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(policy_zip, run / "model.zip")
    (run / "config.yaml").write_text("algo: ppo\nenv_kwargs:\n  task: goal\n")
    assert load_policy(run).trained["task"] == "goal"
    with pytest.raises(SystemExit) as exit_info:
        main(["--policy", str(run), "--emulate", "--task", "track", "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2 and "trained with task 'goal'" in _error_line(capsys)
    (run / "vecnormalize.pkl").write_bytes(b"\x80\x04 truncated")
    with pytest.raises(ValueError, match="vecnormalize.pkl: not a readable VecNormalize pickle"):
        load_policy(run)
    with pytest.raises(SystemExit) as exit_info:
        main(["--policy", str(run), "--emulate", "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2 and "vecnormalize.pkl" in _error_line(capsys)

    from types import SimpleNamespace

    # the statistics of another run: 27 observation entries for a 19-entry model
    other = SimpleNamespace(norm_obs=True, clip_obs=10.0, epsilon=1e-8,
                            obs_rms=SimpleNamespace(mean=np.zeros(27), var=np.ones(27)))
    (run / "vecnormalize.pkl").write_bytes(pickle.dumps(other))
    with pytest.raises(ValueError, match="size 27.*another run"):
        load_policy(run)
