"""A robot firmware's conformance to the protocol's robot rules, checked over the radio (``pectoral-firmware-check``).

:mod:`.probe` sends raw protocol messages and collects the answers; :mod:`.judge` holds the verdicts, the
tolerances and their argument; :mod:`.timing`, :mod:`.sessions` and :mod:`.fins` hold one scenario per rule of
``docs/protocol.md`` section 5; :mod:`pectoral_gym.hardware.firmware_check` runs them and reports.
"""
