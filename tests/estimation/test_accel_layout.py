import math

import numpy as np
import pytest
import yaml

from ppod_ros.errors import ConfigError
from ppod_ros.estimation import AccelerometerLayout


def _tangential_and_vertical(angles_deg, radius=0.17, z=-0.025):
    names, pos, ax = [], [], []
    for deg in angles_deg:
        th = math.radians(deg)
        p = [radius * math.cos(th), radius * math.sin(th), z]
        names += [f"a{deg}.t", f"a{deg}.z"]
        pos += [p, p]
        ax += [[-math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]]
    return names, np.array(pos), np.array(ax)


def test_default_layout_is_physics_md_six_dual_axis_units_and_well_conditioned():
    lay = AccelerometerLayout.default()
    assert lay.num_channels == 12
    np.testing.assert_allclose(np.hypot(lay.position_m[:, 0], lay.position_m[:, 1]), 0.17)
    np.testing.assert_allclose(lay.position_m[:, 2], -0.025)
    angles = np.degrees(np.arctan2(lay.position_m[::2, 1], lay.position_m[::2, 0])) % 360
    np.testing.assert_allclose(angles, [10, 110, 130, 230, 250, 350])
    np.testing.assert_allclose(lay.axis[1::2], [[0, 0, 1]] * 6)
    assert lay.observability().condition < 5


def test_measurement_row_is_e_and_l_cross_e_and_matches_a_direct_evaluation():
    lay = AccelerometerLayout.default()
    rng = np.random.default_rng(3)
    u = rng.normal(size=6)
    direct = [e @ (u[:3] + np.cross(u[3:], l)) for l, e in zip(lay.position_m, lay.axis)]
    np.testing.assert_allclose(lay.measurement_matrix() @ u, direct, atol=1e-12)


def test_tilted_gravity_adds_g_over_k_omega_squared_to_the_lever_arm_along_z():
    lay = AccelerometerLayout.default()
    w = 2 * math.pi * 30
    H0, H1 = lay.measurement_matrix(), lay.measurement_matrix(w, 9.81)
    c = 9.81 / w**2
    expected = np.cross(np.array([0, 0, c]), lay.axis)
    np.testing.assert_allclose(H1[:, 3:] - H0[:, 3:], expected, atol=1e-15)
    np.testing.assert_array_equal(H1[:, :3], H0[:, :3])


def test_layout_loads_from_yaml_with_multi_axis_units_and_round_trips(tmp_path):
    text = """
    accelerometers:
      max_condition: 500
      channels:
        - {name: u1, position_m: [0.17, 0, -0.025], axes: {t: [0, 1, 0], z: [0, 0, 1]}, full_scale_mps2: 160}
        - {name: u2, position_m: [-0.085, 0.147, -0.025], axes: {t: [-0.866, -0.5, 0], z: [0, 0, 1]}}
        - {name: u3, position_m: [-0.085, -0.147, -0.025], axes: {t: [0.866, -0.5, 0], z: [0, 0, 1]}}
    """
    path = tmp_path / "device.yaml"
    path.write_text(text)
    lay = AccelerometerLayout.from_yaml(path)
    assert lay.names == ("u1.t", "u1.z", "u2.t", "u2.z", "u3.t", "u3.z")
    assert lay.full_scale_mps2[0] == 160 and math.isinf(lay.full_scale_mps2[2])
    assert lay.max_condition == 500
    again = AccelerometerLayout.from_dict(yaml.safe_load(yaml.safe_dump(lay.to_dict())))
    assert again.names == lay.names
    np.testing.assert_allclose(again.axis, lay.axis)
    np.testing.assert_allclose(again.full_scale_mps2, lay.full_scale_mps2)


@pytest.mark.parametrize(
    ("patch", "needle"),
    [
        ({"colour": "red"}, "channels[0].colour"),
        ({"axis": [0, 0, 2]}, "unit vector"),
        ({"position_m": [0, 0]}, "channels[0].position_m: expected shape 3"),
        ({"axis": [0, 0, float("nan")]}, "finite"),
        ({"axes": {"z": [0, 0, 1]}}, "exactly one of 'axis'"),
    ],
)
def test_layout_yaml_is_validated_strictly_naming_the_key(patch, needle):
    names, pos, ax = _tangential_and_vertical([0, 120, 240])
    channels = [{"name": n, "position_m": p.tolist(), "axis": a.tolist()} for n, p, a in zip(names, pos, ax)]
    channels[0].update(patch)
    with pytest.raises(ConfigError, match=needle.replace("[", r"\[").replace("]", r"\]")):
        AccelerometerLayout.from_dict({"channels": channels})


def test_layout_of_only_vertical_channels_is_rejected_naming_the_unobservable_in_plane_motion():
    names, pos, ax = _tangential_and_vertical([0, 60, 120, 180, 240, 300])
    vertical = slice(1, None, 2)
    with pytest.raises(ConfigError, match="cannot determine all six") as info:
        AccelerometerLayout(tuple(names[vertical]), pos[vertical], ax[vertical])
    message = str(info.value)
    assert any(axis in message for axis in ("ddpx", "ddpy", "alpha_z"))
    assert "alpha_x" not in message.split("unobservable:")[1].split("(")[0]


def test_layout_whose_tangential_channels_are_all_at_one_angle_pair_cannot_see_alpha_z_apart_from_ddpy():
    # Two units on the x axis, both tangential axes along y: alpha_z and ddpy are separable, ddpx is not seen.
    names = ["a.t", "a.z", "b.t", "b.z", "c.z", "d.z"]
    pos = np.array([[0.17, 0, 0], [0.17, 0, 0], [-0.17, 0, 0], [-0.17, 0, 0], [0, 0.17, 0], [0, -0.17, 0]])
    ax = np.array([[0, 1, 0], [0, 0, 1], [0, -1, 0], [0, 0, 1], [0, 0, 1], [0, 0, 1]])
    with pytest.raises(ConfigError, match=r"unobservable: 1\.00 ddpx"):
        AccelerometerLayout(tuple(names), pos, ax)


def test_layout_with_fewer_than_six_channels_or_duplicate_names_is_rejected():
    names, pos, ax = _tangential_and_vertical([0, 120])
    with pytest.raises(ConfigError, match="need at least 6"):
        AccelerometerLayout(tuple(names), pos, ax)
    names, pos, ax = _tangential_and_vertical([0, 120, 240])
    names[1] = names[0]
    with pytest.raises(ConfigError, match="duplicate channel names"):
        AccelerometerLayout(tuple(names), pos, ax)
