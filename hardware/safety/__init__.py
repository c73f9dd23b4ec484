"""PC-side safety of the hardware environment.

The rules (:mod:`.rules`), the geofence and its physical speed bound (:mod:`.geofence`) and the supervisor thread
that applies them (:mod:`.supervisor`). The robot's own rules are :mod:`pectoral_gym.hardware.radio.firmware`'s.
"""
