"""Share a trained run in rl-baselines3-zoo's Hugging Face Hub layout, and lay a downloaded one out to use, offline.

rl_zoo3 2.9.2 publishes a run as a Hub repository (``rl_zoo3/push_to_hub.py``, ``package_to_hub``) named
``<org>/<algo>-<env>`` that holds, at its top level:

* ``<algo>-<env>.zip``: the SB3 model (``huggingface_sb3.ModelName(algo, EnvironmentName(env)).filename``; an
  env id's slashes become dashes);
* ``vec_normalize.pkl``: the ``VecNormalize`` statistics, when the run normalises observations;
* ``config.yml``: zoo's hyperparameters of the run (``n_envs``, ``n_timesteps``, ``policy``, ``normalize``, the
  algorithm's arguments with ``policy_kwargs`` as Python text, ``env_kwargs``);
* ``args.yml``: zoo's command line (``rl_zoo3.enjoy`` reads its ``env_kwargs``); ``env_kwargs.yml``;
* ``train_eval_metrics.zip``: the training's evaluation and monitor files;
* a model card (``README.md``), and, from ``package_to_hub``'s own evaluation, ``results.json`` and a replay video.

``rl_zoo3.load_from_hub`` (``download_from_hub``) fetches the first six and lays them out as zoo's run folder,
``<folder>/<algo>/<env>_<n>/<env>.zip`` with ``<env>/config.yml``, ``args.yml``, ``env_kwargs.yml`` and
``vecnormalize.pkl``, the metrics unpacked beside the model: the layout that
:func:`~pectoral_gym.agents.training.policy.load_policy` (and so ``pectoral-evaluate --policy``, ``pectoral-deploy``)
and zoo's ``enjoy`` read.

:func:`write_hub_folder` writes a ``pectoral-train`` run folder in the repository's layout (the model and statistics
``load_policy`` would use; no evaluation, no video), ready for ``huggingface_hub.HfApi().upload_folder``.
:func:`read_hub_folder` lays out a repository's files (``huggingface_hub.snapshot_download``, or any copy) as
``download_from_hub`` does, without ``huggingface_sb3`` or a network. Command line::

    python -m pectoral_gym.agents.training.hub write runs/PectoralFish-Averaged-v2/ppo_seed0 hub/ppo-fish
    python -m pectoral_gym.agents.training.hub read hub/ppo-fish -f logs
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import zipfile
from pathlib import Path
from typing import Any

import yaml

from pectoral_gym.agents.training.policy import read_config
from pectoral_gym.agents.training.run_files import RUN_FILES

__all__ = ["HUB_FILES", "build_parser", "hub_model_name", "main", "read_hub_folder", "write_hub_folder"]

#: The files of a repository that ``download_from_hub`` fetches, besides the model (``vec_normalize.pkl`` optional).
HUB_FILES = ("config.yml", "args.yml", "env_kwargs.yml", "train_eval_metrics.zip", "vec_normalize.pkl")
_METRICS = ("training.json", "config.yaml", "command.txt")  # of a run, kept in the metrics zip
# The metrics zip's folder for the run's own files: unpacked beside zoo's model, a config.yaml there would make the
# folder look like a pectoral-train run folder to load_policy.
_RUN_FILES_DIR = "pectoral-train"


def hub_model_name(algo: str, env_id: str) -> str:
    """``<algo>-<env>``, the repository's name and its model's file stem (``huggingface_sb3.ModelName``)."""
    return f"{algo}-{env_id.replace('/', '-')}"


def _python_text(value: Any) -> str:
    """``value`` (dicts, lists, numbers, text, ``nn.<Name>`` class names) as the Python text zoo evaluates."""
    if isinstance(value, dict):
        return "dict(" + ", ".join(f"{key}={_python_text(item)}" for key, item in value.items()) + ")"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_python_text(item) for item in value) + "]"
    if isinstance(value, str) and re.fullmatch(r"(nn|th|torch)(\.[A-Za-z_]\w*)+", value):
        return value
    return repr(value)


def _zoo_config(config: dict[str, Any]) -> dict[str, Any]:
    """The ``config.yml`` zoo would write for a ``pectoral-train`` run: its hyperparameters in zoo's format."""
    hyperparams = {"n_envs": config["n_envs"], "n_timesteps": config["n_timesteps"], "policy": config["policy"],
                   "normalize": config.get("normalize", False), "env_kwargs": dict(config.get("env_kwargs") or {})}
    for key, value in (config.get("algo_kwargs") or {}).items():
        hyperparams[key] = _python_text(value) if key == "policy_kwargs" else value
    if isinstance(hyperparams["normalize"], dict):  # zoo's own files give the VecNormalize arguments as text
        hyperparams["normalize"] = _python_text(hyperparams["normalize"])
    return {key: hyperparams[key] for key in sorted(hyperparams)}


