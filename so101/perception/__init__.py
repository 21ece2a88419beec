"""Eyes taught by the simulator: where the cube is, from the front camera's picture, for a state policy."""
