"""The device envelope as the planner uses it: the one envelope checker, with headroom.

The planner checks its candidate motions with the generator's own checker
(:class:`ppod_ros.actuation.envelope.Envelope`, the one every goal and corrected table passes) and
keeps every ratio (use / limit) at most ``1 - headroom``, so the feedback's corrections on top of
the planned motion are not scaled back. Ratios are linear in amplitude, so one scale fits a motion
into the envelope; a motion with a row at a forbidden frequency cannot be scaled in.
"""

from __future__ import annotations

import math
from functools import lru_cache

from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.motion import PlateMotion

#: Shrink factor per retry when a scaled motion still lands a hair over (refined extrema, rounding).
RETRY_STEP = 0.98


@lru_cache(maxsize=8)
def _envelope(device):
    from ppod_ros.actuation.envelope import Envelope

    return Envelope(device)


def fit_envelope(motion: PlateMotion, device, headroom: float = 0.15, step: float = RETRY_STEP
                 ) -> tuple[PlateMotion, float]:
    """``motion`` scaled down until the device envelope holds with ``headroom`` under every limit
    (every ratio <= 1 - headroom); returns (motion, scale). LimitError naming the limit when no
    scale fits (a row at a forbidden frequency)."""
    if not 0.0 <= headroom < 0.5:
        raise ConfigError(f"headroom: expected 0 <= headroom < 0.5 (fraction), got {headroom!r}")
    if motion.is_zero():
        return motion, 1.0
    envelope = _envelope(device)
    max_ratio = 1.0 - headroom
    report = envelope.check_motion(motion)
    name, worst = report.worst()
    if not math.isfinite(worst):
        raise report.error(max_ratio)  # a row at a forbidden frequency: no amplitude fits
    scale = 1.0 if worst <= max_ratio else max_ratio / worst
    for _ in range(20):
        candidate = motion if scale == 1.0 else motion.scaled(scale)
        report = envelope.check_motion(candidate)
        if report.within(max_ratio):
            return candidate, scale
        scale *= step
    err = report.error(max_ratio)
    raise LimitError(f"motion: not within the device envelope with {100 * headroom:.0f} % headroom even at "
                     f"{100 * scale:.1f} % amplitude ({err})", limit=err.limit, limit_value=err.limit_value,
                     requested=err.requested)


__all__ = ["fit_envelope"]
