"""``python -m pectoral_gym.scaling``: identify or validate the scaling functions."""

from pectoral_gym.scaling.cli import main

raise SystemExit(main())
