"""The fish tasks: their batched numba kernels, and the task table and state shared by the simulated and robot envs."""
