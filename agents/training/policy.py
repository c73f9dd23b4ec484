"""The controller protocol shared by trained policies and baselines, and :func:`load_policy`.

A controller maps one observation ``(19,)`` of a fish environment to one
normalised action ``(8,)`` in [-1, 1]. Trained Stable-Baselines3 policies and
the baseline controllers of :mod:`pectoral_gym.agents.baselines` both implement
:class:`Controller`, so :mod:`pectoral_gym.agents.training.evaluate`, the benchmark and
``pectoral_gym.hardware.deploy`` treat them alike.

A controller that is stateless across steps may also offer
``act_batch(obs (n, 19)) -> (n, 8)`` (:class:`BatchController`); the
evaluation then runs many episodes through one call per step.
"""

from __future__ import annotations

import json
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from pectoral_gym.agents.training.acting_load import load_for_acting
from pectoral_gym.envs.observation import OBS_SIZE

__all__ = ["ALGOS", "BatchController", "Controller", "SB3Controller", "TRAINED_KEYS", "algo_of_zip", "load_policy",
           "read_config"]

# The env settings a policy's actions and observations depend on, and where its episodes start and end, recorded
# from its run folder's config.yaml (its env id's settings with ``env_kwargs`` over them; EnvConfig's default where
# neither has a key) in SB3Controller.trained.
TRAINED_KEYS = ("task", "control_period", "observe_fins", "bias_range", "amplitude_range", "period_range",
                "ratio_range", "ref_speed", "start_inset", "goal_inset", "sensing", "timing")


@runtime_checkable
class Controller(Protocol):
    """A fish controller: one observation in, one normalised action out.

    Attributes:
        name: Short name for tables and plots (``"ppo"``, ``"hand"``, ``"nmpc"``, ...).
    """

    name: str

    def reset(self, seed: int | None = None) -> None:
        """Start of an episode (clear any internal state; reseed any randomness)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Observation ``(19,)`` float32 -> action ``(8,)`` float32 in [-1, 1]."""


