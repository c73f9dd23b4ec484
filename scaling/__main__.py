"""``python -m scaling``: identify or validate the scaling functions."""

from scaling.cli import main

raise SystemExit(main())
