"""The device description: geometry, actuators, flexures, plate, limits, CAN, sensors, simulation.

One YAML file describes one PPOD (docs/device.md lists every key with its unit and where the
default value comes from). :func:`load_device_config` reads it strictly with
:class:`ppod_ros.config.fields.Fields` (unknown keys, wrong shapes and out-of-range numbers are
errors naming the full key path) into a frozen :class:`DeviceConfig`. The packaged default
(``ppod_ros/data/device.yaml``, identical to the documented lab copy ``config/device.yaml``)
describes a PPOD-sized device with a 0.35 m plate.

Frames: the base frame B has its origin at the centre of the six base attachment points' plane,
z up; the plate frame P (PHYSICS.md) has its origin at the centre of the plate's top surface. At
the home pose P sits at ``(0, 0, geometry.home_height_m)`` in B with parallel axes.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.config.fields import Fields, check_array, load_yaml_file
from ppod_ros.device.schema import (
    MAX_CHANNELS,
    MAX_SUMMARY_CYCLES,
    MAX_WATCHDOG_CHECK_S,
    MAX_WATCHDOG_RAMP_S,
    MIN_STOP_RAMP_S,
    NUM_ACTUATORS,
    Accelerometers,
    ActuatorParams,
    CanSettings,
    DeviceConfig,
    DeviceTiming,
    FlexureParams,
    Geometry,
    Limits,
    Mismatch,
    PlateParams,
    SimSettings,
)
from ppod_ros.device.schema import frozen_array as _frozen
from ppod_ros.errors import ConfigError
from ppod_ros.estimation.layout import AccelerometerLayout
from ppod_ros.motion import MAX_HARMONIC

#: The device counts plate cycles modulo 2^24 (its frames carry the count as a u24); the protocol
#: and the feedback's settling count in cycles share this one definition.
CYCLE_MODULUS = 2**24


# ---------------------------------------------------------------------------------------- parsing
def _positive(f: Fields, key: str, unit: str, default: Any = ...) -> float:
    args = () if default is ... else (default,)
    return f.number(key, *args, min_value=0.0, exclusive_min=True, unit=unit)


def _geometry(f: Fields) -> Geometry:
    base = f.array("base_points_m", shape=(NUM_ACTUATORS, 3), unit="m")
    plate = f.array("plate_points_m", shape=(NUM_ACTUATORS, 3), unit="m")
    height = _positive(f, "home_height_m", "m")
    f.finish()
    for name, pts in (("base_points_m", base), ("plate_points_m", plate)):
        d = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(NUM_ACTUATORS)
        if np.min(d) < 1e-3:
            raise ConfigError(f"{f.key_path(name)}: attachment points must be at least 1 mm apart")
    legs = plate + [0.0, 0.0, height] - base
    length = np.linalg.norm(legs, axis=1)
    if np.min(length) < 1e-2:
        raise ConfigError(
            f"{f.path}: every leg must be at least 10 mm long at the home pose, got {length.tolist()}"
        )
    n = legs / length[:, None]
    J = np.hstack([n, np.cross(plate, n)])
    if np.linalg.cond(J) > 1e6:
        raise ConfigError(
            f"{f.path}: the legs are (nearly) singular at the home pose: the plate is not fully "
            "constrained by the six legs"
        )
    return Geometry(_frozen(base), _frozen(plate), height)


def _plate(f: Fields) -> PlateParams:
    mass = _positive(f, "mass_kg", "kg")
    com = f.array("com_m", shape=(3,), unit="m")
    raw = f.raw("inertia_kgm2")
    arr = np.asarray(raw, dtype=object)
    if arr.shape == (3,):
        inertia = np.diag(check_array(raw, f.key_path("inertia_kgm2"), shape=(3,), unit="kg m^2"))
    else:
        inertia = check_array(raw, f.key_path("inertia_kgm2"), shape=(3, 3), unit="kg m^2")
    radius = _positive(f, "radius_m", "m")
    f.finish()
    if not np.allclose(inertia, inertia.T, rtol=1e-9, atol=1e-12) or np.min(np.linalg.eigvalsh(inertia)) <= 0:
        raise ConfigError(
            f"{f.key_path('inertia_kgm2')}: must be symmetric positive definite, got {inertia.tolist()}"
        )
    return PlateParams(mass, _frozen(com), _frozen(inertia), radius)


def _actuators(f: Fields) -> ActuatorParams:
    out = ActuatorParams(
        force_constant_n_per_a=_positive(f, "force_constant_n_per_a", "N/A"),
        back_emf_v_s_per_m=_positive(f, "back_emf_v_s_per_m", "V s/m"),
        resistance_ohm=_positive(f, "resistance_ohm", "ohm"),
        inductance_h=_positive(f, "inductance_h", "H"),
        moving_mass_kg=f.number("moving_mass_kg", min_value=0.0, unit="kg"),
        current_loop_bandwidth_hz=_positive(f, "current_loop_bandwidth_hz", "Hz"),
        thermal_resistance_k_per_w=_positive(f, "thermal_resistance_k_per_w", "K/W"),
        thermal_time_constant_s=_positive(f, "thermal_time_constant_s", "s"),
        ambient_temperature_c=f.number("ambient_temperature_c", min_value=-50.0, max_value=80.0, unit="degC"),
    )
    f.finish()
    return out


def _flexures(f: Fields) -> FlexureParams:
    out = FlexureParams(
        _positive(f, "leg_stiffness_n_per_m", "N/m"),
        f.number("leg_damping_n_s_per_m", min_value=0.0, unit="N s/m"),
    )
    f.finish()
    return out


def _limits(f: Fields, plate_radius_m: float, ambient_c: float) -> Limits:
    fr = f.array("frequency_range_hz", shape=(2,), min_value=0.0, unit="Hz")
    if not 0 < fr[0] < fr[1]:
        raise ConfigError(
            f"{f.key_path('frequency_range_hz')}: expected [min, max] with 0 < min < max, got {fr.tolist()}"
        )
    raw_bands = f.raw("excluded_bands_hz", [])
    if raw_bands is None or (isinstance(raw_bands, list) and not raw_bands):
        bands = np.zeros((0, 2))
    else:
        bands = check_array(
            raw_bands, f.key_path("excluded_bands_hz"), shape=(None, 2), min_value=0.0, unit="Hz"
        )
        if np.any(bands[:, 0] >= bands[:, 1]):
            raise ConfigError(
                f"{f.key_path('excluded_bands_hz')}: each band must be [low, high] with low < high, "
                f"got {bands.tolist()}"
            )
    out = Limits(
        leg_stroke_m=_positive(f, "leg_stroke_m", "m"),
        coil_current_a=_positive(f, "coil_current_a", "A"),
        coil_temperature_c=f.number(
            "coil_temperature_c", min_value=ambient_c, exclusive_min=True, unit="degC"
        ),
        amplifier_voltage_v=_positive(f, "amplifier_voltage_v", "V"),
        plate_accel_mps2=_positive(f, "plate_accel_mps2", "m/s^2"),
        plate_angular_accel_radps2=_positive(f, "plate_angular_accel_radps2", "rad/s^2"),
        contact_margin_mps2=f.number("contact_margin_mps2", min_value=0.0, unit="m/s^2"),
        working_radius_m=f.number(
            "working_radius_m", min_value=0.0, max_value=plate_radius_m, exclusive_min=True, unit="m"
        ),
        frequency_range_hz=(float(fr[0]), float(fr[1])),
        excluded_bands_hz=_frozen(bands),
        max_harmonic=f.integer("max_harmonic", min_value=1, max_value=MAX_HARMONIC),
        correction_step_a=_positive(f, "correction_step_a", "A"),
        start_correction_a=f.number("start_correction_a", 1.0, min_value=0.0, exclusive_min=True, unit="A"),
        max_table_harmonic=f.integer("max_table_harmonic", MAX_HARMONIC, min_value=1, max_value=MAX_HARMONIC),
        plant_model_allowance=f.number("plant_model_allowance", 0.25, min_value=0.0, max_value=1.0, unit="1"),
        plant_uncertainty=_plant_uncertainty(f),
    )
    if out.max_table_harmonic < out.max_harmonic:
        raise ConfigError(f"{f.key_path('max_table_harmonic')}: must be >= max_harmonic ({out.max_harmonic}), "
                          f"got {out.max_table_harmonic}")
    f.finish()
    return out


def _plant_uncertainty(f: Fields) -> tuple[float, float, float]:
    """``limits.plant_uncertainty``: {gain, phase_deg, coupling}, each optional (defaults 0.15, 10, 0.05)."""
    u = f.sub("plant_uncertainty", {})
    if u is None:
        u = Fields({}, f.key_path("plant_uncertainty"))
    out = (
        u.number("gain", 0.15, min_value=0.0, max_value=0.49, unit="1"),
        u.number("phase_deg", 10.0, min_value=0.0, max_value=60.0, unit="deg"),
        u.number("coupling", 0.05, min_value=0.0, max_value=0.49, unit="1"),
    )
    u.finish()
    return out


def _stop_ramp(f: Fields, key: str) -> float:
    """A stop ramp (``timing.estop_ramp_s``, ``timing.watchdog_ramp_s``): exactly the design's 0.1 s."""
    value = f.number(key, unit="s")
    if not MIN_STOP_RAMP_S - 1e-12 <= value <= MAX_WATCHDOG_RAMP_S + 1e-12:
        raise ConfigError(
            f"{f.key_path(key)}: must be {MIN_STOP_RAMP_S:g} s (a faster stop rings the flexures past the leg "
            f"stroke: 50 ms 1.036x, 20 ms 1.46x; DESIGN.md allows at most {MAX_WATCHDOG_RAMP_S:g} s), got {value:g}"
        )
    return value


