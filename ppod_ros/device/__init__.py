"""The device description: a validated, immutable :class:`DeviceConfig` (schema) loaded from YAML (config)."""

from ppod_ros.device.config import (
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
    default_device_config,
    default_device_config_path,
    device_config_from_dict,
    load_device_config,
)

__all__ = [
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
