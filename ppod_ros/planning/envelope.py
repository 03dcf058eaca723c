"""The device envelope as the planner uses it: the one envelope checker, with headroom.

The planner checks its candidate motions with the generator's own checker
(:class:`ppod_ros.actuation.envelope.Envelope`, the one every goal and corrected table passes) and
keeps every ratio (use / limit) at most ``1 - headroom``, so the feedback's corrections on top of
the planned motion are not scaled back. Ratios are linear in amplitude, so one scale fits a motion
into the envelope; a motion with a row at a forbidden frequency cannot be scaled in.

Headroom alone does not keep corrections from being scaled back. The checker judges a corrected
table's plate-side limits on the plate the feedback measured, but bounds what the nominal plant
predicts for it by ``1 + limits.plant_model_allowance`` (a wrong measurement cannot command an
arbitrary plate motion; with the allowance 0, by 1); the feedback's table for a plant whose actuators
are off by ``G = G0 M`` is ``M^-1 G0^-1 goal``, which the nominal plant reads as the motion
``G0 M^-1 G0^-1 goal``. Actuator errors of 15 % leak the large components of a motion (the
rotation and the horizontal translation of a sink) into its small ones (tilt and heave), so this
reading can nearly double the contact-margin use of a motion that leaves 15 % headroom: the
checker then scales every correction back to nothing and the plate keeps its first error (measured
in the demo: 20-30 %). With a :class:`PlantTolerance`, :func:`fit_envelope` also keeps the plate
motion limits (peak acceleration, angular acceleration, contact margin) within the headroom under
that bound for that reading, under a fixed set of actuator errors drawn within the tolerance, so the
corrections a plant within it needs pass the checker.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from ppod_ros.actuation.envelope import PlantTolerance
from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.motion import PlateMotion

#: Shrink factor per retry when a scaled motion still lands a hair over (refined extrema, rounding).
RETRY_STEP = 0.98
#: The drive limits' largest ratio over the plants within ``limits.plant_uncertainty`` a fitted motion
#: may use (the generator accepts 1; the table's quantisation and rows change it by far less).
DRIVE_FIT = 0.999


@lru_cache(maxsize=8)
def _envelope(device):
    from ppod_ros.actuation.envelope import Envelope

    return Envelope(device)


@lru_cache(maxsize=64)
def _readings(device, tolerance: PlantTolerance, frequency_hz: float, ks: tuple[int, ...]) -> np.ndarray:
    """Per drawn plant and harmonic, the map from a goal's phasors to the nominal plant's reading of
    the table that realises it on that plant: ``G0 M^-1 G0^-1``, (samples, K, 6, 6)."""
    plant = _envelope(device).plant
    G0 = plant.frequency_response(frequency_hz * np.asarray(ks, float))  # (K, 6, 6)
    Minv = np.linalg.inv(tolerance.matrices())  # (S, 6, 6)
    return np.einsum("kij,sjl,klm->skim", G0, Minv, np.linalg.inv(G0))


@lru_cache(maxsize=64)
def _played(device, tolerance: PlantTolerance, frequency_hz: float, ks: tuple[int, ...]) -> np.ndarray:
    """Per drawn plant and harmonic, the map from a goal's phasors to the plate motion the nominal
    feed-forward alone plays on that plant: ``G0 M G0^-1``, (samples, K, 6, 6)."""
    plant = _envelope(device).plant
    G0 = plant.frequency_response(frequency_hz * np.asarray(ks, float))  # (K, 6, 6)
    return np.einsum("kij,sjl,klm->skim", G0, tolerance.matrices(), np.linalg.inv(G0))


def uncorrected_motions(motion: PlateMotion, device, tolerance: PlantTolerance) -> list[PlateMotion]:
    """What the plants within ``tolerance`` play of ``motion`` before the accelerometer feedback has
    learned them (the nominal feed-forward alone, ``G0 M G0^-1 X`` per drawn plant): the first
    motions of a session (docs/feedback.md: they start 12-18 % off)."""
    active = motion.pruned()
    if active.is_zero():
        return [motion] * tolerance.samples
    ks = tuple(int(k) for k in active.k)
    X = np.einsum("skij,kj->ski", _played(device, tolerance, float(motion.frequency_hz), ks), active.phasors())
    return [PlateMotion.from_phasors(motion.frequency_hz, active.k, x, name=motion.name) for x in X]


#: Checker reports of one-harmonic motions and the corrected tables' worst ratio of motions, checked
#: before, by their exact arrays: a replanning step fits again the motion it chose, which an earlier
#: fit returned (a report of a one-harmonic motion does not depend on the motions checked with it:
#: ``Envelope.check_motions``). Bounded (cleared when full).
_CHECKED: dict[tuple, object] = {}
_ROBUST: dict[tuple, float] = {}
_MEMO_MAX = 1024


def _exact(motion: PlateMotion) -> tuple:
    return (motion.frequency_hz, motion.k.tobytes(), motion.amplitude.tobytes(), motion.phase.tobytes())


def _remembered(memo: dict, keys: list, compute) -> list:
    """The values of ``keys`` from ``memo``; the misses computed together (``compute(indices)``, in
    their order) and remembered (a key None: computed, not remembered). Bounded: cleared when full."""
    out = [None if key is None else memo.get(key) for key in keys]
    miss = [i for i, r in enumerate(out) if r is None]
    if miss:
        if len(memo) + len(miss) > _MEMO_MAX:
            memo.clear()
        for i, value in zip(miss, compute(miss)):
            out[i] = value
            if keys[i] is not None:
                memo[keys[i]] = value
    return out


def _check_motions(envelope, motions: list[PlateMotion]) -> list:
    """``envelope.check_motions(motions)``, one-harmonic motions checked before taken from ``_CHECKED``."""
    return _remembered(_CHECKED, [(envelope, _exact(m)) if m.k.size == 1 else None for m in motions],
                       lambda miss: envelope.check_motions([motions[i] for i in miss]))


def _robust_many(motions: list[PlateMotion], device, tolerance: PlantTolerance) -> list[float]:
    """The worst of :func:`corrected_motion_ratios` of each motion (remembered by the motion's exact
    arrays; those not remembered in one :func:`corrected_motion_ratios_many`)."""
    return _remembered(_ROBUST, [(device, tolerance, _exact(m)) for m in motions],
                       lambda miss: [max(r.values()) for r in
                                     corrected_motion_ratios_many([motions[i] for i in miss], device, tolerance)])


_MOTION_LIMITS = ("limits.plate_accel_mps2", "limits.plate_angular_accel_radps2", "limits.contact_margin_mps2")


def corrected_motion_ratios(motion: PlateMotion, device, tolerance: PlantTolerance) -> dict[str, float]:
    """The plate motion limits' worst use ratios over the tolerance's drawn plants, as the checker
    reads the table that realises ``motion`` on each (see the module docstring)."""
    return corrected_motion_ratios_many([motion], device, tolerance)[0]


def corrected_motion_ratios_many(motions: Sequence[PlateMotion], device,
                                 tolerance: PlantTolerance) -> list[dict[str, float]]:
    """:func:`corrected_motion_ratios` of each motion, those of one frequency and one set of
    harmonics in one peak search over every (motion, plant) (its refinement per column: the cost is
    linear in the columns)."""
    from ppod_ros.actuation.envelope import harmonic_groups, motion_extremes_many
    from ppod_ros.motion import GRAVITY_MPS2

    lim = device.limits
    out: list[dict[str, float]] = [dict.fromkeys(_MOTION_LIMITS, 0.0) for _ in motions]
    actives = [m.pruned() for m in motions]
    for (frequency_hz, ks), members in harmonic_groups(actives).items():
        if not ks:
            continue   # zero motions: no use
        T = _readings(device, tolerance, frequency_hz, ks)
        read = np.concatenate([np.einsum("skij,kj->ski", T, actives[i].phasors()) for i in members])
        ext = motion_extremes_many(read, np.asarray(ks), lim.working_radius_m).reshape(len(members), -1, 3)
        for i, e in zip(members, ext):
            out[i] = {
                "limits.plate_accel_mps2": float(e[:, 0].max() / lim.plate_accel_mps2),
                "limits.plate_angular_accel_radps2": float(e[:, 1].max() / lim.plate_angular_accel_radps2),
                "limits.contact_margin_mps2": float(max(0.0, GRAVITY_MPS2 - e[:, 2].min())
                                                    / (GRAVITY_MPS2 - lim.contact_margin_mps2)),
            }
    return out


def fit_envelope(motion: PlateMotion, device, headroom: float = 0.15, step: float = RETRY_STEP,
                 tolerance: PlantTolerance | None = None) -> tuple[PlateMotion, float]:
    """``motion`` scaled down until the device envelope holds with ``headroom`` under every limit
    (every ratio <= 1 - headroom) and, with ``tolerance``, the plate motion limits hold with the same
    headroom for the corrected tables of the plants within it; returns (motion, scale). LimitError
    naming the limit when no scale fits (a row at a forbidden frequency).

    The ratios are linear in amplitude but for the exact leg stroke's second-order terms, so the
    scale they give is checked again on the scaled motion (and shrunk by ``step`` until it passes);
    a motion within as it is is returned at once (the checker's report is its own)."""
    return fit_envelope_many([motion], device, headroom, step, tolerance)[0]


def fit_envelope_many(motions: Sequence[PlateMotion], device, headroom: float = 0.15, step: float = RETRY_STEP,
                      tolerance: PlantTolerance | None = None) -> list[tuple[PlateMotion, float]]:
    """:func:`fit_envelope` of each motion, in order, with the checker's vectorised passes shared
    (:meth:`~ppod_ros.actuation.envelope.Envelope.check_motions`). LimitError for a motion that cannot
    be fitted (none of the others is returned then)."""
    if not 0.0 <= headroom < 0.5:
        raise ConfigError(f"headroom: expected 0 <= headroom < 0.5 (fraction), got {headroom!r}")
    motions = list(motions)
    out: list[tuple[PlateMotion, float] | None] = [(m, 1.0) if m.is_zero() else None for m in motions]
    todo = [i for i, m in enumerate(motions) if out[i] is None]
    if not todo:
        return out  # type: ignore[return-value]
    envelope = _envelope(device)
    max_ratio = 1.0 - headroom
    reports = _check_motions(envelope, [motions[i] for i in todo])
    for report in reports:
        if not math.isfinite(report.worst()[1]):
            raise report.error(max_ratio)  # a row at a forbidden frequency: no amplitude fits
    # The generator judges a corrected table's plate-side limits on the measured plate, and bounds
    # their nominal reading by 1 + limits.plant_model_allowance (actuation/corrections.py): keep the
    # reading under that bound with the same headroom.
    allowance = float(getattr(device.limits, "plant_model_allowance", 0.0))
    robust = ([0.0] * len(todo) if tolerance is None else
              [r / (1.0 + allowance) for r in _robust_many([motions[i] for i in todo], device, tolerance)])
    # The generator accepts a goal only if its drive limits hold on every plant within the device's
    # limits.plant_uncertainty (GoalPlanner.plan): that allowance is the goal's room for the plant,
    # so these limits are kept at DRIVE_FIT (read as max_ratio), not with the headroom on top.
    unmeasured = PlantTolerance.from_limits(device.limits)

    def drive(motion: PlateMotion, report, enough: float = 1.0) -> float:
        """The drive limits' worst-plant ratio over DRIVE_FIT, or an upper bound of it when that is
        at most ``enough`` (no exact check)."""
        if unmeasured.is_zero():
            return 0.0
        return envelope.drive_ratio(motion, unmeasured, DRIVE_FIT * enough, report) / DRIVE_FIT

    pending = []
    drives = {}
    for i, report, rob in zip(todo, reports, robust):
        other = max(report.worst()[1], rob)
        # Exact only where it can decide: a bound at most max(other, max_ratio) leaves the motion
        # accepted, or scaled by the other limits, exactly as the exact ratio would.
        drives[i] = drive(motions[i], report, max(other, max_ratio) / max_ratio)
        worst = max(other, drives[i] * max_ratio)
        if worst <= max_ratio:
            out[i] = (motions[i], 1.0)   # within as it is: the checker's report above is its own
        else:
            pending.append((i, max_ratio / worst))
    last = {}   # the last report of each motion still pending
    for _ in range(20):
        if not pending:
            return out  # type: ignore[return-value]
        candidates = [motions[i].scaled(scale) for i, scale in pending]
        still = []
        for (i, scale), candidate, report in zip(pending, candidates, _check_motions(envelope, candidates)):
            # The drive limits are linear in the scale but for the legs' second-order terms, which
            # shrink faster: scale times the unscaled ratio (or its bound) bounds the scaled one (no
            # second exact check).
            if report.within(max_ratio) and (scale * drives[i] <= 1.0 or drive(candidate, report) <= 1.0):
                out[i] = (candidate, scale)
            else:
                last[i] = report
                still.append((i, scale * step))
        pending = still
    if not pending:
        return out  # type: ignore[return-value]
    i, scale = pending[0]
    err = last[i].error(max_ratio) or LimitError(
        f"the drive limits on a plant within limits.plant_uncertainty ({unmeasured.describe()})",
        limit="limits.leg_stroke_m", limit_value=math.nan, requested=math.nan)
    raise LimitError(f"motion: not within the device envelope with {100 * headroom:.0f} % headroom even at "
                     f"{100 * scale:.1f} % amplitude ({err})", limit=err.limit, limit_value=err.limit_value,
                     requested=err.requested)


__all__ = ["PlantTolerance", "corrected_motion_ratios", "corrected_motion_ratios_many", "fit_envelope",
           "fit_envelope_many", "uncorrected_motions"]