def _can_options(f: Fields) -> tuple[tuple[str, Any], ...]:
    """``can.options``: keywords passed unchanged to python-can's ``can.Bus`` (scalars or lists)."""
    value = f.raw("options", {})
    if value is None:
        return ()
    if not isinstance(value, dict) or not all(isinstance(k, str) and k.isidentifier() for k in value):
        raise ConfigError(f"{f.key_path('options')}: expected a mapping of python-can keyword names to values, "
                          f"e.g. {{tty_baudrate: 115200}}, got {value!r}")
    for k, v in value.items():
        if not isinstance(v, (str, int, float, bool, list)):
            raise ConfigError(f"{f.key_path('options')}.{k}: expected a number, string, boolean or list, got {v!r}")
    reserved = sorted(set(value) & {"interface", "channel", "bitrate"})
    if reserved:
        raise ConfigError(f"{f.key_path('options')}: {', '.join(reserved)} belong in can.{reserved[0]}, not options")
    return tuple(sorted(value.items()))


def _can(f: Fields) -> CanSettings:
    out = CanSettings(
        interface=f.string("interface"),
        channel=str(f.raw("channel")),
        bitrate=f.integer("bitrate", min_value=10_000, max_value=1_000_000),
        device_node_id=f.integer("device_node_id", min_value=1, max_value=15),
        host_node_id=f.integer("host_node_id", min_value=0, max_value=15),
        heartbeat_period_s=_positive(f, "heartbeat_period_s", "s"),
        status_rate_hz=_positive(f, "status_rate_hz", "Hz"),
        summary_max_rate_hz=_positive(f, "summary_max_rate_hz", "Hz"),
        summary_harmonics=f.integer("summary_harmonics", min_value=1, max_value=MAX_HARMONIC),
        raw_frame_rate_hz=_positive(f, "raw_frame_rate_hz", "Hz"),
        bus_load_limit=f.number("bus_load_limit", min_value=0.0, max_value=1.0, exclusive_min=True),
        options=_can_options(f),
    )
    f.finish()
    if not out.interface:
        raise ConfigError(
            f"{f.key_path('interface')}: must name a bus backend (virtual, remote, socketcan, ...)"
        )
    return out