@runtime_checkable
class BatchController(Controller, Protocol):
    """A controller without per-episode state that can act on a batch of observations."""

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Observations ``(n, 19)`` -> actions ``(n, 8)`` float32 in [-1, 1]."""


def _algos() -> dict[str, Any]:
    from stable_baselines3 import A2C, DDPG, PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C, "ddpg": DDPG}


ALGOS = ("ppo", "sac", "td3", "a2c", "ddpg")


class SB3Controller:
    """A trained Stable-Baselines3 model acting deterministically, with its observation normalisation.

    The action: SB3's deterministic action, ``model.predict(obs, deterministic=True)`` (for PPO's and A2C's
    Gaussian ``clip(mean, -1, 1)``; SAC's squashed mean; the actor of TD3 and DDPG). With ``expected_clip`` and
    a diagonal-Gaussian policy (PPO, A2C), instead the mean of the clipped Gaussian the policy samples in
    training, ``E[clip(a, -1, 1)]`` per action entry (:mod:`pectoral_gym.agents.training.deployed_action`; why it
    is not the default: docs/notes/2026-12-04-deployed-action.md).

    Args:
        model: The SB3 model (``BaseAlgorithm``).
        name: Controller name.
        obs_mean: Running mean of the observations (``VecNormalize.obs_rms.mean``), or ``None``.
        obs_var: Running variance of the observations, or ``None``.
        clip_obs: Clip normalised observations to ``[-clip_obs, clip_obs]``.
        epsilon: Added to the variance before the square root (as ``VecNormalize``).
        trained: The env settings it was trained with (:data:`TRAINED_KEYS`), ``{}`` when unknown.
        trained_from: The ``config.yaml`` ``trained`` was read from, or ``None``.
        expected_clip: Deploy ``E[clip(a, -1, 1)]`` where the policy is a diagonal Gaussian (see above).

    Attributes:
        obs_size: Observation entries the model takes (19, or 27 with ``observe_fins``).
        action_size: Action entries it returns (8 for the fish envs).
        trained: The env settings it was trained with, where its run folder records them (``{}`` otherwise).
        trained_from: The ``config.yaml`` they were read from, or ``None``.
        expected_clip: Whether it deploys ``E[clip(a, -1, 1)]``; off unless set (:func:`load_policy` leaves it
            off), and set after loading too. A policy that is not a diagonal Gaussian deploys SB3's action whatever
            it says.
    """

    def __init__(self, model: Any, name: str = "policy", obs_mean: np.ndarray | None = None,
                 obs_var: np.ndarray | None = None, clip_obs: float = 10.0, epsilon: float = 1e-8,
                 trained: dict[str, Any] | None = None, trained_from: str | Path | None = None,
                 expected_clip: bool = False):
        from pectoral_gym.agents.training.deployed_action import diag_gaussian_policy

        self.model = model
        self.name = name
        self.obs_mean = None if obs_mean is None else np.asarray(obs_mean, dtype=np.float64)
        self.obs_std = None if obs_var is None else np.sqrt(np.asarray(obs_var, dtype=np.float64) + epsilon)
        self.clip_obs = float(clip_obs)
        # 19 entries, or 27 for a policy trained with observe_fins=True (envs.observation)
        space = getattr(model, "observation_space", None)
        self.obs_size = int(space.shape[0]) if getattr(space, "shape", None) else OBS_SIZE
        actions = getattr(model, "action_space", None)
        self.action_size = int(np.prod(actions.shape)) if getattr(actions, "shape", None) else 8
        self.trained = dict(trained or {})
        self.trained_from = None if trained_from is None else Path(trained_from)
        self.expected_clip = bool(expected_clip) and diag_gaussian_policy(model)

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: the policy is deterministic and has no memory."""

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """Apply the training-time observation normalisation (identity if there was none)."""
        obs = np.asarray(obs, dtype=np.float64)
        if self.obs_mean is None:
            return obs.astype(np.float32)
        return np.clip((obs - self.obs_mean) / self.obs_std, -self.clip_obs, self.clip_obs).astype(np.float32)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Observations ``(n, obs_size)`` -> deterministic actions ``(n, 8)`` float32 in [-1, 1] (see the class)."""
        obs = np.asarray(obs)
        if obs.ndim != 2 or obs.shape[1] != self.obs_size:
            hint = " (a policy trained with observe_fins=True needs that env setting)" if self.obs_size > OBS_SIZE \
                else ""
            raise ValueError(f"observations must have shape (n, {self.obs_size}), got {obs.shape}{hint}")
        action = None
        if self.expected_clip:
            from pectoral_gym.agents.training.deployed_action import expected_clipped_action

            action = expected_clipped_action(self.model, self.normalize(obs))  # None: not a diagonal Gaussian
        if action is None:
            action, _ = self.model.predict(self.normalize(obs), deterministic=True)
        return np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Observation ``(obs_size,)`` -> deterministic action ``(8,)`` float32 in [-1, 1] (see the class)."""
        obs = np.asarray(obs)
        if obs.shape != (self.obs_size,):
            raise ValueError(f"observation must have shape ({self.obs_size},), got {obs.shape}")
        return self.act_batch(obs[None])[0]


def algo_of_zip(path: str | Path) -> str | None:
    """The algorithm (``"ppo"``, ``"sac"``, ...) that saved an SB3 ``.zip`` (from its attributes), or ``None``."""
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data").decode())
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None
    if "clip_range" in data:
        return "ppo"
    if "use_rms_prop" in data:
        return "a2c"
    if "target_entropy" in data:
        return "sac"
    if "policy_delay" in data:
        return "ddpg" if data.get("policy_delay") == 1 and data.get("target_policy_noise") == 0.0 else "td3"
    return None


def read_config(run_dir: str | Path) -> dict[str, Any]:
    """The resolved ``config.yaml`` of a run folder (empty dict if absent), the files it keeps as paths into it.

    Raises:
        ValueError: If the file is not YAML or not a mapping (naming the file).
    """
    import yaml

    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        return {}
    try:
        with open(path) as f:
            config = yaml.safe_load(f) or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        raise ValueError(f"{path}: cannot read the run config: {type(error).__name__}: {error}") from None
    if not isinstance(config, dict):
        raise ValueError(f"{path}: the run config must be a mapping, got {type(config).__name__}")
    from pectoral_gym.agents.training.run_files import resolve_run_files

    for section in ("env_kwargs", "eval_env_kwargs"):  # the robot's files the run keeps, as paths into it
        if isinstance(config.get(section), dict):
            config[section] = resolve_run_files(config[section], path.parent)
    return config


def _trained_settings(config: dict[str, Any], path: Path) -> dict[str, Any]:
    """:data:`TRAINED_KEYS` of a run config's env id and ``env_kwargs`` (EnvConfig's defaults where absent)."""
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.registration import ENV_SETTINGS, registered_settings

    env_kwargs = config.get("env_kwargs") or {}
    if not isinstance(env_kwargs, dict):
        raise ValueError(f"{path}: env_kwargs must be a mapping, got {env_kwargs!r}")
    if config.get("env_id") in ENV_SETTINGS:  # the id's own settings (v1's observe_fins, goal_inset, ...)
        env_kwargs = registered_settings(config["env_id"], env_kwargs)
    defaults = EnvConfig()
    return {key: env_kwargs.get(key, getattr(defaults, key)) for key in TRAINED_KEYS}


