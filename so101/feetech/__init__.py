"""The Feetech STS3215 servo bus: the register table, the bus, LeRobot's calibration, and an emulated arm."""
