"""The least clearance from the tank's walls over a deployment's step records, and the records past a wall.

Reads ``steps.jsonl`` of an emulated deployment (``pectoral-deploy --emulate``; its step records carry the
emulator's ``true_pose``) and prints the smallest :func:`pectoral_gym.model.tank.clearance` of the fish's outline
(Table 1's fish, or ``--params``) at those poses, and how many records had the outline past a wall. The safety
guide's "least clearance" column comes from it::

    python docs/validation/hardware/least_clearance.py OUT/steps.jsonl

Exit 2 with a one-line error for a missing file, a malformed line, or records without a true pose (a real robot's
log has none: only an emulator knows where the fish truly is).
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from pectoral_gym.model import tank
from pectoral_gym.model.params import FishParams, load_params


def least_clearance(path: str, outline: tank.Outline) -> tuple[float, int, int]:
    """``(least clearance [m], records past a wall, records with a true pose)`` of the step records in ``path``.

    Raises:
        ValueError: A line that is not a JSON object, or a true pose that is not three finite numbers.
        OSError: The file cannot be read.
    """
    least, past, seen = math.inf, 0, 0
    with open(path, encoding="utf-8") as lines:
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError as err:
                raise ValueError(f"{path}:{number}: not JSON ({err.msg})") from None
            if not isinstance(record, dict):
                raise ValueError(f"{path}:{number}: a step record is a JSON object")
            pose = record.get("true_pose")
            if pose is None:
                continue
            if not (isinstance(pose, list) and len(pose) >= 3
                    and all(isinstance(v, (int, float)) and math.isfinite(v) for v in pose[:3])):
                raise ValueError(f"{path}:{number}: true_pose is not three finite numbers: {pose!r}")
            clearance = float(np.min(tank.clearance(pose[0], pose[1], pose[2], outline)))
            least = min(least, clearance)
            past += clearance < 0.0
            seen += 1
    return least, past, seen


def main(argv: list[str] | None = None) -> int:
    """Print the least clearance of ``steps.jsonl``; 0, or 2 with a one-line error."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("steps", help="a deployment's steps.jsonl (emulated: its records carry true_pose)")
    parser.add_argument("--params", metavar="FILE", help="the fish's parameters (JSON; default: Table 1's fish)")
    args = parser.parse_args(argv)
    try:
        params = load_params(args.params) if args.params else FishParams()
        least, past, seen = least_clearance(args.steps, tank.Outline.from_params(params))
    except (OSError, ValueError) as err:
        parser.error(str(err))
    if not seen:
        parser.error(f"{args.steps}: no step record has a true_pose (only an emulated deployment's do)")
    print(f"least clearance {least * 1000:.0f} mm over {seen} records, records past a wall {past}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
