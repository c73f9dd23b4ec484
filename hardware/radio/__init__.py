"""The radio link to the robot.

XBee API frames (:mod:`.xbee`) carrying the messages of :mod:`.protocol`; the PC's side of the link (:mod:`.link`,
its receiving half :mod:`.linkstatus`, :mod:`.linkclock`); the robot's reference firmware rules (:mod:`.firmware`);
seeded radio conditions (:mod:`.channel`) on a lossy TCP radio for tests (:mod:`.radioproxy`) or an in-process
stream driven by a clock (:mod:`.pipe`, lockstep emulation).
"""
