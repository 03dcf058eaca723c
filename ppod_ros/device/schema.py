"""The device description's data model: frozen dataclasses, one per section of the device YAML.

Read and validated by :mod:`ppod_ros.device.config` (``load_device_config``); docs/device.md lists
every key with its unit and default.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.estimation.layout import AccelerometerLayout

NUM_ACTUATORS = 6
#: The CAN protocol addresses channels with 4 bits and averages at most 16 cycles per summary.
MAX_CHANNELS = 16
MAX_SUMMARY_CYCLES = 16
#: DESIGN.md, device safety: heartbeat checked at least every 10 ms, ramp to zero within 100 ms.
MAX_WATCHDOG_CHECK_S = 0.010
MAX_WATCHDOG_RAMP_S = 0.100
#: The shortest stop ramp (e-stop, watchdog, stopping fault): a faster stop rings the lightly damped
#: flexures past the steady leg excursion (simulated device, spins at 67-96 % of the stroke, 19-40 Hz:
#: 10 ms 1.75x, 20 ms 1.46x, 50 ms 1.036x, 100 ms 1.010x; docs/device.md, "Stops"): only the
#: design's longest ramp keeps a motion near the stroke within it.
MIN_STOP_RAMP_S = 0.100


def frozen_array(arr: np.ndarray) -> np.ndarray:
    """A read-only float copy (the dataclasses are immutable, their arrays too)."""
    arr = np.array(arr, dtype=float)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Geometry:
    """Stewart platform attachment points.

    Attributes
    ----------
    base_points_m : ndarray, shape (6, 3)
        Leg i's base attachment a_i in the base frame (m).
    plate_points_m : ndarray, shape (6, 3)
        Leg i's plate attachment b_i in the plate frame (m).
    home_height_m : float
        Height of the plate origin P above the base frame's origin at the home pose (m).
    """

    base_points_m: np.ndarray
    plate_points_m: np.ndarray
    home_height_m: float


@dataclass(frozen=True, eq=False)
class PlateParams:
    """The moving plate as a rigid body: mass, centre of mass (plate frame) and inertia about it."""

    mass_kg: float
    com_m: np.ndarray  # (3,)
    inertia_kgm2: np.ndarray  # (3, 3), about the centre of mass, plate axes
    radius_m: float


@dataclass(frozen=True)
class ActuatorParams:
    """One voice-coil actuator and its current-mode amplifier (all six are alike)."""

    force_constant_n_per_a: float
    back_emf_v_s_per_m: float
    resistance_ohm: float
    inductance_h: float
    moving_mass_kg: float
    current_loop_bandwidth_hz: float
    thermal_resistance_k_per_w: float
    thermal_time_constant_s: float
    ambient_temperature_c: float


@dataclass(frozen=True)
class FlexureParams:
    """Axial stiffness and damping of each leg's flexure suspension."""

    leg_stiffness_n_per_m: float
    leg_damping_n_s_per_m: float


@dataclass(frozen=True, eq=False)
class Limits:
    """Device limits. A goal that would exceed any of them is rejected whole (DESIGN.md).

    ``contact_margin_mps2`` is the smallest allowed min(g + a_n) over the working disc of radius
    ``working_radius_m``; ``excluded_bands_hz`` (B, 2) are frequency bands (flexure resonances)
    that no harmonic of a goal may fall in; ``max_harmonic`` is the highest harmonic a goal may
    use, ``max_table_harmonic`` (>= it) the highest row of a current table (the goal's harmonics and
    the distortion products the feedback cancels); ``correction_step_a`` bounds one feedback
    correction step per table entry;
    ``start_correction_a`` bounds a goal's starting correction per table entry (the one the feedback
    sends as the goal ramps in: learned for this goal before, or predicted by the learned plant);
    ``plant_model_allowance`` (fraction) is how far the nominal plant's prediction of a corrected
    table's plate-side limits may exceed them when the table is judged on the measured plate motion
    (docs/device.md, "Planning and limits"; 0: judged through the nominal plant alone);
    ``plant_uncertainty`` (gain fraction, phase deg, coupling fraction) bounds how far the real
    plant's drive may differ from the nominal model before the feedback has measured it: a goal's
    table must keep the drive limits (leg stroke, peak coil current, amplifier voltage) for every
    plant within it (docs/device.md, "Goals on a plant not measured yet").
    """

    leg_stroke_m: float
    coil_current_a: float
    coil_temperature_c: float
    amplifier_voltage_v: float
    plate_accel_mps2: float
    plate_angular_accel_radps2: float
    contact_margin_mps2: float
    working_radius_m: float
    frequency_range_hz: tuple[float, float]
    excluded_bands_hz: np.ndarray
    max_harmonic: int
    correction_step_a: float
    start_correction_a: float = 1.0
    max_table_harmonic: int = 10
    plant_model_allowance: float = 0.25
    plant_uncertainty: tuple[float, float, float] = (0.15, 10.0, 0.05)


