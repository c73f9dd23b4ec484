"""Validation of the identified K: averaged against full model, fidelity runs, yaw balance, their plots."""
