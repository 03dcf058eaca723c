"""Actuation: harmonic tables, the nominal plant model, goal planning with limits, and corrections."""
