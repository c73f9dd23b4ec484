"""Run trained policies on the real robotic fish: XBee radio link, overhead camera, emulated robot."""
