"""The device envelope as the planner uses it: the generator's own goal checker, with headroom.

One small seam (:func:`fit_envelope`) so that the safety-envelope issue's public checker can
replace the generator's GoalPlanner here at merge. The headroom shrinks every limit the checker
applies by the given fraction (upper limits times 1 - headroom; the contact margin's budget
g - margin likewise), so the feedback's corrections on top of the planned motion are not scaled
back.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.motion import PlateMotion

GRAVITY_MPS2 = 9.81


@lru_cache(maxsize=8)
def _checker(device, headroom: float):
    from ppod_ros.actuation.planning import GoalPlanner

    lim = device.limits
    keep = 1.0 - headroom
    tight = dataclasses.replace(
        lim, leg_stroke_m=lim.leg_stroke_m * keep, coil_current_a=lim.coil_current_a * keep,
        coil_temperature_c=lim.coil_temperature_c * keep, amplifier_voltage_v=lim.amplifier_voltage_v * keep,
        plate_accel_mps2=lim.plate_accel_mps2 * keep,
        plate_angular_accel_radps2=lim.plate_angular_accel_radps2 * keep,
        contact_margin_mps2=GRAVITY_MPS2 - keep * (GRAVITY_MPS2 - lim.contact_margin_mps2))
    return GoalPlanner(dataclasses.replace(device, limits=tight))


def fit_envelope(motion: PlateMotion, device, headroom: float = 0.15, step: float = 0.93) -> tuple[PlateMotion, float]:
    """``motion`` scaled down (by ``step`` at a time) until the generator's checker accepts it
    with ``headroom`` under every limit; returns (motion, scale). LimitError if even a small
    fraction of it is rejected (a limit that does not scale with amplitude)."""
    if not 0.0 <= headroom < 0.5:
        raise ConfigError(f"headroom: expected 0 <= headroom < 0.5 (fraction), got {headroom!r}")
    if motion.is_zero():
        return motion, 1.0
    checker = _checker(device, round(float(headroom), 6))
    scale = 1.0
    for _ in range(40):
        candidate = motion if scale == 1.0 else motion.scaled(scale)
        try:
            checker.plan(candidate)
            return candidate, scale
        except LimitError as exc:
            last = exc
            scale *= step
    raise LimitError(f"motion: not within the device envelope with {100 * headroom:.0f} % headroom even at "
                     f"{100 * scale:.1f} % amplitude ({last})", limit=last.limit, limit_value=last.limit_value,
                     requested=last.requested)


__all__ = ["fit_envelope"]
