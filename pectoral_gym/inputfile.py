"""Bounded reads of the files a user names: a size limit, then text, then JSON, each fault a one-line ``ValueError``.

A path given on a command line may name anything: a symlink to ``/dev/zero`` (read whole, it fills the memory),
a document nested thousands of levels deep (``json`` recurses and raises ``RecursionError``), binary data. Every
reader of a user's input file goes through :func:`read_text` or :func:`load_json`, which read at most a stated
number of bytes and turn every such fault into a ``ValueError`` naming the file and what is wrong.

Limits (each at least 100 times the largest such file the tool chain writes):

* :data:`SMALL_FILE_BYTES` (1 MiB): a parameters file (under 1 kB), a camera calibration (under 1 kB).
* :data:`K_FILE_BYTES` (64 MiB): a K file (the shipped ones: 0.3 and 0.6 MB).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

__all__ = ["K_FILE_BYTES", "SMALL_FILE_BYTES", "load_json", "read_text"]

SMALL_FILE_BYTES = 1 << 20
K_FILE_BYTES = 64 << 20


def read_text(path: str | os.PathLike, limit: int) -> str:
    """The UTF-8 text of ``path``, read only if it holds at most ``limit`` bytes.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        OSError: If it cannot be opened or read (a directory, no permission).
        ValueError: If it holds more than ``limit`` bytes (also an endless device such as ``/dev/zero``) or is
            not UTF-8 text.
    """
    with Path(path).open("rb") as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"{os.fspath(path)}: larger than {limit} bytes, more than such a file ever holds "
                         "(a device or the wrong file?)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ValueError(f"{os.fspath(path)}: not UTF-8 text ({err.reason} at byte {err.start})") from None


def _reject_constant(token: str) -> float:
    raise ValueError(f"{token} is not a number JSON allows")


def load_json(path: str | os.PathLike, limit: int = SMALL_FILE_BYTES) -> Any:
    """The JSON document in ``path`` (:func:`read_text`'s limit).

    ``NaN`` and ``Infinity`` (which Python's ``json`` accepts) are refused.

    Raises:
        FileNotFoundError, OSError: As :func:`read_text`.
        ValueError: Too large, not text, nested too deep, or not valid JSON.
    """
    text = read_text(path, limit)
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except ValueError as err:  # json.JSONDecodeError and the constants
        raise ValueError(f"{os.fspath(path)}: not valid JSON ({err})") from None
    except RecursionError:  # json's scanner recurses once per level
        raise ValueError(f"{os.fspath(path)}: JSON nested deeper than Python's recursion limit (not such a file: "
                         "the tool chain writes at most 5 levels)") from None
