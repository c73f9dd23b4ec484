"""The controller protocol shared by trained policies and baselines, and :func:`load_policy`.

A controller maps one observation ``(19,)`` of a fish environment to one
normalised action ``(8,)`` in [-1, 1]. Trained Stable-Baselines3 policies and
the baseline controllers of :mod:`agents.baselines` both implement
:class:`Controller`, so :mod:`agents.evaluate`, the benchmark and
``hardware.deploy`` treat them alike.

A controller that is stateless across steps may also offer
``act_batch(obs (n, 19)) -> (n, 8)`` (:class:`BatchController`); the
evaluation then runs many episodes through one call per step.
"""

from __future__ import annotations

import io
import json
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from pectoral_gym.envs.observation import OBS_SIZE

__all__ = ["ALGOS", "BatchController", "Controller", "SB3Controller", "algo_of_zip", "load_policy", "read_config"]


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

    Args:
        model: The SB3 model (``BaseAlgorithm``).
        name: Controller name.
        obs_mean: Running mean of the observations (``VecNormalize.obs_rms.mean``), or ``None``.
        obs_var: Running variance of the observations, or ``None``.
        clip_obs: Clip normalised observations to ``[-clip_obs, clip_obs]``.
        epsilon: Added to the variance before the square root (as ``VecNormalize``).
    """

    def __init__(self, model: Any, name: str = "policy", obs_mean: np.ndarray | None = None,
                 obs_var: np.ndarray | None = None, clip_obs: float = 10.0, epsilon: float = 1e-8):
        self.model = model
        self.name = name
        self.obs_mean = None if obs_mean is None else np.asarray(obs_mean, dtype=np.float64)
        self.obs_std = None if obs_var is None else np.sqrt(np.asarray(obs_var, dtype=np.float64) + epsilon)
        self.clip_obs = float(clip_obs)
        # 19 entries, or 27 for a policy trained with observe_fins=True (envs.observation)
        space = getattr(model, "observation_space", None)
        self.obs_size = int(space.shape[0]) if getattr(space, "shape", None) else OBS_SIZE

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: the policy is deterministic and has no memory."""

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """Apply the training-time observation normalisation (identity if there was none)."""
        obs = np.asarray(obs, dtype=np.float64)
        if self.obs_mean is None:
            return obs.astype(np.float32)
        return np.clip((obs - self.obs_mean) / self.obs_std, -self.clip_obs, self.clip_obs).astype(np.float32)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Observations ``(n, obs_size)`` -> deterministic actions ``(n, 8)`` float32 in [-1, 1]."""
        obs = np.asarray(obs)
        if obs.ndim != 2 or obs.shape[1] != self.obs_size:
            hint = " (a policy trained with observe_fins=True needs that env setting)" if self.obs_size > OBS_SIZE \
                else ""
            raise ValueError(f"observations must have shape (n, {self.obs_size}), got {obs.shape}{hint}")
        action, _ = self.model.predict(self.normalize(obs), deterministic=True)
        return np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Observation ``(obs_size,)`` -> deterministic action ``(8,)`` float32 in [-1, 1]."""
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
    """The resolved ``config.yaml`` of a run folder (empty dict if absent)."""
    import yaml

    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        return {}
    with open(path) as f:
        return yaml.safe_load(f) or {}


def _load_normalization(path: Path) -> dict[str, Any]:
    """Observation statistics (``obs_mean``, ``obs_var``, ``clip_obs``, ``epsilon``) of a pickled ``VecNormalize``."""
    with open(path, "rb") as f:
        vec_normalize = pickle.load(f)  # noqa: S301 - our own run folder
    if not getattr(vec_normalize, "norm_obs", True):
        return {}
    return {"obs_mean": vec_normalize.obs_rms.mean, "obs_var": vec_normalize.obs_rms.var,
            "clip_obs": vec_normalize.clip_obs, "epsilon": vec_normalize.epsilon}


def _zoo_params_dir(run_dir: Path) -> Path | None:
    """The ``<env>/`` folder of an rl-baselines3-zoo run folder (it holds ``config.yml``), or ``None``."""
    if (run_dir / "config.yaml").is_file():
        return None  # an agents.train run folder
    found = sorted(p.parent for p in run_dir.glob("*/config.yml"))
    return found[0] if len(found) == 1 else None


def _stats_beside(zip_path: Path) -> Path | None:
    """The ``VecNormalize`` pickle that goes with an SB3 zip, in agents.train's or rl-baselines3-zoo's layout.

    agents.train: ``vecnormalize_final.pkl`` with ``model.zip``, else ``vecnormalize.pkl`` beside the zip.
    rl-baselines3-zoo (``<log>/<algo>/<env>_<n>/``): ``<env>/vecnormalize.pkl`` (saved on every new best and
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
        path: A run folder of :mod:`agents.train` (``best_model.zip`` preferred over ``model.zip``;
            ``vecnormalize.pkl`` applied when present, ``vecnormalize_final.pkl`` with ``model.zip``;
            the algorithm read from ``config.yaml``), a run folder of rl-baselines3-zoo
            (``<log>/<algo>/<env>_<n>``: the final ``<env>.zip``, else ``best_model.zip``, with
            ``<env>/vecnormalize.pkl``, which holds the final statistics), or an SB3 ``.zip`` of either
            (the statistics found beside it as :func:`_stats_beside` says; the algorithm read from the
            zip, or ``algo``).
        device: Torch device.
        algo: Force the algorithm (``"ppo"``, ``"sac"``, ...).

    Returns:
        The controller (it also has ``act_batch``).

    Raises:
        FileNotFoundError: If ``path`` is neither a run folder with a model nor a ``.zip``.
        ValueError: If the algorithm is unknown or cannot be determined.
    """
    path = Path(path)
    normalization: dict[str, Any] = {}
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
    elif path.is_file() and path.suffix == ".zip":
        zip_path = path
        stats_path = _stats_beside(path)
        if stats_path is not None:
            normalization = _load_normalization(stats_path)
    else:
        raise FileNotFoundError(f"{path} is neither a run folder nor an SB3 .zip file")
    algo = (algo or algo_of_zip(zip_path) or "").lower() or None
    classes = _algos()
    if algo is not None and algo not in classes:
        raise ValueError(f"unknown algorithm {algo!r}; known: {sorted(classes)}")
    candidates = [algo] if algo else list(classes)
    errors = []
    for candidate in candidates:
        try:
            with open(zip_path, "rb") as f:
                model = classes[candidate].load(io.BytesIO(f.read()), device=device)
        except Exception as error:  # noqa: BLE001 - try the next algorithm, report all failures below
            errors.append(f"{candidate}: {error}")
            continue
        return SB3Controller(model, name=name if path.is_dir() and zoo_dir is None else candidate, **normalization)
    raise ValueError(f"could not load {zip_path} with {candidates}: " + "; ".join(errors))
