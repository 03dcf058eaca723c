"""The simulated accelerometers: rigid-body physics, tilted gravity, AC coupling, noise, quantisation."""

import dataclasses
import math

import numpy as np
import pytest

from ppod_ros.device import default_device_config
from ppod_ros.kinematics.stewart import rotation_matrix
from ppod_ros.motion import GRAVITY_MPS2
from ppod_sim.sensors import AccelerometerArray, SensorErrors, specific_force

X_AXIS = np.array([[1.0, 0.0, 0.0]])


def test_a_spinning_plate_reads_the_centripetal_acceleration():
    omega = np.array([[0.0, 0.0, 2.0]])
    l = np.array([[0.17, 0.0, 0.0]])
    zero = np.zeros((1, 6))
    g = np.zeros((1, 3))
    assert specific_force(zero, omega, g, l, X_AXIS)[0, 0] == pytest.approx(-(2.0**2) * 0.17)


def test_the_lever_arm_gives_alpha_cross_l():
    accel = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 100.0]])  # alpha_z
    l = np.array([[0.17, 0.0, 0.0]])
    y_axis = np.array([[0.0, 1.0, 0.0]])
    assert specific_force(accel, np.zeros((1, 3)), np.zeros((1, 3)), l, y_axis)[0, 0] == pytest.approx(17.0)


def test_a_plate_pitched_about_y_sees_minus_g_times_the_pitch_along_x():
    phi = 2e-3
    R = rotation_matrix(np.array([0.0, phi, 0.0]))
    gravity_plate = (R.T @ np.array([0.0, 0.0, -GRAVITY_MPS2]))[None]
    reading = specific_force(np.zeros((1, 6)), np.zeros((1, 3)), gravity_plate, np.zeros((1, 3)), X_AXIS)
    assert reading[0, 0] == pytest.approx(-GRAVITY_MPS2 * math.sin(phi), rel=1e-9)
    z = specific_force(
        np.zeros((1, 6)), np.zeros((1, 3)), gravity_plate, np.zeros((1, 3)), np.array([[0, 0, 1.0]])
    )
    assert z[0, 0] == pytest.approx(GRAVITY_MPS2 * math.cos(phi))


def quiet_layout(**changes):
    layout = default_device_config().accelerometers
    return dataclasses.replace(layout, **{"noise_mps2": 0.0, "quantisation_mps2": 0.0, **changes})


def test_ac_coupling_removes_the_static_g_and_passes_vibration_with_its_documented_response():
    sensors = AccelerometerArray(quiet_layout(), np.random.default_rng(0), SensorErrors.none())
    f, dt, n = 30.0, 1 / 2100, 2100 * 3
    t = np.arange(n) * dt
    accel = np.zeros((n, 6))
    accel[:, 2] = 5.0 * np.sin(2 * np.pi * f * t)
    gravity = np.tile([0.0, 0.0, -GRAVITY_MPS2], (n, 1))
    y = sensors.read(accel, np.zeros((n, 3)), gravity, dt)[:, 1]  # u1.z
    # At rest the static 1 g is gone; the 30 Hz vibration passes with H(f) of the discrete high-pass.
    last = y[-2100:]
    tt = t[-2100:]
    X = (2j / last.size) * np.sum(last * np.exp(-2j * np.pi * f * tt))
    assert pytest.approx(5.0 * sensors.high_pass_response(f, dt), abs=1e-4) == X
    assert abs(np.angle(sensors.high_pass_response(f, dt))) == pytest.approx(math.atan(0.1 / 30), rel=0.01)
    still = AccelerometerArray(quiet_layout(), np.random.default_rng(0), SensorErrors.none())
    assert np.allclose(still.read(np.zeros((10, 6)), np.zeros((10, 3)), gravity[:10], dt), 0.0, atol=1e-12)


def test_noise_and_quantisation_follow_the_configuration():
    layout = quiet_layout(noise_mps2=0.05, quantisation_mps2=0.0048)
    sensors = AccelerometerArray(layout, np.random.default_rng(1), SensorErrors.none())
    n = 4000
    y = sensors.read(np.zeros((n, 6)), np.zeros((n, 3)), np.tile([0, 0, -GRAVITY_MPS2], (n, 1)), 1 / 2000)
    assert np.allclose(y / 0.0048, np.round(y / 0.0048))
    assert np.std(y) == pytest.approx(0.05, rel=0.05)


def test_default_sensor_errors_are_the_lab_like_gains_tilts_and_bending():
    layout = quiet_layout(ac_coupling_hz=0.0)
    ideal = AccelerometerArray(layout, np.random.default_rng(0), SensorErrors.none())
    real = AccelerometerArray(layout, np.random.default_rng(0))  # default: errors on
    accel = np.array([[1.0, 2.0, 10.0, 5.0, -3.0, 8.0]])
    zero3 = np.zeros((1, 3))
    y_ideal = ideal.read(accel, zero3, zero3, 1e-4)[0]
    y_real = real.read(accel, zero3, zero3, 1e-4)[0]
    gains = np.linalg.norm(real.axis, axis=1)
    assert gains[6] == pytest.approx(0.92) and gains[8] == pytest.approx(1.06)
    tilt = np.degrees(np.arcsin(real.axis[[6, 8], 2] / gains[[6, 8]]))
    assert tilt == pytest.approx([4.0, -4.0])
    # Vertical channels: gain x rigid reading + 2 % of the vertical acceleration, saddle-shaped.
    theta = np.arctan2(real.position[:, 1], real.position[:, 0])
    expect = gains[1::2] * y_ideal[1::2] + 0.02 * np.cos(2 * theta[1::2]) * 10.0
    assert y_real[1::2] == pytest.approx(expect)
    assert SensorErrors.default(6) == SensorErrors.none()  # other layouts: no errors by default