def _load_normalization(path: Path) -> dict[str, Any]:
    """Observation statistics (``obs_mean``, ``obs_var``, ``clip_obs``, ``epsilon``) of a pickled ``VecNormalize``.

    Raises:
        ValueError: If the file does not unpickle to observation statistics (naming the file and the fault).
    """
    try:
        with open(path, "rb") as f:
            vec_normalize = pickle.load(f)  # noqa: S301 - our own run folder
    except Exception as error:  # noqa: BLE001 - any unpickling fault (truncated, other class, other version)
        raise ValueError(f"{path}: not a readable VecNormalize pickle ({type(error).__name__}: {error}); it is "
                         "corrupt or from another library version: restore it from the run's copy or retrain") from None
    if not getattr(vec_normalize, "norm_obs", True):
        return {}
    try:
        stats = {"obs_mean": np.asarray(vec_normalize.obs_rms.mean, dtype=np.float64),
                 "obs_var": np.asarray(vec_normalize.obs_rms.var, dtype=np.float64),
                 "clip_obs": float(vec_normalize.clip_obs), "epsilon": float(vec_normalize.epsilon)}
    except (AttributeError, TypeError, ValueError) as error:
        raise ValueError(f"{path}: not VecNormalize observation statistics ({type(error).__name__}: {error})") \
            from None
    mean, var = stats["obs_mean"], stats["obs_var"]
    if mean.ndim != 1 or mean.shape != var.shape or not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var))
                                                           and np.all(var >= 0)):
        raise ValueError(f"{path}: observation statistics must be finite 1-D arrays of one size with variances "
                         f">= 0, got mean {mean.shape}, var {var.shape}")
    stats["path"] = path
    return stats


def _check_normalization(normalization: dict[str, Any], model: Any, zip_path: Path) -> dict[str, Any]:
    """``normalization`` without its path, after checking that its size is the model's observation size."""
    stats = dict(normalization)
    path = stats.pop("path", None)
    space = getattr(model, "observation_space", None)
    if stats and getattr(space, "shape", None) and stats["obs_mean"].shape != tuple(space.shape):
        raise ValueError(f"{path}: observation statistics of size {stats['obs_mean'].shape[0]}, but {zip_path} "
                         f"takes observations of shape {tuple(space.shape)}: the file belongs to another run")
    return stats


def _zoo_params_dir(run_dir: Path) -> Path | None:
    """The ``<env>/`` folder of an rl-baselines3-zoo run folder (it holds ``config.yml``), or ``None``."""
    if (run_dir / "config.yaml").is_file():
        return None  # a pectoral_gym.agents.training.train run folder
    found = sorted(p.parent for p in run_dir.glob("*/config.yml"))
    return found[0] if len(found) == 1 else None


def _stats_beside(zip_path: Path) -> Path | None:
    """The ``VecNormalize`` pickle that goes with an SB3 zip, in our training's or rl-baselines3-zoo's layout.

    pectoral_gym.agents.training.train: ``vecnormalize_final.pkl`` with ``model.zip``, else ``vecnormalize.pkl`` beside
    the zip. rl-baselines3-zoo (``<log>/<algo>/<env>_<n>/``): ``<env>/vecnormalize.pkl`` (saved on every new best and
    at the end, so it holds the final statistics; zoo's ``enjoy --load-best`` uses it with ``best_model.zip``
    too), and ``rl_model_vecnormalize_<N>_steps.pkl`` with a checkpoint ``rl_model_<N>_steps.zip``.
    """
    parent = zip_path.parent
    if zip_path.name == "model.zip" and (parent / "vecnormalize_final.pkl").is_file():
        return parent / "vecnormalize_final.pkl"
    if (parent / "vecnormalize.pkl").is_file():
        return parent / "vecnormalize.pkl"
    match = re.fullmatch(r"rl_model_(\d+)_steps", zip_path.stem)
    if match and (parent / f"rl_model_vecnormalize_{match.group(1)}_steps.pkl").is_file():
        return parent / f"rl_model_vecnormalize_{match.group(1)}_steps.pkl"
    params_dir = parent / zip_path.stem if (parent / zip_path.stem / "vecnormalize.pkl").is_file() else (
        _zoo_params_dir(parent))
    if params_dir is not None and (params_dir / "vecnormalize.pkl").is_file():
        return params_dir / "vecnormalize.pkl"
    return None


