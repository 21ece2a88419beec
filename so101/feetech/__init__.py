"""The Feetech STS3215 servo bus: the register table, the bus, LeRobot's calibration, the arm read only
(arm_reader.py), and an emulated arm."""
