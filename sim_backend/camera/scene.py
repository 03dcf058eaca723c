"""What the simulated camera sees and how its sensor responds.

Plain, validated dataclasses: the parts (outline, pose, height, reflectance), occluders, the
lighting (overall brightness, a linear gradient and vignetting; a function of time may replace a
fixed lighting to test changes), the scene's reflectances and the sensor (exposure, blur, noise).
Ground truth comes back with each frame as :class:`PartTruth`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ppod_ros.config.fields import check_array, check_number
from ppod_ros.errors import ConfigError
from ppod_ros.parts import Footprint, PointPart, RigidPart


@dataclass(frozen=True, eq=False)
class RenderPart:
    """A part as the camera sees it: its top face at ``height_m`` above the plate.

    Parameters
    ----------
    label : str
        Part type name (ground truth only).
    outline : ndarray, shape (M, 2)
        Outline in the body frame (m), counter-clockwise; the body origin is the pose's point.
    x_m, y_m, theta_rad : float
        Pose in the plate frame.
    height_m : float
        Height of the visible top face above the plate surface (m).
    reflectance : float
        Top-face reflectance in [0, 1].
    """

    label: str
    outline: np.ndarray
    x_m: float
    y_m: float
    theta_rad: float
    height_m: float = 0.0
    reflectance: float = 0.85

    def __post_init__(self) -> None:
        outline = check_array(self.outline, f"part {self.label!r} outline", shape=(None, 2), unit="m")
        if len(outline) < 3:
            raise ConfigError(f"part {self.label!r} outline: needs at least 3 vertices, got {len(outline)}")
        object.__setattr__(self, "outline", outline)
        for name in ("x_m", "y_m", "theta_rad"):
            object.__setattr__(self, name, check_number(getattr(self, name), f"part {self.label!r} {name}"))
        object.__setattr__(
            self,
            "height_m",
            check_number(self.height_m, f"part {self.label!r} height_m", min_value=0.0, unit="m"),
        )
        object.__setattr__(
            self,
            "reflectance",
            check_number(self.reflectance, f"part {self.label!r} reflectance", min_value=0.0, max_value=1.0),
        )

    @classmethod
    def of(
        cls,
        label: str,
        shape: Footprint | PointPart | RigidPart,
        pose: tuple[float, float, float],
        height_m: float = 0.0,
        reflectance: float = 0.85,
    ) -> RenderPart:
        """From a footprint or a part (its footprint, or a rigid part's contact triangle)."""
        if isinstance(shape, Footprint):
            outline = shape.outline(n_disk=256) if shape.kind == "disk" else shape.outline()
        elif isinstance(shape, RigidPart):
            fp = shape.footprint
            outline = fp.outline(n_disk=256) if fp is not None and fp.kind == "disk" else shape.outline()
        elif isinstance(shape, PointPart):
            if shape.footprint is None:
                raise ConfigError(f"part {label!r}: a point part needs a footprint to be rendered")
            fp = shape.footprint
            outline = fp.outline(n_disk=256) if fp.kind == "disk" else fp.outline()
        else:
            raise ConfigError(
                f"part {label!r}: expected a Footprint, PointPart or RigidPart, got {type(shape).__name__}"
            )
        return cls(label, outline, pose[0], pose[1], pose[2], height_m, reflectance)

    def plate_outline(self) -> np.ndarray:
        """Outline (M, 2) placed at the pose, plate frame (m)."""
        c, s = math.cos(self.theta_rad), math.sin(self.theta_rad)
        return self.outline @ np.array([[c, s], [-s, c]]) + np.array([self.x_m, self.y_m])


@dataclass(frozen=True, eq=False)
class Occluder:
    """Something between the camera and the plate (a hand, a tool): a polygon (M, 2) in the plate
    frame at ``height_m`` above it, with its reflectance."""

    polygon: np.ndarray
    height_m: float = 0.05
    reflectance: float = 0.1

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "polygon", check_array(self.polygon, "occluder polygon", shape=(None, 2), unit="m")
        )
        object.__setattr__(self, "height_m", check_number(self.height_m, "occluder height_m", min_value=0.0))
        object.__setattr__(
            self,
            "reflectance",
            check_number(self.reflectance, "occluder reflectance", min_value=0.0, max_value=1.0),
        )


