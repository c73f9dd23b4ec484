"""``python -m pectoral_gym``: the ``pectoral-fish`` command line."""

from pectoral_gym.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
