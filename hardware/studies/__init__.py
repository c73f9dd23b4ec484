"""Studies that run the robot stack: the deployment study the benchmark and the demo reach as a robot-stack plugin."""