def _model_and_stats(run: Path) -> tuple[Path, Path | None]:
    """The model and statistics ``load_policy`` takes from a run folder (best model first)."""
    if (run / "best_model.zip").is_file():
        stats = run / "vecnormalize.pkl"
        return run / "best_model.zip", stats if stats.is_file() else None
    if (run / "model.zip").is_file():
        stats = next((run / f for f in ("vecnormalize_final.pkl", "vecnormalize.pkl") if (run / f).is_file()), None)
        return run / "model.zip", stats
    raise FileNotFoundError(f"{run} has neither best_model.zip nor model.zip; is it a pectoral-train run folder?")


def write_hub_folder(run: str | Path, out: str | Path) -> Path:
    """Write the ``pectoral-train`` run folder ``run`` in rl_zoo3's Hub repository layout into ``out``.

    Returns:
        ``out``, holding ``<algo>-<env>.zip``, ``vec_normalize.pkl`` (when the run normalises), ``config.yml``,
        ``args.yml``, ``env_kwargs.yml``, ``train_eval_metrics.zip`` (the run's ``training.json``,
        ``config.yaml``, ``command.txt`` in its folder ``pectoral-train/``) and ``README.md``.

    Raises:
        FileNotFoundError: If ``run`` has no ``config.yaml`` or no model.
        ValueError: If ``out`` exists and is not empty, or the run's env arguments name files of the run folder
            (a robot's ``params`` or ``scaling`` file): a zoo layout has no place for them.
    """
    run, out = Path(run), Path(out)
    config = read_config(run)
    if not config:
        raise FileNotFoundError(f"{run} has no config.yaml; is it a pectoral-train run folder?")
    env_kwargs = dict(config.get("env_kwargs") or {})
    kept = sorted(key for key in RUN_FILES if isinstance(env_kwargs.get(key), str) and (run / RUN_FILES[key]).is_file())
    if kept:
        raise ValueError(f"{run} trained with its own {kept} file(s); sharing such a run in zoo's layout is not "
                         "supported (share the run folder itself)")
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} exists and is not empty")
    out.mkdir(parents=True, exist_ok=True)
    algo, env_id = str(config["algo"]), str(config["env_id"])
    name = hub_model_name(algo, env_id)
    model, stats = _model_and_stats(run)
    shutil.copyfile(model, out / f"{name}.zip")
    if stats is not None:
        shutil.copyfile(stats, out / "vec_normalize.pkl")
    (out / "config.yml").write_text(yaml.safe_dump(_zoo_config(config), sort_keys=False))
    args = {"algo": algo, "env": env_id, "env_kwargs": env_kwargs, "seed": config.get("seed")}
    (out / "args.yml").write_text(yaml.safe_dump(args))
    (out / "env_kwargs.yml").write_text(yaml.safe_dump(env_kwargs))
    with zipfile.ZipFile(out / "train_eval_metrics.zip", "w") as archive:
        for file_name in _METRICS:
            if (run / file_name).is_file():
                archive.write(run / file_name, arcname=f"{_RUN_FILES_DIR}/{file_name}")
    (out / "README.md").write_text(_model_card(algo, env_id, model.name, config))
    return out


def _model_card(algo: str, env_id: str, model_file: str, config: dict[str, Any]) -> str:
    """A short model card with the Hub's metadata header (the library, the env id as a tag)."""
    meta = {"library_name": "stable-baselines3",
            "tags": [env_id, "deep-reinforcement-learning", "reinforcement-learning", "stable-baselines3"]}
    return (f"---\n{yaml.safe_dump(meta, sort_keys=False)}---\n\n# {algo.upper()} on {env_id}\n\n"
            f"A {algo.upper()} policy trained with pectoral-gym's `pectoral-train` (seed {config.get('seed')}, "
            f"{config.get('n_timesteps')} steps), its `{model_file}`, in rl-baselines3-zoo's layout. Load it with\n\n"
            f"```bash\npython -m pectoral_gym.agents.training.hub read <this folder> -f logs\n"
            f"pectoral-evaluate --policy logs/{algo}/{env_id.replace('/', '-')}_1 --env {env_id}\n```\n\n"
            f"or `python -m rl_zoo3.load_from_hub --algo {algo} --env {env_id} -orga <org> -f logs`. The run's own "
            "`config.yaml` and `training.json` are in `train_eval_metrics.zip` (`pectoral-train/`).\n")


