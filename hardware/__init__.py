"""Run trained policies on the real robotic fish: XBee radio link, overhead camera, emulated robot.

Every time, wait and thread of the stack goes through a clock (:mod:`.clock`): the wall clock on the robot, a
virtual one for a lockstep emulation (:mod:`.emurig`, ``deploy --emulate --lockstep``).
"""

if __name__ != "pectoral_gym.hardware":  # one module identity (pip install -e . maps this folder there too)
    raise ImportError(f"import pectoral_gym.hardware, not {__name__}: the repository's hardware/ folder is installed "
                      "as pectoral_gym.hardware; importing it by another name would load a second copy of its modules")