@dataclass(frozen=True)
class Lighting:
    """Illumination over the image, as a gain on the scene's reflectance.

    gain(u, v) = brightness * (1 + gradient_u * (u - cx) / width + gradient_v * (v - cy) / height)
                 * (1 - vignetting * r^2), r = distance from the image centre / half-diagonal.
    """

    brightness: float = 1.0
    gradient_u: float = 0.25
    gradient_v: float = -0.10
    vignetting: float = 0.15

    def __post_init__(self) -> None:
        check_number(self.brightness, "lighting.brightness", min_value=0.0)
        check_number(self.gradient_u, "lighting.gradient_u", min_value=-1.0, max_value=1.0)
        check_number(self.gradient_v, "lighting.gradient_v", min_value=-1.0, max_value=1.0)
        check_number(self.vignetting, "lighting.vignetting", min_value=0.0, max_value=0.9)

    def gain_map(self, width: int, height: int) -> np.ndarray:
        """The gain (height, width), float32."""
        u = (np.arange(width, dtype=np.float32) - (width - 1) / 2) / width
        v = (np.arange(height, dtype=np.float32) - (height - 1) / 2) / height
        lin = 1.0 + self.gradient_u * u[None, :] + self.gradient_v * v[:, None]
        r2 = (u[None, :] ** 2 + v[:, None] ** 2) / 0.5
        return (self.brightness * lin * (1.0 - self.vignetting * r2)).astype(np.float32)


#: A lighting that changes with time: stamp (s) -> Lighting.
LightingSchedule = Callable[[float], Lighting]


@dataclass(frozen=True)
class SceneStyle:
    """Reflectances of the static scene (in [0, 1])."""

    table: float = 0.35
    plate: float = 0.18
    marker_black: float = 0.04
    marker_white: float = 0.88
    board_white: float = 0.9
    board_black: float = 0.05


@dataclass(frozen=True)
class SensorModel:
    """The sensor's response: DN = exposure_dn * gain * reflectance, blurred, plus noise.

    Parameters
    ----------
    exposure_dn : float
        Digital number for reflectance 1 under gain 1 (clipped at 255).
    blur_sigma_px : float
        Gaussian blur (optics and focus), pixels; 0 for none.
    read_noise_dn : float
        Signal-independent noise (DN, standard deviation).
    shot_noise_dn2_per_dn : float
        Photon noise variance per DN of signal (DN^2 / DN).
    """

    exposure_dn: float = 240.0
    blur_sigma_px: float = 0.7
    read_noise_dn: float = 1.5
    shot_noise_dn2_per_dn: float = 0.02

    def __post_init__(self) -> None:
        check_number(self.exposure_dn, "sensor.exposure_dn", min_value=0.0)
        check_number(self.blur_sigma_px, "sensor.blur_sigma_px", min_value=0.0, max_value=10.0)
        check_number(self.read_noise_dn, "sensor.read_noise_dn", min_value=0.0)
        check_number(self.shot_noise_dn2_per_dn, "sensor.shot_noise_dn2_per_dn", min_value=0.0)


@dataclass(frozen=True)
class PartTruth:
    """Ground truth of one part in one frame: index in the scene list, label, pose in the plate
    frame, and whether its whole outline lies inside the image."""

    index: int
    label: str
    x_m: float
    y_m: float
    theta_rad: float
    in_image: bool


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """A rendered image (uint8, mono8 or bgr8) at ``stamp_s`` with ground truth."""

    image: np.ndarray
    stamp_s: float
    index: int
    truth: tuple[PartTruth, ...]
    plate_displacement: np.ndarray


__all__ = [
    "Lighting",
    "LightingSchedule",
    "Occluder",
    "PartTruth",
    "RenderPart",
    "RenderedFrame",
    "SceneStyle",
    "SensorModel",
]
