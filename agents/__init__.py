"""Stable-Baselines3 training, evaluation, baseline controllers and the benchmark suite."""

if __name__ != "pectoral_gym.agents":  # one module identity (pip install -e . maps this folder there too)
    raise ImportError(f"import pectoral_gym.agents, not {__name__}: the repository's agents/ folder is installed as "
                      "pectoral_gym.agents; importing it by another name would load a second copy of its modules")
