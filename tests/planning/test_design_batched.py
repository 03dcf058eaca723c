"""Design Jacobians in one solve_fields call: the same design as scipy's own one-point-at-a-time
finite differences, bit for bit, with far fewer solver calls."""

import numpy as np
import scipy.optimize

import ppod_ros.physics as physics
from ppod_ros.planning import FieldSpec
from ppod_ros.planning import design as design_module


def _design(monkeypatch, batched: bool):
    calls = []
    real = physics.solve_fields

    def counting(motions, *args, **kwargs):
        calls.append(len(motions))
        return real(motions, *args, **kwargs)

    monkeypatch.setattr(physics, "solve_fields", counting)
    if not batched:  # scipy's own scheme: every Jacobian point through ``residual`` alone
        real_ls = scipy.optimize.least_squares

        def serial(*args, workers=None, **kwargs):
            return real_ls(*args, **kwargs)

        monkeypatch.setattr(scipy.optimize, "least_squares", serial)
    design_module._CACHE.clear()
    result = design_module.design_field(FieldSpec.from_request("line_sink", [0.01, 0.0, 0.5, 0.3]),
                                        max_evaluations=4)
    monkeypatch.undo()
    design_module._CACHE.clear()
    return result, calls


def test_batched_jacobian_gives_the_same_design_in_fewer_calls(monkeypatch):
    batched, calls_b = _design(monkeypatch, True)
    serial, calls_s = _design(monkeypatch, False)
    np.testing.assert_array_equal(batched.motion.phasors(), serial.motion.phasors())
    assert batched.r2 == serial.r2
    assert max(calls_b) == 11          # one Jacobian: the 11 inputs' points in one call
    assert max(calls_s) == 1
    assert len(calls_b) * 3 < len(calls_s)
