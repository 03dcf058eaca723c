"""Actuation: the nominal plant model, harmonic tables, goal planning and limits (ROS-free)."""