def _timing(f: Fields, heartbeat_period_s: float) -> DeviceTiming:
    out = DeviceTiming(
        watchdog_timeout_s=_positive(f, "watchdog_timeout_s", "s"),
        watchdog_check_s=f.number(
            "watchdog_check_s", min_value=1e-4, max_value=MAX_WATCHDOG_CHECK_S, unit="s"
        ),
        watchdog_ramp_s=_stop_ramp(f, "watchdog_ramp_s"),
        estop_ramp_s=_stop_ramp(f, "estop_ramp_s"),
        default_ramp_s=_positive(f, "default_ramp_s", "s"),
        min_ramp_s=f.number("min_ramp_s", min_value=1e-3, unit="s"),
        min_goal_ramp_s=f.number("min_goal_ramp_s", 0.2, min_value=1e-3, unit="s"),
    )
    f.finish()
    if out.watchdog_timeout_s < 2 * heartbeat_period_s:
        raise ConfigError(
            f"{f.key_path('watchdog_timeout_s')}: must be at least two heartbeat periods "
            f"({2 * heartbeat_period_s:g} s), got {out.watchdog_timeout_s:g}"
        )
    if out.default_ramp_s < out.min_ramp_s:
        raise ConfigError(f"{f.key_path('default_ramp_s')}: must be >= min_ramp_s ({out.min_ramp_s:g} s)")
    if not out.min_ramp_s <= out.min_goal_ramp_s <= out.default_ramp_s:
        raise ConfigError(f"{f.key_path('min_goal_ramp_s')}: must be within min_ramp_s .. default_ramp_s "
                          f"({out.min_ramp_s:g} .. {out.default_ramp_s:g} s), got {out.min_goal_ramp_s:g}")
    return out


