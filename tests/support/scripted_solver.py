"""What a scripted stand-in for ``ppod_ros.physics.solve_fields`` returns, for planner tests that
decide which rows the solver gives up on (tests/planning/test_mpc_hold.py, test_mpc_gave_up.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

import ppod_ros.physics as physics

#: The solver's reason codes by text ("not converged (step limit)", "contact lost", ...).
CODE = {text: code for code, text in physics.REASONS.items()}


def solver_result(velocity: np.ndarray, valid: np.ndarray, reason_code: np.ndarray) -> SimpleNamespace:
    """The fields of solve_fields' result the planner reads."""
    return SimpleNamespace(velocity=velocity, valid=valid, reason_code=reason_code)
