"""Fold pfw_simavr's flat profile (``--profile``: byte address, cycles) into cycles per function.

Usage: ``python3 profile.py FIRMWARE.elf PROFILE [N]`` (needs avr-nm); prints the N (default 25) costliest
functions with their share of the profiled cycles. Exclusive costs: a function's own instructions, not its callees'.
"""

import bisect
import subprocess
import sys


def main() -> None:
    """Print the costliest functions of a profile (arguments: see the module docstring)."""
    elf, path = sys.argv[1], sys.argv[2]
    top = int(sys.argv[3]) if len(sys.argv) > 3 else 25
    symbols = []
    for line in subprocess.run(["avr-nm", "-n", elf], capture_output=True, text=True, check=True).stdout.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1] in "tTwW" and not parts[2].startswith("__stack"):
            symbols.append((int(parts[0], 16), parts[2]))
    starts = [a for a, _ in symbols]
    cost: dict[str, int] = {}
    with open(path) as fh:
        for line in fh:
            address, cycles = line.split()
            i = bisect.bisect_right(starts, int(address, 16)) - 1
            name = symbols[i][1] if i >= 0 else "?"
            cost[name] = cost.get(name, 0) + int(cycles)
    total = sum(cost.values()) or 1
    print(f"{total} cycles profiled")
    for name, cycles in sorted(cost.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{cycles:10d} {100.0 * cycles / total:5.1f} %  {name}")


if __name__ == "__main__":
    main()
