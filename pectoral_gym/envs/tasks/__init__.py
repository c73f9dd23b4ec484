"""The fish tasks: their batched numba kernels, a task (one row of the table), and the task table and state.

``kernels`` (the compiled goal/track logic of a step), ``episode_start`` (the task geometry, an episode's
draws and start states), ``reference_ellipse`` (the track task's moving point), ``row``
(:class:`~pectoral_gym.envs.tasks.row.Task`, what a task is), ``table`` (the task table and ``TaskState``,
shared by the simulated and the robot envs).
"""
