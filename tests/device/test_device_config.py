"""The device description: the default loads, the lab copy matches it, and errors name the key."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from ppod_ros.device import Mismatch, default_device_config, default_device_config_path, load_device_config
from ppod_ros.device.config import device_config_from_dict
from ppod_ros.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]


def default_dict():
    return yaml.safe_load(default_device_config_path().read_text())


def test_the_packaged_default_describes_a_ppod_sized_device():
    c = default_device_config()
    assert c.plate.radius_m * 2 == pytest.approx(0.35)
    assert c.geometry.base_points_m.shape == (6, 3) and c.geometry.plate_points_m.shape == (6, 3)
    assert c.accelerometers.num_channels == 12
    assert c.accelerometers.names[:2] == ("u1.t", "u1.z")
    assert c.limits.working_radius_m == 0.08
    assert c.can.bitrate == 1_000_000
    assert c.timing.watchdog_timeout_s == 0.15 and c.timing.watchdog_check_s <= 0.01
    assert c.timing.watchdog_ramp_s <= 0.1


def test_accelerometer_layout_is_physics_md_default():
    c = default_device_config().accelerometers
    angles = np.deg2rad([10, 110, 130, 230, 250, 350])
    pos = c.position_m[0::2]
    assert np.allclose(np.hypot(pos[:, 0], pos[:, 1]), 0.17, atol=1e-6)
    assert np.allclose(pos[:, 2], -0.025)
    assert np.allclose(np.arctan2(pos[:, 1], pos[:, 0]) % (2 * np.pi), angles % (2 * np.pi), atol=1e-5)
    tangential = np.stack([-np.sin(angles), np.cos(angles), 0 * angles], axis=1)
    assert np.allclose(c.axis[0::2], tangential, atol=1e-5)
    assert np.allclose(c.axis[1::2], [0, 0, 1])


def test_lab_copy_config_device_yaml_equals_the_packaged_default():
    lab = load_device_config(REPO / "config" / "device.yaml")
    ref = default_device_config()
    assert yaml.safe_load((REPO / "config" / "device.yaml").read_text()) == default_dict()
    assert lab.name == ref.name


def test_config_is_immutable():
    c = default_device_config()
    with pytest.raises((AttributeError, TypeError)):
        c.name = "x"
    with pytest.raises(ValueError):
        c.geometry.base_points_m[0, 0] = 1.0


def test_with_mismatch_zero_returns_an_exact_plant_config():
    c = default_device_config().with_mismatch(Mismatch.zero())
    assert c.sim.mismatch.is_zero
    assert not default_device_config().sim.mismatch.is_zero


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (("plate", "mass_kg"), -1.0, "plate.mass_kg: must be > 0"),
        (("plate", "inertia_kgm2"), [1.0, 2.0], "plate.inertia_kgm2: expected shape 3 x 3"),
        (("actuators", "resistance_ohm"), float("nan"), "actuators.resistance_ohm: must be finite"),
        (("limits", "coil_current_a"), "lots", "limits.coil_current_a: expected a number"),
        (("timing", "watchdog_check_s"), 0.02, "timing.watchdog_check_s: must be <= 0.01"),
        (("timing", "watchdog_ramp_s"), 0.2, "timing.watchdog_ramp_s: must be 0.1 s"),
        # A faster stop rings the flexures past the leg stroke (docs/device.md, "Stops").
        (("timing", "watchdog_ramp_s"), 0.05, "timing.watchdog_ramp_s: must be 0.1 s (a faster stop rings"),
        (("timing", "estop_ramp_s"), 0.001, "timing.estop_ramp_s: must be 0.1 s (a faster stop rings"),
        (("timing", "estop_ramp_s"), 0.099, "timing.estop_ramp_s: must be 0.1 s"),
        (("limits", "plant_uncertainty"), {"gain": 0.6}, "limits.plant_uncertainty.gain: must be <= 0.49"),
        (("limits", "plant_uncertainty"), {"phase": 5}, "limits.plant_uncertainty"),
        (("can", "device_node_id"), 16, "can.device_node_id: must be <= 15"),
        (("limits", "excluded_bands_hz"), [[20.0, 10.0]], "limits.excluded_bands_hz: each band must be"),
        (("limits", "frequency_range_hz"), [50.0, 10.0], "limits.frequency_range_hz"),
        (("limits", "max_harmonic"), 11, "limits.max_harmonic: must be <= 10"),
        (("limits", "max_table_harmonic"), 4, "limits.max_table_harmonic: must be >= max_harmonic"),
        (("limits", "start_correction_a"), 0.0, "limits.start_correction_a: must be > 0"),
        (("limits", "plant_model_allowance"), -0.1, "limits.plant_model_allowance: must be >= 0"),
        (("limits", "plant_model_allowance"), 1.5, "limits.plant_model_allowance: must be <= 1"),
        (("sim", "mismatch", "gain"), 2.0, "sim.mismatch.gain: must be <= 0.9"),
        (("limits", "frequency_range_hz"), [5.0, 600.0], "would exceed their configured rate"),
    ],
)
def test_invalid_values_are_rejected_naming_the_key(path, value, message):
    data = default_dict()
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace("[", r"\[")):
        device_config_from_dict(data)


def test_unknown_keys_are_rejected_naming_them():
    data = default_dict()
    data["limits"]["leg_strok_m"] = 0.001
    with pytest.raises(ConfigError, match="limits.leg_strok_m"):
        device_config_from_dict(data)


def test_missing_keys_are_rejected_naming_them():
    data = default_dict()
    del data["actuators"]["inductance_h"]
    with pytest.raises(ConfigError, match="actuators.inductance_h: required key is missing"):
        device_config_from_dict(data)


def test_collapsed_geometry_is_rejected():
    data = default_dict()
    data["geometry"]["plate_points_m"] = [[0.1, 0.0, -0.03]] * 3 + [[0.0, 0.1, -0.03]] * 3
    with pytest.raises(
        ConfigError, match="geometry.plate_points_m: attachment points must be at least 1 mm apart"
    ):
        device_config_from_dict(data)


def test_legs_that_cannot_hold_the_plate_are_rejected():
    data = default_dict()
    # All six legs vertical: nothing resists sliding or yaw.
    pts = [[0.15 * np.cos(a), 0.15 * np.sin(a)] for a in np.deg2rad([0, 60, 120, 180, 240, 300])]
    data["geometry"]["base_points_m"] = [[x, y, 0.0] for x, y in pts]
    data["geometry"]["plate_points_m"] = [[x, y, -0.03] for x, y in pts]
    with pytest.raises(ConfigError, match="singular"):
        device_config_from_dict(data)


def test_accelerometers_that_cannot_see_six_components_are_rejected():
    data = default_dict()
    for ch in data["accelerometers"]["channels"]:
        ch["axes"] = {"z": [0.0, 0.0, 1.0]}
        ch["position_m"] = [0.1, 0.0, 0.0]
    with pytest.raises(ConfigError, match="need 6 to 16 channels|cannot determine"):
        device_config_from_dict(data)


def test_load_device_config_names_the_file_in_errors(tmp_path):
    data = default_dict()
    data["can"]["bitrate"] = 5
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"bad.yaml: can.bitrate: must be >= 10000"):
        load_device_config(path)
    with pytest.raises(ConfigError, match="device description file"):
        load_device_config(tmp_path / "missing.yaml")


def test_the_excluded_band_covers_every_suspension_mode_of_the_default_device():
    from ppod_ros.actuation.plant import NominalPlant

    c = default_device_config()
    modes = NominalPlant(c).modes()
    assert len(modes) == 6
    for m in modes:
        assert any(lo < m.frequency_hz < hi for lo, hi in c.limits.excluded_bands_hz), m
