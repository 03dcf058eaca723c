"""The tracker's configuration: settings and part types, strictly loaded from YAML or mappings."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ppod_ros.config.fields import Fields, load_yaml_file
from ppod_ros.errors import ConfigError
from ppod_ros.vision.detection import DetectorSettings
from ppod_ros.vision.kalman import FilterSettings
from ppod_ros.vision.shapes import PartSpec


@dataclass(frozen=True)
class TrackerSettings:
    """Tracking parameters (detection and filter settings nested).

    area_tolerance : a blob matches a part type if its area is within this fraction.
    shape_tolerance : largest difference of scale-free shape invariants for a match.
    fit_tolerance : largest relative misfit of the orientation moments for a match.
    gate_m, gate_sigmas : a track accepts detections within max(gate_m, gate_sigmas * sigma).
    max_coast_s : a track unmeasured for longer is LOST.
    forget_after_s : a LOST track is dropped after this long.
    reacquire_radius_m : how far from where it was lost a part may reappear and keep its id.
    follow_plate : measure the plate's in-plane shift from its markers in every frame and give poses
        in the moving plate's frame (a vibrating plate is caught displaced by the motion's amplitude).
    """

    detector: DetectorSettings = field(default_factory=DetectorSettings)
    filter: FilterSettings = field(default_factory=FilterSettings)
    area_tolerance: float = 0.06
    shape_tolerance: float = 0.03
    fit_tolerance: float = 0.05
    gate_m: float = 0.008
    gate_sigmas: float = 6.0
    max_coast_s: float = 1.0
    forget_after_s: float = 300.0
    reacquire_radius_m: float = 0.03
    follow_plate: bool = True

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "tracker") -> TrackerSettings:
        """Strict parse; every key optional, e.g. ``{max_coast_s: 2.0, detector: {polarity: dark}}``."""
        f = Fields(data, where)
        d = cls()
        det = f.sub("detector", {})
        dd = DetectorSettings()
        detector = DetectorSettings(
            polarity=det.string("polarity", dd.polarity, choices=("bright", "dark")),
            threshold_ratio=det.number("threshold_ratio", dd.threshold_ratio, min_value=1.05),
            min_area_px=det.integer("min_area_px", dd.min_area_px, min_value=1),
            background_cell_px=det.integer(
                "background_cell_px", dd.background_cell_px, min_value=1, max_value=64
            ),
            max_part_size_m=det.number(
                "max_part_size_m", dd.max_part_size_m, min_value=0.0, exclusive_min=True, unit="m"
            ),
            max_order=det.integer("max_order", dd.max_order, min_value=2, max_value=12),
            dark_level_dn=det.number("dark_level_dn", dd.dark_level_dn, min_value=0.0),
            bright_level_dn=det.number("bright_level_dn", dd.bright_level_dn, max_value=255.0),
        )
        det.finish()
        flt = f.sub("filter", {})
        fd = FilterSettings()
        filt = FilterSettings(
            **{
                k: flt.number(k, getattr(fd, k), min_value=0.0, exclusive_min=True)
                for k in fd.__dataclass_fields__
            }
        )
        flt.finish()
        kw = {
            k: f.number(k, getattr(d, k), min_value=0.0, exclusive_min=True)
            for k in (
                "area_tolerance",
                "shape_tolerance",
                "fit_tolerance",
                "gate_m",
                "gate_sigmas",
                "max_coast_s",
                "forget_after_s",
                "reacquire_radius_m",
            )
        }
        follow = f.boolean("follow_plate", d.follow_plate)
        f.finish()
        return cls(detector=detector, filter=filt, follow_plate=follow, **kw)


def load_part_specs(items: Sequence[Mapping[str, Any]], where: str = "parts") -> list[PartSpec]:
    """Part types from a list of ``{label, footprint | part, height_m}`` mappings."""
    if not isinstance(items, Sequence) or isinstance(items, (str, bytes)):
        raise ConfigError(f"{where}: expected a list of part types")
    return [PartSpec.from_dict(item, f"{where}[{i}]") for i, item in enumerate(items)]


def load_tracker_config(source: str | Path | Mapping[str, Any]) -> tuple[list[PartSpec], TrackerSettings]:
    """Part types and settings from a tracker YAML file (or its parsed mapping)::

    parts:
      - {label: washer, footprint: {disk: 0.006}, height_m: 0.002}
      - {label: bracket, part: {type: rigid, ...}, height_m: 0.004}   # a PART.yaml mapping
    settings: {max_coast_s: 2.0, detector: {polarity: dark}}          # optional
    """
    if isinstance(source, Mapping):
        data, origin = source, "tracker"
    else:
        data, origin = load_yaml_file(source, "tracker"), str(source)
    try:
        f = Fields(data, "")
        specs = load_part_specs(f.raw("parts"), "parts")
        settings = TrackerSettings.from_dict(f.raw("settings", {}) or {}, "settings")
        f.finish()
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}") from exc
    return specs, settings


__all__ = ["TrackerSettings", "load_part_specs", "load_tracker_config"]