def load_policy(path: str | Path, device: str = "cpu", algo: str | None = None) -> SB3Controller:
    """Load a trained policy as a deterministic :class:`Controller`.

    Args:
        path: A run folder of :mod:`pectoral_gym.agents.training.train` (``best_model.zip`` preferred over
            ``model.zip``; ``vecnormalize.pkl`` applied when present, ``vecnormalize_final.pkl`` with ``model.zip``;
            the algorithm read from ``config.yaml``), a run folder of rl-baselines3-zoo
            (``<log>/<algo>/<env>_<n>``: the final ``<env>.zip``, else ``best_model.zip``, with
            ``<env>/vecnormalize.pkl``, which holds the final statistics), or an SB3 ``.zip`` of either
            (the statistics found beside it as :func:`_stats_beside` says; the algorithm read from the
            zip, or ``algo``).
        device: Torch device.
        algo: Force the algorithm (``"ppo"``, ``"sac"``, ...).

    Returns:
        The controller (it also has ``act_batch``). Its ``model`` is loaded to act: the policy's optimizer is a
        stand-in that keeps the saved state (:func:`~pectoral_gym.agents.training.acting_load.load_for_acting`).

    Raises:
        FileNotFoundError: If ``path`` is neither a run folder with a model nor a ``.zip``.
        ValueError: If the algorithm is unknown or cannot be determined, or the run's ``config.yaml`` or
            ``vecnormalize*.pkl`` is corrupt or does not fit the model (the message names the file).
    """
    path = Path(path)
    normalization: dict[str, Any] = {}
    trained: dict[str, Any] = {}
    trained_from: Path | None = None
    name = path.stem
    zoo_dir = _zoo_params_dir(path) if path.is_dir() else None
    if zoo_dir is not None:
        zip_path = next((z for z in (path / f"{zoo_dir.name}.zip", path / "best_model.zip") if z.is_file()), None)
        if zip_path is None:
            raise FileNotFoundError(f"{path} looks like an rl-baselines3-zoo run folder ({zoo_dir.name}/config.yml) "
                                    f"but has neither {zoo_dir.name}.zip nor best_model.zip")
        if (zoo_dir / "vecnormalize.pkl").is_file():
            normalization = _load_normalization(zoo_dir / "vecnormalize.pkl")
    elif path.is_dir():
        config = read_config(path)
        zip_path = next((path / f for f in ("best_model.zip", "model.zip") if (path / f).is_file()), None)
        if zip_path is None:
            raise FileNotFoundError(f"{path} has neither best_model.zip nor model.zip; is it a run folder?")
        stats = path / "vecnormalize.pkl"
        if zip_path.name == "model.zip" and (path / "vecnormalize_final.pkl").is_file():
            stats = path / "vecnormalize_final.pkl"
        if stats.is_file():
            normalization = _load_normalization(stats)
        algo = algo or config.get("algo")
        name = str(config.get("algo", name))
        if config:
            trained, trained_from = _trained_settings(config, path / "config.yaml"), path / "config.yaml"
    elif path.is_file() and path.suffix == ".zip":
        zip_path = path
        stats_path = _stats_beside(path)
        if stats_path is not None:
            normalization = _load_normalization(stats_path)
        config = read_config(path.parent)  # a model of a pectoral_gym.agents.training.train run folder
        if config:
            trained, trained_from = _trained_settings(config, path.parent / "config.yaml"), path.parent / "config.yaml"
    else:
        raise FileNotFoundError(f"{path} is neither a run folder nor an SB3 .zip file")
    algo = (algo or algo_of_zip(zip_path) or "").lower() or None
    classes = _algos()
    if algo is not None and algo not in classes:
        raise ValueError(f"unknown algorithm {algo!r}; known: {sorted(classes)}")
    candidates = [algo] if algo else list(classes)
    errors = []
    with open(zip_path, "rb") as f:
        raw = f.read()
    for candidate in candidates:
        try:
            model = load_for_acting(classes[candidate], raw, device)
        except Exception as error:  # noqa: BLE001 - try the next algorithm, report all failures below
            errors.append(f"{candidate}: {error}")
            continue
        return SB3Controller(model, name=name if path.is_dir() and zoo_dir is None else candidate,
                             trained=trained, trained_from=trained_from,
                             **_check_normalization(normalization, model, zip_path))
    raise ValueError(f"could not load {zip_path} with {candidates}: " + "; ".join(errors))
