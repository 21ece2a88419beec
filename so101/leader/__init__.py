"""The SO-101 leader arm: six servos with torque off, moved by a person's hand, read as joint commands."""
