"""The radio link to the robot.

XBee API frames (:mod:`.xbee`) carrying the messages of :mod:`.protocol`; the PC's side of the link (:mod:`.link`,
:mod:`.linkclock`); the robot's reference firmware rules (:mod:`.firmware`); a lossy radio for tests
(:mod:`.radioproxy`).
"""
