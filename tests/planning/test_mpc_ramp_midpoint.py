"""The ramp of a switch predicted with the model half-way through it (``MpcSettings.ramp_midpoint``).

Regression (``ppod bench planner --sections multipart``, one bracket, seed 1, scene 1): the planner
switched from a turn to a weak motion with the bracket 1.4 mm from its goal. It predicted the ramp
from the two motions' velocities crossfaded linearly: 0.7 mm. The bracket moved 4.3 mm, because
half-way through the generator's crossfade the plate plays a motion under which the model itself
moves it at 9.1 mm/s, faster than either motion does (6.1 and 3.5 mm/s) and another way. The
velocity-scale estimate then read the bracket as four times faster than the model (the range's
limit; its scale jumped from 0.9 to 2.8) and the next motions threw it again.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion, crossfade
from ppod_ros.parts import PointPart
from ppod_ros.physics import PartDynamics
from ppod_ros.planning.mpc import MpcSettings, MultiTask, PartGoal, moved, ramp_weights, ramped_displacement


def _quadratic_ramp(c, t: float, r: float) -> float:
    """The integral over [0, t] of c0 + c1 u + c2 u^2 (u = s / r) on the ramp, constant after it."""
    u = min(t, r) / r
    on_ramp = r * (c[0] * u + c[1] * u * u / 2 + c[2] * u ** 3 / 3)
    return on_ramp + (c[0] + c[1] + c[2]) * max(0.0, t - r)


def test_the_linear_ramp_is_the_velocities_crossfaded():
    r, v0, v1 = 0.5, np.array([1.0, -2.0]), np.array([3.0, 0.5])
    for t in (0.1, 0.25, 0.5, 1.2):
        # The linear crossfade is the quadratic with c2 = 0 (c1 = v1 - v0).
        expected = [_quadratic_ramp((a, b - a, 0.0), t, r) for a, b in zip(v0, v1)]
        np.testing.assert_allclose(ramped_displacement(v0, v1, t, r), expected, rtol=1e-12)
        assert sum(ramp_weights(t, r)) == pytest.approx(t)
    assert ramp_weights(0.3, 0.0) == (0.0, 0.0, 0.3)


def test_the_midpoint_ramp_integrates_a_quadratic_exactly_and_the_mean_gives_the_linear_one():
    r, c = 0.5, (0.3, -1.0, 2.0)

    def v(s: float) -> float:
        u = min(s, r) / r
        return c[0] + c[1] * u + c[2] * u * u

    for t in (0.05, 0.2, 0.5, 0.9):
        assert ramped_displacement(v(0), v(r), t, r, v(r / 2)) == pytest.approx(_quadratic_ramp(c, t, r), rel=1e-12)
        assert sum(ramp_weights(t, r, True)) == pytest.approx(t)
        assert ramped_displacement(1.0, 3.0, t, r, 2.0) == pytest.approx(ramped_displacement(1.0, 3.0, t, r))
    assert ramp_weights(0.5, 0.5, True) == pytest.approx((0.5 / 6, 0.5 * 2 / 3, 0.5 / 6))   # Simpson's rule


def test_crossfade_mixes_the_tables_as_the_generator_ramps():
    a = PlateMotion.single(30.0, [1.0, 2.0, 0.5, 3.0, 1.0, 10.0], [0.0, 1.0, 2.0, 0.0, 1.0, 2.0])
    b = PlateMotion.single(30.0, [2.0, 0.0, 1.5, 1.0, 4.0, 20.0], [1.0, 0.0, -1.0, 0.5, 0.0, 3.0])
    mixed = 0.75 * a.phasor_table(1) + 0.25 * b.phasor_table(1)
    np.testing.assert_allclose(crossfade(a, b, 0.25).phasor_table(1), mixed)
    assert crossfade(a, b, 1.0) is b
    rest = PlateMotion.zero(30.0)
    np.testing.assert_allclose(crossfade(rest, b, 0.3).phasors(), 0.3 * b.phasors())
    np.testing.assert_allclose(crossfade(None, b, 0.3).phasors(), 0.3 * b.phasors())
    np.testing.assert_allclose(crossfade(a, rest, 0.3).phasors(), 0.7 * a.phasors())
    # Another frequency: faded out over the first half, in over the second.
    c = PlateMotion.single(40.0, [2.0, 0.0, 1.5, 1.0, 4.0, 20.0])
    assert crossfade(a, c, 0.5).is_zero()
    np.testing.assert_allclose(crossfade(a, c, 0.25).phasors(), 0.5 * a.phasors())
    np.testing.assert_allclose(crossfade(a, c, 0.75).phasors(), 0.5 * c.phasors())


def _switch_after_a_sink(ramp_midpoint: str):
    """A washer that rested under a sink 1 s, then switched to a transport: the planner's prediction
    of the ramp, its estimate after it, and the part's true displacement over the ramp (the
    dynamics under the generator's crossfade, friction as the model's)."""
    part = PointPart(0.3)
    task = MultiTask([part], [PartGoal(0, 0.0, 0.0)], settings=MpcSettings(ramp_midpoint=ramp_midpoint))
    sink = moved(task._base("sink"), -0.02, 0.03)
    transport = moved(task._base("transport"), 0.0, 0.0, mirror=True)
    dyn = PartDynamics([part], np.array([[0.02, 0.01]]))
    t = 0.0
    for _ in range(10):
        dyn.advance(sink, t, 0.1)
        t += 0.1
    p0 = dyn.state.configurations.copy()
    ramp = task.settings.ramp_s
    n = int(round(ramp / 0.1))
    for i in range(n):
        dyn.advance(crossfade(sink, transport, (i + 0.5) / n), t, 0.1)
        t += 0.1
    p1 = dyn.state.configurations.copy()
    task.current, task.t0 = sink, 0.0
    task._v_current = task._current_velocity(p0)
    task._switch(1.0, p0, transport, task._velocities([transport], p0)[0][0])
    pred = task.last_prediction
    predicted = ramped_displacement(pred["previous"], pred["velocity"], ramp, ramp, pred["middle"])[0, :2]
    task.state[0].estimated = True
    task._estimate(1.0 + ramp, p1)
    return task, sink, transport, p0, predicted, p1[0, :2] - p0[0, :2]


def test_a_switch_predicts_its_ramp_from_the_motion_the_generator_plays_half_way():
    task, sink, transport, p0, predicted, moved_m = _switch_after_a_sink("estimate")
    half = task._velocities([crossfade(sink, transport, 0.5)], p0)[0][0]
    np.testing.assert_allclose(task.segment.middle, half, rtol=1e-12)
    pred = task.last_prediction   # scaled as the velocity is
    np.testing.assert_allclose(pred["middle"] * task.segment.velocity, half * pred["velocity"], rtol=1e-12)
    linear_task, *_, linear, _ = _switch_after_a_sink("off")
    assert linear_task.segment.middle is None and linear_task.last_prediction["middle"] is None
    err, err_linear = np.linalg.norm(predicted - moved_m), np.linalg.norm(linear - moved_m)
    # Measured: 1.4 mm off a 5.0 mm ramp, against 2.9 mm crossfaded linearly.
    assert err < 0.6 * err_linear and np.linalg.norm(moved_m) > 3e-3
    # The part moves as the model says (the same friction, no plant error): the estimate stays
    # nearer 1 with the midpoint than without it.
    assert abs(task.state[0].scale - 1.0) < abs(linear_task.state[0].scale - 1.0)


def test_with_plan_the_ranked_motions_cost_their_ramp_with_the_midpoint():
    task, sink, transport, p0, *_ = _switch_after_a_sink("plan")
    task.current = sink
    task._v_current = task._current_velocity(p0)
    statuses = task._statuses(1.0, p0)
    cost_mid, _ = task._costs([transport, sink], p0, statuses, ramped=True)
    cost_lin, _ = task._costs([transport, sink], p0, statuses)
    # "estimate" predicts the switch so, but ranks with the linear crossfade.
    task.settings = dataclasses.replace(task.settings, ramp_midpoint="estimate")
    assert task._costs([transport], p0, statuses, ramped=True)[0][0] == pytest.approx(cost_lin[0], rel=1e-12)
    assert cost_mid[0] != pytest.approx(cost_lin[0], rel=1e-3)
    assert cost_mid[1] == pytest.approx(cost_lin[1], rel=1e-12)   # the motion playing: no ramp
    task.settings = dataclasses.replace(task.settings, ramp_midpoint="off")
    assert task._costs([transport], p0, statuses, ramped=True)[0][0] == pytest.approx(cost_lin[0], rel=1e-12)
    with pytest.raises(ConfigError, match="ramp_midpoint"):
        MpcSettings(ramp_midpoint="on")
