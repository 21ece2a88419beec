"""Episodes as LeRobot datasets (LeRobotDataset v3.0): the features, the files, the recorder's and replay's logic."""
