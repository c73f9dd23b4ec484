"""Command-line tools over the model and the envs: ``pectoral-fish`` (simulate, steady, patterns, step-rate)."""
