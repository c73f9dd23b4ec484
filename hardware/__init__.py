"""Run trained policies on the real robotic fish: XBee radio link, overhead camera, emulated robot."""

if __name__ != "pectoral_gym.hardware":  # one module identity (pip install -e . maps this folder there too)
    raise ImportError(f"import pectoral_gym.hardware, not {__name__}: the repository's hardware/ folder is installed "
                      "as pectoral_gym.hardware; importing it by another name would load a second copy of its modules")
