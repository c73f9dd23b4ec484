"""The files a run trained with (a robot's ``params`` and ``scaling`` files), kept in its run folder.

A run's ``config.yaml`` records its env arguments; a ``params`` or ``scaling`` given as a file path would be
recorded as typed, relative to the directory training ran in, so an evaluation or a deploy started anywhere
else (or on another machine) could not find it, or would find another robot's file of the same name.
:func:`keep_run_files` copies each such file into the run folder and :func:`resolve_run_files` reads the
recorded names back relative to it: a run folder is self-contained.
"""

from __future__ import annotations

import copy
import os
import shutil
from pathlib import Path
from typing import Any

__all__ = ["RUN_FILES", "keep_run_files", "resolve_run_files"]

#: Env arguments that may name a file -> the name of its copy in the run folder.
RUN_FILES = {"params": "params.json", "scaling": "scaling_coefficients.json"}
_KWARGS_KEYS = ("env_kwargs", "eval_env_kwargs")  # the config's sections of env arguments
_NOT_FILES = ("identified", "none")  # scaling's named choices


def _file_value(value: Any) -> Path | None:
    """``value`` as a path if it names an existing file, else ``None`` (a dict of fields, a named choice)."""
    if not isinstance(value, (str, os.PathLike)) or os.fspath(value) in _NOT_FILES:
        return None
    path = Path(value)
    return path if path.is_file() else None


def keep_run_files(config: dict[str, Any], run_dir: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """Copy the files ``config``'s env arguments name into ``run_dir``.

    Args:
        config: A resolved training config (:func:`pectoral_gym.agents.training.config.resolve_config`).
        run_dir: The run folder (exists).

    Returns:
        ``(to_train, to_record)``: ``config`` with each such argument naming its copy, by its full path (what
        training opens) and by its name in the run folder (what ``config.yaml`` records).

    Raises:
        ValueError: Two different files for one argument (``env_kwargs`` and ``eval_env_kwargs``).
    """
    to_train, to_record = copy.deepcopy(config), copy.deepcopy(config)
    copied: dict[str, Path] = {}
    for section in _KWARGS_KEYS:
        kwargs = config.get(section) or {}
        for key, name in RUN_FILES.items():
            source = _file_value(kwargs.get(key))
            if source is None:
                continue
            if key in copied and copied[key].resolve() != source.resolve():
                raise ValueError(f"{section}[{key!r}] names {source}, another file than the training's "
                                 f"{copied[key]}: a run keeps one {key} file")
            if key not in copied:
                shutil.copyfile(source, run_dir / name)
                copied[key] = source
            to_train[section][key] = str(run_dir / name)
            to_record[section][key] = name
    return to_train, to_record


def resolve_run_files(env_kwargs: dict[str, Any], run_dir: str | Path) -> dict[str, Any]:
    """``env_kwargs`` of a run folder's ``config.yaml`` with the kept files' names as paths into ``run_dir``.

    A name that is not a file of the run folder (a run written before files were kept: a path relative to
    where it trained) is left as it is.
    """
    out = dict(env_kwargs)
    for key, name in RUN_FILES.items():
        if out.get(key) == name and (Path(run_dir) / name).is_file():
            out[key] = str(Path(run_dir) / name)
    return out
