"""Identification of K: the pattern grids, the full-model reference runs, the regression, the identification NMPC."""