def _latest_run_id(algo_dir: Path, env_name: str) -> int:
    """The largest ``n`` of the ``<env>_<n>`` folders in ``algo_dir`` (0: none), as zoo's ``get_latest_run_id``."""
    ids = [int(m.group(1)) for p in algo_dir.glob(f"{env_name}_*")
           if (m := re.fullmatch(re.escape(env_name) + r"_(\d+)", p.name)) and p.is_dir()]
    return max(ids, default=0)


def read_hub_folder(folder: str | Path, logs: str | Path, exp_id: int = 0) -> Path:
    """Lay the Hub repository files in ``folder`` out as zoo's run folder under ``logs``, as ``download_from_hub``.

    Args:
        folder: A repository's files (:func:`write_hub_folder`, ``snapshot_download``, a copy).
        logs: zoo's log folder (``-f``).
        exp_id: The run's number ``n`` in ``<logs>/<algo>/<env>_<n>``; 0: one more than the latest.

    Returns:
        The run folder, for ``load_policy`` / ``pectoral-evaluate --policy`` and zoo's ``enjoy --exp-id n``.

    Raises:
        FileNotFoundError: If ``folder`` has no one ``<algo>-<env>.zip`` or lacks a file ``download_from_hub`` needs.
        ValueError: If the run folder exists already.
    """
    folder, logs = Path(folder), Path(logs)
    # the model's name says the algorithm and the env (<algo>-<env>.zip; zoo's algorithm names have no dash): zoo's
    # own args.yml is a pickled-style YAML (an OrderedDict) that a safe loader does not read
    models = sorted(p for p in folder.glob("*-*.zip") if p.name != "train_eval_metrics.zip")
    if len(models) != 1:
        raise FileNotFoundError(f"{folder} has {len(models)} <algo>-<env>.zip models, not one; is it an "
                                "rl-baselines3-zoo Hub repository?")
    model = models[0]
    algo, env_name = model.stem.split("-", 1)
    missing = [name for name in HUB_FILES[:-1] if not (folder / name).is_file()]
    if missing:
        raise FileNotFoundError(f"{folder} lacks {missing}")
    if exp_id == 0:
        exp_id = _latest_run_id(logs / algo, env_name) + 1
    run = logs / algo / f"{env_name}_{exp_id}"
    if run.exists():
        raise ValueError(f"{run} exists already; choose another exp_id (0: the next free one)")
    (run / env_name).mkdir(parents=True)
    shutil.copyfile(model, run / f"{env_name}.zip")
    for file_name in ("args.yml", "config.yml", "env_kwargs.yml"):
        shutil.copyfile(folder / file_name, run / env_name / file_name)
    if (folder / "vec_normalize.pkl").is_file():
        shutil.copyfile(folder / "vec_normalize.pkl", run / env_name / "vecnormalize.pkl")
    with zipfile.ZipFile(folder / "train_eval_metrics.zip") as archive:
        archive.extractall(run)
    return run


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m pectoral_gym.agents.training.hub`` (``write`` and ``read``)."""
    from pectoral_gym.tools.cli_common import HelpFormatter, examples, prog_name, subcommands

    prog = prog_name(None, "pectoral_gym.agents.training.hub")
    write_example = f"{prog} write runs/PectoralFish-Averaged-v2/ppo_seed0 hub/ppo-fish"
    read_example = f"{prog} read hub/ppo-fish -f logs"
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter,
                                     epilog=examples(write_example, read_example))
    commands = subcommands(parser, dest="command", required=True)
    write = commands.add_parser("write", help="a pectoral-train run folder in rl_zoo3's Hub repository layout",
                                description="Write a pectoral-train run folder in rl_zoo3's Hub repository layout "
                                "(the folder to upload as the repository).", epilog=examples(write_example))
    write.add_argument("run", help="the pectoral-train run folder")
    write.add_argument("out", help="the folder to write (new or empty)")
    read = commands.add_parser("read", help="a Hub repository's files laid out as zoo's run folder",
                               description="Lay a Hub repository's files out as zoo's run folder, as rl_zoo3's "
                               "download_from_hub does.", epilog=examples(read_example))
    read.add_argument("folder", help="the repository's files (e.g. from huggingface_hub.snapshot_download)")
    read.add_argument("-f", "--folder-out", dest="logs", default="logs", help="zoo's log folder")
    read.add_argument("--exp-id", type=int, default=0, help="the run's number n of <env>_<n> (0: the next free)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; prints the folder written as JSON. Exit status 2 on bad input."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        done = write_hub_folder(args.run, args.out) if args.command == "write" else read_hub_folder(
            args.folder, args.logs, args.exp_id)
    except (FileNotFoundError, ValueError) as error:
        parser.exit(2, f"error: {error}\n")
    print(json.dumps({"folder": str(done)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
