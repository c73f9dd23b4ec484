"""The fish tasks: their batched numba kernels, a task (one row of the table), and the task table and state.

``kernels`` (the compiled goal/track logic), ``row`` (:class:`~pectoral_gym.envs.tasks.row.Task`, what a task is),
``table`` (the task table and ``TaskState``, shared by the simulated and the robot envs).
"""
