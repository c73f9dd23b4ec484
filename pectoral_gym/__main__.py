"""``python -m pectoral_gym``: the ``pectoral-fish`` command line."""

from pectoral_gym.tools.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
