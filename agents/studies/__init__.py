"""Studies over trained policies and controllers: the benchmark suite, seeds, time to solve, hyperparameter sweeps."""