def _accelerometers(f: Fields, key: str, sampling: Fields) -> Accelerometers:
    # One schema for the device and the estimator: AccelerometerLayout reads the channels.
    layout = AccelerometerLayout.from_dict(f.raw(key), f.key_path(key))
    if not 6 <= len(layout.names) <= MAX_CHANNELS:
        raise ConfigError(f"{f.key_path(key)}.channels: need 6 to {MAX_CHANNELS} channels, got {len(layout.names)}")
    out = Accelerometers(
        layout=layout,
        sample_rate_hz=_positive(sampling, "sample_rate_hz", "Hz"),
        noise_mps2=sampling.number("noise_mps2", min_value=0.0, unit="m/s^2"),
        quantisation_mps2=sampling.number("quantisation_mps2", min_value=0.0, unit="m/s^2"),
        ac_coupling_hz=sampling.number("ac_coupling_hz", min_value=0.0, unit="Hz"),
    )
    sampling.finish()
    return out


def _sim(f: Fields) -> SimSettings:
    m = f.sub("mismatch")
    mismatch = Mismatch(
        gain=m.number("gain", min_value=0.0, max_value=0.9),
        phase_deg=m.number("phase_deg", min_value=0.0, max_value=90.0, unit="deg"),
        coupling=m.number("coupling", min_value=0.0, max_value=0.5),
        third_harmonic=m.number("third_harmonic", min_value=0.0, max_value=0.5),
    )
    m.finish()
    out = SimSettings(
        seed=f.integer("seed", min_value=0),
        control_steps_per_sample=f.integer("control_steps_per_sample", min_value=1, max_value=64),
        exact_geometry=f.boolean("exact_geometry"),
        idle_frequency_hz=_positive(f, "idle_frequency_hz", "Hz"),
        mismatch=mismatch,
    )
    f.finish()
    return out


def device_config_from_dict(data: Mapping[str, Any], source: str = "") -> DeviceConfig:
    """Validate a device-description mapping (the YAML's top level) into a :class:`DeviceConfig`."""
    f = Fields(data, "")
    name = f.string("name", "ppod")
    plate = _plate(f.sub("plate"))
    actuators = _actuators(f.sub("actuators"))
    can = _can(f.sub("can"))
    cfg = DeviceConfig(
        name=name,
        geometry=_geometry(f.sub("geometry")),
        plate=plate,
        actuators=actuators,
        flexures=_flexures(f.sub("flexures")),
        limits=_limits(f.sub("limits"), plate.radius_m, actuators.ambient_temperature_c),
        can=can,
        timing=_timing(f.sub("timing"), can.heartbeat_period_s),
        accelerometers=_accelerometers(f, "accelerometers", f.sub("accelerometer_sampling")),
        sim=_sim(f.sub("sim")),
        source=source,
    )
    f.finish()
    if cfg.limits.frequency_range_hz[1] > MAX_SUMMARY_CYCLES * cfg.can.summary_max_rate_hz:
        raise ConfigError(
            f"limits.frequency_range_hz: above {MAX_SUMMARY_CYCLES} x can.summary_max_rate_hz = "
            f"{MAX_SUMMARY_CYCLES * cfg.can.summary_max_rate_hz:g} Hz the accelerometer summaries (at most "
            f"{MAX_SUMMARY_CYCLES} cycles each) would exceed their configured rate"
        )
    if cfg.limits.frequency_range_hz[0] <= 0 or cfg.sim.idle_frequency_hz > cfg.limits.frequency_range_hz[1]:
        raise ConfigError("sim.idle_frequency_hz: must lie within limits.frequency_range_hz")
    if not math.isfinite(cfg.accelerometers.sample_rate_hz):
        raise ConfigError("accelerometer_sampling.sample_rate_hz: must be finite")
    return cfg


DEFAULT_DEVICE_FILE = "device.yaml"


def default_device_config_path() -> Path:
    """Path of the packaged default device description (``ppod_ros/data/device.yaml``)."""
    return Path(str(resources.files("ppod_ros") / "data" / DEFAULT_DEVICE_FILE))


def load_device_config(path: str | Path | None = None) -> DeviceConfig:
    """Load and validate a device YAML; ``None`` loads the packaged default.

    Raises
    ------
    ConfigError
        Naming the file and the full key path of the first problem found.
    """
    if path is None:
        return default_device_config()
    data = load_yaml_file(path, "device description")
    try:
        return device_config_from_dict(data, str(path))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


@functools.cache
def default_device_config() -> DeviceConfig:
    """The packaged default device (cached: the config is immutable)."""
    path = default_device_config_path()
    data = load_yaml_file(path, "device description")
    return device_config_from_dict(data, str(path))


__all__ = [
    "CYCLE_MODULUS",
    "NUM_ACTUATORS",
    "Accelerometers",
    "ActuatorParams",
    "CanSettings",
    "DeviceConfig",
    "DeviceTiming",
    "FlexureParams",
    "Geometry",
    "Limits",
    "Mismatch",
    "PlateParams",
    "SimSettings",
    "default_device_config",
    "default_device_config_path",
    "device_config_from_dict",
    "load_device_config",
]
