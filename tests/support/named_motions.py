"""Motions for the per-name scale tests (test_mpc_turn_by_name.py, test_mpc_scale_by_name.py)."""

from __future__ import annotations

from ppod_ros.planning.mpc import moved


def named_motions(base, name: str, other: str):
    """``base`` moved to two places under ``name`` (two keys, one name), a weaker one named "mpc" (a
    refined motion), and another named ``other``: (here, there, refined, other)."""
    return (moved(base, 0.01, 0.0, name=name), moved(base, 0.02, 0.01, name=name),
            moved(base.scaled(0.7), 0.0, 0.01, name="mpc"), moved(base.scaled(0.8), 0.0, -0.01, name=other))
