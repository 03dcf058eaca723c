"""Triggered capture: each frame at the first plate-cycle start after each frame tick (DESIGN.md).

The camera's frame clock ticks at about ``fps``; the device triggers the exposure at the next cycle
boundary of the plate's fundamental, so every frame sees the plate at the same phase (its small
vibration displacement is then a constant offset that the fiducial calibration absorbs, and the
vibration does not smear the parts). Frame stamps are therefore multiples of the cycle period,
spaced 1/fps rounded up to whole cycles.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ppod_ros.config.fields import check_number
from ppod_ros.motion import PlateMotion
from ppod_sim.camera.renderer import CameraRenderer
from ppod_sim.camera.scene import RenderedFrame, RenderPart

#: Ticks within this fraction of a cycle after a boundary still trigger at that boundary
#: (floating-point noise in tick arithmetic must not skip a whole cycle).
_EPS_CYCLES = 1e-9


def trigger_time_s(tick_s: float, cycle_hz: float, cycle_origin_s: float = 0.0) -> float:
    """The first cycle start at or after ``tick_s`` (s), cycles starting at ``cycle_origin_s``."""
    f = check_number(cycle_hz, "cycle_hz", min_value=0.0, exclusive_min=True, unit="Hz")
    n = math.ceil((float(tick_s) - cycle_origin_s) * f - _EPS_CYCLES)
    return cycle_origin_s + n / f


def frame_times_s(
    start_s: float, end_s: float, fps: float, cycle_hz: float, cycle_origin_s: float = 0.0
) -> np.ndarray:
    """Trigger times (s) of the frames whose ticks fall in [start_s, end_s)."""
    fps = check_number(fps, "fps", min_value=0.0, exclusive_min=True, unit="Hz")
    ticks = start_s + np.arange(max(0, math.ceil((end_s - start_s) * fps - _EPS_CYCLES))) / fps
    return np.array([trigger_time_s(t, cycle_hz, cycle_origin_s) for t in ticks])


class TriggeredCamera:
    """A renderer driven by the plate's cycle: frames at cycle starts, with the plate displaced as
    the motion has it at that phase.

    Parameters
    ----------
    renderer : CameraRenderer
    motion : PlateMotion or None
        The plate's current motion (None: plate at rest). Replace with :meth:`set_motion`.
    cycle_origin_s : float
        Device time of a cycle start (s).
    """

    def __init__(
        self, renderer: CameraRenderer, motion: PlateMotion | None = None, cycle_origin_s: float = 0.0
    ):
        self.renderer = renderer
        self.motion = motion
        self.cycle_origin_s = float(cycle_origin_s)
        self._next_tick_s: float | None = None

    def set_motion(self, motion: PlateMotion | None, cycle_origin_s: float | None = None) -> None:
        self.motion = motion
        if cycle_origin_s is not None:
            self.cycle_origin_s = float(cycle_origin_s)

    def trigger_time(self, tick_s: float) -> float:
        """When a frame ticked at ``tick_s`` is exposed (s)."""
        if self.motion is None:
            return float(tick_s)
        return trigger_time_s(tick_s, self.motion.frequency_hz, self.cycle_origin_s)

    def next_trigger(self, now_s: float) -> float:
        """Exposure time of the next frame whose tick is at or after ``now_s``; ticks advance by
        1/fps from the first call."""
        period = 1.0 / self.renderer.config.fps
        if self._next_tick_s is None:
            self._next_tick_s = float(now_s)
        while self._next_tick_s < now_s - 1e-12:
            self._next_tick_s += period
        t = self.trigger_time(self._next_tick_s)
        self._next_tick_s += period
        return t

    def plate_displacement(self, t_s: float) -> np.ndarray:
        """[dx, dy, dz, rx, ry, rz] of the plate at device time ``t_s`` (zero at rest)."""
        if self.motion is None:
            return np.zeros(6)
        return np.asarray(self.motion.displacement(float(t_s) - self.cycle_origin_s), dtype=float)

    def capture(self, parts: Sequence[RenderPart], trigger_s: float, **kwargs) -> RenderedFrame:
        """Render ``parts`` (their poses at ``trigger_s``) as exposed at ``trigger_s``."""
        return self.renderer.render(
            parts, trigger_s, plate_displacement=self.plate_displacement(trigger_s), **kwargs
        )


__all__ = ["TriggeredCamera", "frame_times_s", "trigger_time_s"]
