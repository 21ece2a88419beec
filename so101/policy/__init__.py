"""Trained policies in the dataflow: the environment that runs them (LeRobot and torch, apart from this
project's install) and what a policy's frames are made of."""
