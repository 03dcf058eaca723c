"""Stewart-platform kinematics of the plate (exact inverse kinematics, Jacobians, forward kinematics)."""