@dataclass(frozen=True)
class CanSettings:
    """Bus backend and the protocol's node ids and frame rates (docs/can_protocol.md)."""

    interface: str
    channel: str
    bitrate: int
    device_node_id: int
    host_node_id: int
    heartbeat_period_s: float
    status_rate_hz: float
    summary_max_rate_hz: float
    summary_harmonics: int
    raw_frame_rate_hz: float
    bus_load_limit: float
    #: Backend-specific keywords for ``can.Bus`` (``can.options``), as sorted (name, value) pairs.
    options: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class DeviceTiming:
    """The device firmware's safety timing, on the device's own clock."""

    watchdog_timeout_s: float
    watchdog_check_s: float
    watchdog_ramp_s: float
    estop_ramp_s: float
    default_ramp_s: float
    min_ramp_s: float
    min_goal_ramp_s: float = 0.2  # a new goal (a change of motion) is never crossfaded faster than this


@dataclass(frozen=True, eq=False)
class Accelerometers:
    """The plate's accelerometer channels and how the device samples them.

    Attributes
    ----------
    layout : AccelerometerLayout
        Single-axis channels in protocol channel order (positions, unit sensing axes, names), the
        same object the estimator uses (``ppod_ros.estimation.layout``).
    sample_rate_hz, noise_mps2, quantisation_mps2, ac_coupling_hz : float
        Nominal sample rate (the device locks an integer number of samples to each cycle), white
        noise standard deviation per sample, ADC step and the AC-coupling high-pass corner.
    """

    layout: AccelerometerLayout
    sample_rate_hz: float
    noise_mps2: float
    quantisation_mps2: float
    ac_coupling_hz: float

    @property
    def names(self) -> tuple[str, ...]:
        return self.layout.names

    @property
    def position_m(self) -> np.ndarray:
        """(C, 3) channel positions in the plate frame (m)."""
        return self.layout.position_m

    @property
    def axis(self) -> np.ndarray:
        """(C, 3) unit sensing axes in the plate frame."""
        return self.layout.axis

    @property
    def num_channels(self) -> int:
        return len(self.layout.names)


@dataclass(frozen=True)
class Mismatch:
    """How the simulated plant differs from the nominal model (all zero: an exact match).

    ``gain`` (fraction) and ``phase_deg`` bound each actuator's gain and phase error, ``coupling``
    bounds the off-diagonal actuator cross-coupling; draws are uniform within the bounds from the
    simulation seed. ``third_harmonic`` is the fraction of each actuator's fundamental that its
    nonlinearity adds at three times the frequency.
    """

    gain: float
    phase_deg: float
    coupling: float
    third_harmonic: float

    @classmethod
    def zero(cls) -> Mismatch:
        return cls(0.0, 0.0, 0.0, 0.0)

    @property
    def is_zero(self) -> bool:
        return self.gain == 0 and self.phase_deg == 0 and self.coupling == 0 and self.third_harmonic == 0


@dataclass(frozen=True)
class SimSettings:
    """Settings of the simulated device (sim_backend)."""

    seed: int
    control_steps_per_sample: int
    exact_geometry: bool
    idle_frequency_hz: float
    mismatch: Mismatch


@dataclass(frozen=True, eq=False)
class DeviceConfig:
    """A validated, immutable device description (see the module docstring)."""

    name: str
    geometry: Geometry
    plate: PlateParams
    actuators: ActuatorParams
    flexures: FlexureParams
    limits: Limits
    can: CanSettings
    timing: DeviceTiming
    accelerometers: Accelerometers
    sim: SimSettings
    source: str = ""

    def with_mismatch(self, mismatch: Mismatch) -> DeviceConfig:
        """The same device with other simulated plant mismatch (e.g. ``Mismatch.zero()``)."""
        return dataclasses.replace(self, sim=dataclasses.replace(self.sim, mismatch=mismatch))

    def with_can(self, **changes: Any) -> DeviceConfig:
        """The same device with some CAN settings changed (e.g. ``interface="virtual"``)."""
        return dataclasses.replace(self, can=dataclasses.replace(self.can, **changes))

    def replace(self, section: str, **changes: Any) -> DeviceConfig:
        """A copy with fields of one section changed, e.g. ``replace("limits", coil_current_a=3)``."""
        if section not in {f.name for f in dataclasses.fields(self)} or section in ("name", "source"):
            raise ConfigError(f"section: no device config section named {section!r}")
        return dataclasses.replace(self, **{section: dataclasses.replace(getattr(self, section), **changes)})


__all__ = [
    "MAX_CHANNELS",
    "MAX_SUMMARY_CYCLES",
    "MAX_WATCHDOG_CHECK_S",
    "MAX_WATCHDOG_RAMP_S",
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
    "frozen_array",
]
