"""The recipes of docs/guide/trainers.md ("Other trainers"), run as they are written (sizes shrunk by their constants).

Each test runs one snippet in a fresh interpreter (so the thread settings and numba's thread pool start as in a
user's script) and skips when the snippet's library is not installed: skrl, TorchRL and Minari come with the
``clients`` extra, Stable-Baselines3 with ``rl``, moviepy with ``dev``; Tianshou with none (see the page).
TorchRL, RLlib and rl-baselines3-zoo run in tests/test_trainer_snippets.py and tests/test_config_zoo.py.
"""

import importlib.util
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from doc_snippets import ROOT, commands, snippet, with_constants

import pectoral_gym  # noqa: F401  (registers the ids)

ENV = "PectoralFish-Averaged-v2"


def _has(*modules):
    try:
        return all(importlib.util.find_spec(module) is not None for module in modules)
    except ModuleNotFoundError:
        return False


def _env():
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}


def run_python(code, cwd, *args, env=None):
    done = subprocess.run([sys.executable, "-c", code, *args], cwd=cwd, env=env or _env(), capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    return done.stdout


def run_command(line, cwd, *extra):
    """A command of a bash block, its console script taken from this interpreter's environment."""
    argv = shlex.split(line)
    assert argv[0].startswith("pectoral-"), line
    script = Path(sys.executable).parent / argv[0]
    done = subprocess.run([str(script), *argv[1:], *extra], cwd=cwd, env=_env(), capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    return done.stdout


def test_threads_snippet_keeps_one_torch_thread(tmp_path):
    pytest.importorskip("torch")
    out = run_python(snippet("threads"), tmp_path)
    assert "torch threads: 1" in out  # after the env's first step, which starts numba's thread pool


@pytest.mark.skipif(not _has("torch", "stable_baselines3"), reason="needs the rl extra")
def test_threads_bench_snippet_runs(tmp_path):
    out = run_python(with_constants(snippet("threads-bench"), WARM_UP=64, STEPS=64), tmp_path, "1")
    assert re.search(r"torch threads 1: model.learn\(64\) [\d.]+ s", out), out


def _canonical_train_flags():
    """Whether pectoral-train takes the page's spellings, ``--out`` and ``--timesteps``."""
    done = subprocess.run([str(Path(sys.executable).parent / "pectoral-train"), "--help"], env=_env(),
                          capture_output=True, text=True)
    return done.returncode == 0 and {"--out", "--timesteps"} <= set(re.findall(r"--[a-z-]+", done.stdout))


@pytest.mark.skipif(not _has("torch", "stable_baselines3"), reason="needs the rl extra")
def test_pectoral_train_snippet_trains_and_evaluates(tmp_path):
    if not _canonical_train_flags():
        pytest.skip("pectoral-train does not take --out/--timesteps yet (the CLI-consistency change)")
    train_line, evaluate_line = commands(snippet("pectoral-train"))
    run_command(train_line, tmp_path, "--quick", "--no-progress")
    assert (tmp_path / "runs" / ENV / "ppo_seed0" / "config.yaml").is_file()  # <out>/<env>/<run name>
    run_command(evaluate_line, tmp_path, "--episodes", "2", "--out", str(tmp_path / "eval"))
    assert (tmp_path / "eval" / "metrics.json").is_file()


@pytest.mark.skipif(not _has("torch", "stable_baselines3"), reason="needs the rl extra")
def test_sb3_snippet_trains_and_pectoral_evaluate_reads_it(tmp_path):
    run_python(with_constants(snippet("sb3"), N_ENVS=2, N_STEPS=64, TIMESTEPS=128), tmp_path)
    assert (tmp_path / "sb3_ppo" / "model.zip").is_file() and (tmp_path / "sb3_ppo" / "vecnormalize.pkl").is_file()
    (evaluate_line,) = commands(snippet("sb3-evaluate"))
    run_command(evaluate_line, tmp_path, "--episodes", "2", "--out", str(tmp_path / "eval"))
    assert (tmp_path / "eval" / "metrics.json").is_file()


def test_vector_snippet_gives_the_same_episodes_three_ways(tmp_path):
    out = run_python(with_constants(snippet("vector"), N_ENVS=2, STEPS=60), tmp_path)
    lines = dict(line.split(": ", 1) for line in out.splitlines() if line.split(":")[0] in ("native", "sync", "async"))
    assert set(lines) == {"native", "sync", "async"}, out
    assert len(set(lines.values())) == 1, lines  # mode, episode count and mean return alike
    assert lines["native"].startswith("SameStep, ") and not lines["native"].startswith("SameStep, 0 episodes")


@pytest.mark.skipif(not _has("moviepy"), reason="RecordVideo needs moviepy (dev extra)")
def test_video_snippet_records_an_episode(tmp_path):
    run_python(with_constants(snippet("video"), EPISODES=1), tmp_path, env={**_env(), "SDL_VIDEODRIVER": "dummy"})
    assert list((tmp_path / "videos").glob("*.mp4"))


@pytest.mark.skipif(not _has("torch", "skrl"), reason="skrl not installed (clients extra)")
def test_skrl_snippet_trains(tmp_path):
    run_python(with_constants(snippet("skrl"), N_ENVS=2, ROLLOUT=16, TIMESTEPS=64), tmp_path)
    assert (tmp_path / "skrl_ppo.pt").is_file()
    assert list((tmp_path / "skrl_runs").glob("*_PPO"))  # the experiment folder (cfg.experiment.directory)


@pytest.mark.skipif(not _has("torch", "tianshou"), reason="Tianshou not installed (in no extra: it needs pandas<3)")
def test_tianshou_snippet_trains(tmp_path):
    code = with_constants(snippet("tianshou"), N_ENVS=2, EPOCHS=1, EPOCH_STEPS=128, COLLECT_STEPS=64,
                          TEST_EPISODES=2)
    out = run_python(code, tmp_path)
    assert re.search(r"best test reward -?[\d.]+", out), out
    assert (tmp_path / "tianshou_ppo.pt").is_file()


def _cleanrl():
    namespace = {}
    exec(snippet("cleanrl"), namespace)  # noqa: S102 - the page's code, as a user pastes it
    return namespace


def _rollout(envs, steps, seed=0):
    """CleanRL's rollout pattern with uniform random actions (its ClipAction makes the action space unbounded)."""
    rng = np.random.default_rng(seed)
    envs.reset(seed=seed)
    for _ in range(steps):
        yield envs.step(rng.uniform(-1.0, 1.0, size=(envs.num_envs, *envs.single_action_space.shape)))


def test_cleanrl_shims_report_every_episode_once():
    cleanrl = _cleanrl()
    envs = cleanrl["make_envs"](ENV, 2, False, "test", 0.99)
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    seen = [episode for *_, infos in _rollout(envs, 80) for episode in cleanrl["finished_episodes"](infos)]
    envs.close()
    reference = gym.wrappers.vector.RecordEpisodeStatistics(gym.make_vec(
        ENV, 2, vectorization_mode="sync", vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}))
    expected = []
    for *_, infos in _rollout(reference, 80):
        if "episode" in infos:
            ended = infos["_episode"]
            expected += zip(infos["episode"]["r"][ended], infos["episode"]["l"][ended], strict=True)
    reference.close()
    assert len(seen) == len(expected) >= 2
    np.testing.assert_allclose(np.array(seen, dtype=float), np.array(expected, dtype=float), rtol=1e-6)


def test_cleanrl_original_lines_fail_under_gymnasium_1():
    # the two lines the page says break: TransformObservation without the space, and final_info under NextStep
    env = gym.make(ENV)
    with pytest.raises(TypeError, match="observation_space"):
        gym.wrappers.TransformObservation(env, lambda obs: np.clip(obs, -10, 10))
    envs = gym.vector.SyncVectorEnv([_cleanrl()["make_env"](ENV, i, False, "test", 0.99) for i in range(2)])
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP  # Gymnasium 1.x's default
    ended = 0
    for _, _, terminated, truncated, infos in _rollout(envs, 80):
        ended += int(np.sum(terminated | truncated))
        assert "final_info" not in infos  # CleanRL's statistics loop never runs
    envs.close()
    assert ended >= 2
    envs = _cleanrl()["make_envs"](ENV, 2, False, "test", 0.99)
    infos = next(infos for *_, infos in _rollout(envs, 80) if "final_info" in infos)
    envs.close()
    with pytest.raises(TypeError):  # under SameStep, CleanRL's loop meets a dict of arrays
        for info in infos["final_info"]:
            if info and "episode" in info:
                info["episode"]["r"]


@pytest.mark.skipif(not _has("minari", "h5py", "jax"), reason="minari[create,hdf5] not installed (clients extra)")
def test_minari_snippet_records_a_dataset(tmp_path):
    out = run_python(with_constants(snippet("minari"), EPISODES=2), tmp_path,
                     env={**_env(), "MINARI_DATASETS_PATH": str(tmp_path / "datasets")})
    assert re.search(r"^2 episodes, \d+ steps$", out, re.M), out
    assert (tmp_path / "datasets" / "pectoral" / "full-random-v0").is_dir()


# The distributions behind the third-party imports of CleanRL's ppo_continuous_action.py (gymnasium, numpy, torch,
# tyro, torch.utils.tensorboard), read off its source.
CLEANRL_NEEDS = {"gymnasium", "numpy", "torch", "tyro", "tensorboard"}


def _requirement_names(requirements):
    return {re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower().replace("_", "-")
            for requirement in requirements}


def test_cleanrl_install_line_brings_what_its_script_imports():
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    brought = _requirement_names(project["dependencies"])
    for line in commands(snippet("cleanrl-install")):
        argv = shlex.split(line)
        assert argv[:2] == ["pip", "install"], line
        for item in argv[2:]:
            if item == "-e":
                continue
            match = re.fullmatch(r"\.\[([a-z,]+)\]", item)
            if match:
                for extra in match.group(1).split(","):
                    brought |= _requirement_names(r for r in extras[extra] if not r.startswith("pectoral-gym"))
            else:
                brought |= _requirement_names([item])
    assert CLEANRL_NEEDS <= brought, CLEANRL_NEEDS - brought


@pytest.mark.skipif(not _has("torch", "stable_baselines3"), reason="needs the rl extra")
def test_safe_rl_cost_snippet_reports_a_policys_cost(tmp_path):
    from stable_baselines3 import PPO

    PPO("MlpPolicy", gym.make(ENV), n_steps=64, batch_size=64, seed=0, device="cpu").save(tmp_path / "model.zip")
    out = run_python(with_constants(snippet("safe-rl-cost"), RUN=str(tmp_path / "model.zip"), EPISODES=3), tmp_path)
    match = re.search(r"^3 episodes: success ([\d.]+), stops in the band (\d), band cost per episode ([\d.]+) "
                      r"\(max ([\d.]+)\)$", out, re.M)
    assert match, out
    stops, mean_cost, max_cost = int(match.group(2)), float(match.group(3)), float(match.group(4))
    assert mean_cost <= max_cost and (stops == 0 or max_cost >= 1.0)  # a stop costs 1 on its last step alone


def test_fsrl_install_line_keeps_its_own_environment():
    lines = commands(snippet("fsrl-install"))
    assert lines[0] == "python -m venv .venv-fsrl" and all(line.startswith(".venv-fsrl/") for line in lines[1:])
    assert '"numpy<2"' in lines[-1] and "fast-safe-rl==0.1.0" in lines[-1]  # wandb 0.14 fails on numpy 2
    assert "torch==2.13.0" in lines[-1] and '"setuptools>=77,<81"' in lines[-1]  # pkg_resources, torch kept


@pytest.mark.skipif(not _has("fsrl", "tianshou"), reason="FSRL not installed (a venv of its own: see the page)")
def test_fsrl_snippet_trains(tmp_path):
    code = with_constants(snippet("fsrl"), N_ENVS=2, EPOCHS=1, STEPS_PER_EPOCH=256, TEST_EPISODES=2)
    out = run_python(code, tmp_path)
    assert re.search(r"^test: return -?[\d.]+, length [\d.]+, band cost per episode [\d.]+$", out, re.M), out[-2000:]
    assert (tmp_path / "fsrl_ppolag.pt").is_file()
