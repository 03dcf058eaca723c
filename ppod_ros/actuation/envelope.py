"""The device's safety envelope: one checker for every table and every plate motion.

Every table the host commits (a goal's feed-forward table, or a goal plus a feedback correction)
and every plate motion a planner proposes is held to the same limits of the device description
(``limits.*``, docs/device.md):

====================================  =================================================================
limit                                 what is checked
====================================  =================================================================
``limits.frequency_range_hz``         every row with current (every harmonic of a motion) in the band
``limits.excluded_bands_hz``          ... and outside every excluded band (no current ever goes there)
``limits.plate_accel_mps2``           peak \\|p''\\| over the cycle
``limits.plate_angular_accel_radps2`` peak \\|alpha\\| over the cycle
``limits.contact_margin_mps2``        min over the working disc and the cycle of g + a_n
``limits.leg_stroke_m``               peak leg displacement: exact inverse kinematics, and for a
                                      table also the nominal plant's linear leg prediction
``limits.coil_current_a``             peak coil current
``limits.coil_temperature_c``         steady-state I^2 R heating of the RMS current
``limits.amplifier_voltage_v``        peak amplifier voltage (nominal plant)
====================================  =================================================================

A table's plate motion is what the nominal plant (:class:`~ppod_ros.actuation.plant.NominalPlant`)
predicts for it. Peaks and the contact margin are not taken from samples alone: the sampled
extremum is refined with parabolas through the largest samples (:func:`refined_max`), so what is
reported is the true extremum to about 1e-10 relative, never the 0.1 % low a 64-sample grid gives.

:class:`EnvelopeReport` gives every limit as a *ratio*, use over limit, that scales linearly with the
amplitude of the motion or table: value / limit for the peaks, ``(g - margin) / (g - limit)`` for the
contact margin (the fraction of the allowed loss of normal acceleration that is used) and
``I_rms / I_rms(limit)`` for the thermal limit. A ratio of 0.87 means the motion could grow by 15 %
before reaching that limit, so a planner that wants 15 % headroom asks ``report.within(1 / 1.15)``.
A row at a forbidden frequency has the ratio ``inf``.

Example (a goal with 15 % headroom)::

    env = Envelope(config)
    report = env.check_motion(motion)
    if not report.within(1 / 1.15):
        name, ratio = report.worst()
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ppod_ros.actuation.harmonics import PEAK_SAMPLES_PER_PERIOD, rms, synthesize
from ppod_ros.actuation.plant import NominalPlant
from ppod_ros.device.config import DeviceConfig
from ppod_ros.errors import ConfigError, LimitError
from ppod_ros.kinematics.stewart import LegTrajectory, leg_trajectories, leg_trajectory
from ppod_ros.motion import GRAVITY_MPS2, MAX_HARMONIC, PlateMotion

#: The limits in the order a goal is checked (the first one over is the one a rejection names).
LIMIT_ORDER = (
    "limits.frequency_range_hz",
    "limits.excluded_bands_hz",
    "limits.plate_accel_mps2",
    "limits.plate_angular_accel_radps2",
    "limits.contact_margin_mps2",
    "limits.leg_stroke_m",
    "limits.coil_current_a",
    "limits.coil_temperature_c",
    "limits.amplifier_voltage_v",
)

#: The limits that are properties of the plate's own motion (the others belong to the actuators and
#: legs): a corrected table's plate-side limits may be judged on the measured plate motion
#: (:mod:`ppod_ros.actuation.corrections`).
PLATE_LIMITS = (
    "limits.plate_accel_mps2",
    "limits.plate_angular_accel_radps2",
    "limits.contact_margin_mps2",
)

_UNITS = {
    "limits.frequency_range_hz": "Hz",
    "limits.excluded_bands_hz": "Hz",
    "limits.plate_accel_mps2": "m/s^2",
    "limits.plate_angular_accel_radps2": "rad/s^2",
    "limits.contact_margin_mps2": "m/s^2",
    "limits.leg_stroke_m": "m",
    "limits.coil_current_a": "A",
    "limits.coil_temperature_c": "degC",
    "limits.amplifier_voltage_v": "V",
}

_WHAT = {
    "limits.plate_accel_mps2": "peak plate acceleration",
    "limits.plate_angular_accel_radps2": "peak angular acceleration",
    "limits.contact_margin_mps2": "contact margin min(g + a_n) over the working disc",
    "limits.leg_stroke_m": "peak leg displacement",
    "limits.coil_current_a": "peak coil current",
    "limits.coil_temperature_c": "steady-state coil temperature",
    "limits.amplifier_voltage_v": "peak amplifier voltage",
}

#: Candidates refined per column: the largest sampled local maxima (two: a near-tie between two
#: crests may put the true maximum at either).
REFINE_CANDIDATES = 2
#: The second parabola uses samples this much closer than the grid.
REFINE_ZOOM = 16


def _vertex(ym: np.ndarray, y0: np.ndarray, yp: np.ndarray, step: float) -> np.ndarray:
    """Offset (rad) of the vertex of the parabola through (-step, ym), (0, y0), (step, yp), within +-step."""
    curvature = ym - 2.0 * y0 + yp
    # Divided only where the parabola opens downwards (no warnings, no errstate context per call).
    d = np.divide(0.5 * step * (ym - yp), curvature, out=np.zeros_like(curvature), where=curvature < 0)
    return np.minimum(np.maximum(d, -step), step)   # np.clip without its per-call overhead


@lru_cache(maxsize=16)
def _grid(n_samples: int) -> np.ndarray:
    """The first pass's phases 2 pi n / N (read-only, one array per N)."""
    theta = 2.0 * math.pi * np.arange(n_samples) / n_samples
    theta.flags.writeable = False
    return theta


def refined_max(fn, n_samples: int, at=None) -> np.ndarray:
    """Maximum over one cycle of each column of ``fn(theta)``, refined beyond the sample grid.

    Parameters
    ----------
    fn : callable
        ``fn(theta)`` with theta (M,) phases of the fundamental (rad) returns (M, C) values.
    n_samples : int
        Grid of the first pass (at least 64 per period of the highest harmonic in ``fn``).
    at : callable, optional
        ``at(theta)`` with theta (M, C) returns (M, C): column c of ``fn`` at the phases
        ``theta[:, c]``. The refinement evaluates each column only at its own candidates with it;
        without it, ``fn`` is evaluated at every column's candidates and the diagonal kept, which
        costs C times as much (the checker's calls have tens of columns, a hundred for the corrected
        readings of three motions).

    Returns
    -------
    ndarray, shape (C,)
        The largest value found: the grid maximum, and ``fn`` at the vertex of a parabola through
        each of the :data:`REFINE_CANDIDATES` largest sampled local maxima and its neighbours,
        refined once more with a parabola on a grid :data:`REFINE_ZOOM` times finer (the extremum to
        about 1e-10 relative; a 64-sample grid alone reads a sinusoid's crest up to 0.12 % low).
    """
    theta = _grid(n_samples)
    y = np.asarray(fn(theta), dtype=float)
    best = np.max(y, axis=0)
    C = y.shape[1]
    cols = np.arange(C)
    step = 2.0 * math.pi / n_samples
    left = np.concatenate((y[-1:], y[:-1]))   # np.roll(y, 1, axis=0) without its per-call overhead
    right = np.concatenate((y[1:], y[:1]))   # np.roll(y, -1, axis=0)
    score = np.where((y >= left) & (y >= right), y, -np.inf)
    idx = np.argsort(-score, axis=0)[: min(REFINE_CANDIDATES, n_samples)]  # (n_cand, C)
    centres = theta[idx] + _vertex(left[idx, cols], y[idx, cols], right[idx, cols], step)
    fine = step / REFINE_ZOOM
    n_cand = idx.shape[0]
    if at is None:
        grid = (centres[..., None] + np.array([-fine, 0.0, fine])).reshape(-1)
        v = np.asarray(fn(grid), dtype=float).reshape(n_cand, C, 3, C)[:, cols, :, cols]  # (C, n_cand, 3)
    else:
        grid = (centres[:, None, :] + np.array([-fine, 0.0, fine])[None, :, None]).reshape(n_cand * 3, C)
        v = np.asarray(at(grid), dtype=float).reshape(n_cand, 3, C).transpose(2, 0, 1)  # (C, n_cand, 3)
    best = np.maximum(best, v.max(axis=(1, 2)))
    final = centres.T + _vertex(v[..., 0], v[..., 1], v[..., 2], fine)  # (C, n_cand)
    if at is None:
        w = np.asarray(fn(final.reshape(-1)), dtype=float).reshape(C, n_cand, C)[cols, :, cols]  # (C, n_cand)
    else:
        w = np.asarray(at(np.ascontiguousarray(final.T)), dtype=float).T  # (C, n_cand)
    return np.maximum(best, w.max(axis=1))


def _synthesize_columns(table: np.ndarray, k: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """:func:`~ppod_ros.actuation.harmonics.synthesize` computed column by column, (N, C): each
    column's values do not depend on the other columns (a matrix product's do, in the last bit, with
    two or more harmonics), so a peak searched in a batch is the one searched alone."""
    phase = np.outer(theta, k)  # (N, K)
    s, c = np.sin(phase), np.cos(phase)
    re, im = table.real, table.imag
    y = s[:, :1] * re[0] + c[:, :1] * im[0]
    for j in range(1, len(k)):
        y += s[:, j:j + 1] * re[j]
        y += c[:, j:j + 1] * im[j]
    return y


def _synthesize_at(table: np.ndarray, k: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Column c of :func:`~ppod_ros.actuation.harmonics.synthesize` at its own phases ``theta[:, c]``:
    table (K, C), theta (M, C) -> (M, C)."""
    basis = np.exp(1j * theta[..., None] * k)  # (M, C, K)
    return np.einsum("mck,kc->mc", basis, table).imag


def harmonic_groups(actives: Sequence[PlateMotion]) -> dict[tuple[float, tuple[int, ...]], list[int]]:
    """Indices of (pruned) motions by (frequency, harmonics): the groups whose peaks are searched in
    one vectorised pass (zero motions: harmonics ``()``)."""
    groups: dict[tuple[float, tuple[int, ...]], list[int]] = {}
    for i, a in enumerate(actives):
        groups.setdefault((float(a.frequency_hz), tuple(int(k) for k in a.k)), []).append(i)
    return groups


def table_peak(table: np.ndarray, k: np.ndarray | None = None) -> np.ndarray:
    """Refined peak of |y(t)| per column of a harmonic table (K, C) (rows k, default 1..K), shape (C,)."""
    table = np.asarray(table, dtype=complex)
    if table.shape[0] == 0 or not np.any(table):
        return np.zeros(table.shape[1])
    k = np.arange(1, table.shape[0] + 1) if k is None else np.asarray(k)
    n = PEAK_SAMPLES_PER_PERIOD * max(1, int(np.max(k)))
    return refined_max(lambda th: np.abs(synthesize(table, k, th)), n,
                       at=lambda th: np.abs(_synthesize_at(table, k, th)))


def motion_extremes(phasors: np.ndarray, k: np.ndarray, radius_m: float) -> tuple[float, float, float]:
    """(peak |p''|, peak |alpha|, min over the disc and cycle of g + a_n) of acceleration phasors (K, 6)."""
    acc, ang, margin = motion_extremes_many(np.asarray(phasors, dtype=complex)[None], k, radius_m)[0]
    return float(acc), float(ang), float(margin)


def motion_extremes_many(phasors: np.ndarray, k: np.ndarray, radius_m: float) -> np.ndarray:
    """:func:`motion_extremes` of S motions on the same harmonics at once: phasors (S, K, 6) -> (S, 3)."""
    X = np.asarray(phasors, dtype=complex)
    S = X.shape[0]
    out = np.tile([0.0, 0.0, GRAVITY_MPS2], (S, 1))
    if X.shape[1] == 0 or not np.any(X):
        return out
    k = np.asarray(k)
    n = PEAK_SAMPLES_PER_PERIOD * max(4, int(np.max(k)))
    table = X.transpose(1, 0, 2).reshape(X.shape[1], S * 6)

    def quantities(u: np.ndarray) -> np.ndarray:
        """(..., 6) plate accelerations -> (..., 3): |p''|, |alpha| and the loss of normal acceleration."""
        out = np.empty(u.shape[:-1] + (3,))
        lin, ang = u[..., :3], u[..., 3:]
        # |.| as np.linalg.norm computes it (sqrt of the sum of squares), without its per-call overhead.
        np.sqrt(np.add.reduce(lin * lin, axis=-1), out=out[..., 0])
        np.sqrt(np.add.reduce(ang * ang, axis=-1), out=out[..., 1])
        out[..., 2] = radius_m * np.hypot(u[..., 3], u[..., 4]) - u[..., 2]
        return out

    def fn(theta: np.ndarray) -> np.ndarray:
        return quantities(synthesize(table, k, theta).reshape(theta.size, S, 6)).reshape(theta.size, S * 3)

    def at(theta: np.ndarray) -> np.ndarray:
        # Each (motion, quantity) column at its own phases: the motion's six components there.
        M = theta.shape[0]
        basis = np.exp(1j * theta.reshape(M, S, 3)[..., None] * k)  # (M, S, 3, K)
        u = np.einsum("msqk,skj->msqj", basis, X).imag  # (M, S, 3, 6)
        q = quantities(u)  # (M, S, 3 phases, 3 quantities): keep each column's own quantity
        return np.stack([q[:, :, 0, 0], q[:, :, 1, 1], q[:, :, 2, 2]], axis=-1).reshape(M, S * 3)

    peaks = refined_max(fn, n, at=at).reshape(S, 3)
    out[:, :2] = peaks[:, :2]
    out[:, 2] = GRAVITY_MPS2 - peaks[:, 2]
    return out


@dataclass(frozen=True)
class EnvelopeReport:
    """Every limit of the envelope for one table or motion (see the module docstring).

    Attributes
    ----------
    frequency_hz : float
    values : dict
        Limit name -> the value checked (its unit: peak m/s^2, margin m/s^2, stroke m, A, degC, V;
        for the frequency limits the worst row's frequency in Hz, NaN when all rows are allowed).
    ratios : dict
        Limit name -> use / limit, linear in amplitude (inf for a row at a forbidden frequency).
    forbidden_rows : tuple of int
        Harmonic numbers that carry current (or motion) at a frequency outside the band or inside
        an excluded band.
    worst_actuator : dict
        Limit name -> actuator / leg index of the peak, for the per-actuator limits.
    """

    frequency_hz: float
    values: dict[str, float]
    ratios: dict[str, float]
    limits: dict[str, float]
    forbidden_rows: tuple[int, ...] = ()
    worst_actuator: dict[str, int] = field(default_factory=dict)
    allowance: PlantTolerance | None = None
    nominal_ratios: dict[str, float] | None = None
    #: Limits whose value is the worst over the plants within ``allowance`` (over the nominal plant's).
    plant_bound: frozenset[str] = frozenset()

    def within(self, max_ratio: float = 1.0) -> bool:
        """True when every ratio is at most ``max_ratio`` (1: on the limits; 1 / 1.15: 15 % headroom)."""
        return all(r <= max_ratio for r in self.ratios.values())

    def over(self, max_ratio: float = 1.0) -> list[str]:
        """Limit names whose ratio exceeds ``max_ratio``, in checking order."""
        return [name for name in LIMIT_ORDER if self.ratios.get(name, 0.0) > max_ratio]

    def nominal_ratio(self, name: str) -> float:
        """The ratio of limit ``name`` on the nominal plant alone (the same as ``ratios`` without an allowance)."""
        source = self.nominal_ratios if self.nominal_ratios is not None else self.ratios
        return source.get(name, 0.0)

    def worst(self) -> tuple[str, float]:
        """(limit name, ratio) of the largest ratio."""
        name = max(LIMIT_ORDER, key=lambda n: self.ratios.get(n, 0.0))
        return name, self.ratios.get(name, 0.0)

    def error(self, max_ratio: float = 1.0) -> LimitError | None:
        """A LimitError naming the first limit over ``max_ratio`` (checking order), or None."""
        over = self.over(max_ratio)
        if not over:
            return None
        name = over[0]
        value, limit, unit = self.values[name], self.limits[name], _UNITS[name]
        if name in ("limits.frequency_range_hz", "limits.excluded_bands_hz"):
            return LimitError(
                f"harmonic {self.forbidden_rows[0]} at {value:g} Hz is outside {name} (no current may "
                f"go to a forbidden frequency)",
                limit=name,
                limit_value=limit,
                requested=value,
            )
        where = f" of actuator {self.worst_actuator[name]}" if name in self.worst_actuator else ""
        relation = "is below" if name == "limits.contact_margin_mps2" else "exceeds"
        plants = ""
        if name in self.plant_bound and self.allowance is not None:
            plants = (f" on a plant within limits.plant_uncertainty ({self.allowance.describe()}; the plant is "
                      f"not measured yet; {self.ratios[name] / self.nominal_ratio(name):.3g}x the nominal plant's)")
        return LimitError(
            f"{_WHAT[name]}{where} {value:.4g} {unit} {relation} {name} = {limit:g} {unit}{plants}",
            limit=name,
            limit_value=limit,
            requested=value,
        )


@dataclass(frozen=True)
class PlantTolerance:
    """Actuator errors of the real plant against the nominal model: per actuator a gain error up to
    ``gain`` (fraction) and a phase error up to ``phase_deg``, and cross-coupling up to ``coupling``
    (fraction): the drive the plant plays is ``M I`` for a commanded table ``I``, with
    ``M = diag(g e^{i phi}) (1 + C)`` (as the simulated device's drive, ``ppod_sim.drive``).

    The checker (:meth:`Envelope.check_table` with ``allowance``) bounds a table's limits over *every*
    plant within the tolerance (:func:`worst_over_plants`); the planner's fitting uses ``samples``
    fixed draws (``seed``) of M (:meth:`matrices`, ``ppod_ros.planning.envelope``). The device
    description's ``limits.plant_uncertainty`` gives the tolerance of a device
    (:meth:`from_limits`)."""

    gain: float = 0.15
    phase_deg: float = 10.0
    coupling: float = 0.05
    samples: int = 12
    seed: int = 0

    def __post_init__(self):
        for name in ("gain", "phase_deg", "coupling"):
            v, top = getattr(self, name), (90.0 if name == "phase_deg" else 0.5)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v < top):
                raise ConfigError(f"plant tolerance {name}: expected 0 <= value < {top:g}, got {v!r}")
        if not (isinstance(self.samples, int) and 1 <= self.samples <= 64):
            raise ConfigError(f"plant tolerance samples: expected 1..64, got {self.samples!r}")

    def matrices(self) -> np.ndarray:
        """The drawn actuator error matrices M, (samples, 6, 6) complex."""
        rng = np.random.default_rng(self.seed)
        out = np.empty((self.samples, 6, 6), complex)
        for s in range(self.samples):
            # Uniform within the tolerance, as the simulated device draws its own (corner draws cost a
            # further 20 % of amplitude for the last 2 % of plants: their corrections are scaled a little).
            g = 1.0 + self.gain * rng.uniform(-1.0, 1.0, 6)
            ph = np.deg2rad(self.phase_deg) * rng.uniform(-1.0, 1.0, 6)
            c = rng.uniform(-self.coupling, self.coupling, (6, 6))
            np.fill_diagonal(c, 0.0)
            out[s] = np.diag(g * np.exp(1j * ph)) @ (np.eye(6) + c)
        return out

    @classmethod
    def from_limits(cls, limits) -> PlantTolerance:
        """The device description's ``limits.plant_uncertainty`` (gain, phase deg, coupling)."""
        gain, phase_deg, coupling = limits.plant_uncertainty
        return cls(float(gain), float(phase_deg), float(coupling))

    def describe(self) -> str:
        """One line for messages: 'gain +-15 %, phase +-10 deg, coupling +-5 %'."""
        return (f"gain +-{100 * self.gain:g} %, phase +-{self.phase_deg:g} deg, "
                f"coupling +-{100 * self.coupling:g} %")

    def is_zero(self) -> bool:
        return self.gain == 0 and self.phase_deg == 0 and self.coupling == 0

    def factor_hull(self, segments: int = 4) -> np.ndarray:
        """Complex points whose convex hull contains every per-actuator factor ``g e^{i phi}`` within
        the tolerance: the outer arc's points, the corners of the polygon circumscribing it
        (``segments`` pieces) and the two inner corners. Every real quantity linear in ``M`` takes its
        largest value over the tolerance at one of them (:func:`worst_over_plants`). Read-only (the
        same array for the same tolerance and segments)."""
        return _factor_hull(self, segments)

    def _factor_hull(self, segments: int) -> np.ndarray:
        gmax, gmin, top = 1.0 + self.gain, 1.0 - self.gain, math.radians(self.phase_deg)
        if top == 0.0:
            return np.array([gmax, gmin], dtype=complex)
        phi = np.linspace(-top, top, segments + 1)
        half = 0.5 * (phi[1] - phi[0])
        outer = gmax * np.exp(1j * phi)
        tangents = gmax / math.cos(half) * np.exp(1j * (phi[:-1] + half))
        inner = gmin * np.exp(1j * np.array([-top, top]))
        return np.concatenate([outer, tangents, inner])


@lru_cache(maxsize=32)
def _factor_hull(tolerance: PlantTolerance, segments: int) -> np.ndarray:
    hull = tolerance._factor_hull(segments)
    hull.flags.writeable = False
    return hull


def worst_over_plants(W: np.ndarray, tolerance: PlantTolerance) -> tuple[np.ndarray, np.ndarray]:
    """The largest and the smallest value over every plant within ``tolerance`` of real quantities
    linear in the drive matrix ``M``: ``y = sum_lm Re(M_lm W_lm)``, ``W`` (..., 6, 6) complex.

    With ``M = diag(u) (1 + C)`` row ``l`` contributes ``Re(u_l W_ll) + sum_m C_lm Re(u_l W_lm)``; rows
    are independent, each coupling entry takes the sign that helps (``+-coupling``), and a convex
    function of ``u_l`` is largest at a vertex of :meth:`PlantTolerance.factor_hull`. So the result is
    exact up to the hull (a bound at most 1e-3 relative above the true worst: 1 / cos 2.5 deg). Returns (max y, -min y),
    each of shape ``W.shape[:-2]``."""
    W = np.asarray(W, dtype=complex)
    shape = W.shape[:-2] + (6,)
    up = np.full(shape, -np.inf)
    down = np.full(shape, -np.inf)
    re, im = W.real, W.imag
    for u in tolerance.factor_hull():
        R = u.real * re - u.imag * im      # Re(u W)
        d = np.diagonal(R, axis1=-2, axis2=-1)
        off = tolerance.coupling * (np.add.reduce(np.abs(R), axis=-1) - np.abs(d))
        np.maximum(up, d + off, out=up)
        np.maximum(down, off - d, out=down)
    return up.sum(axis=-1), down.sum(axis=-1)


#: The limits a goal keeps for every plant within the device's ``limits.plant_uncertainty``
#: (:meth:`Envelope.check_table` with an allowance): the instantaneous limits of the drive, which a
#: plant stronger than the model passes on the goal's first ramp-up, before the feedback has
#: measured it, and which the device protects itself from (its stopping faults). Not among them:
#: the coil temperature (a steady-state I^2 R estimate; the coils' time constant is 300 s and the
#: feedback measures the plant within about 1-2 s, after which the coils carry the nominal
#: feed-forward's currents) and the plate-side limits (the plate's motion, which the feedback
#: measures and corrects; docs/device.md, "Planning and limits").
DRIVE_LIMITS = (
    "limits.leg_stroke_m",
    "limits.coil_current_a",
    "limits.amplifier_voltage_v",
)


class Envelope:
    """The one envelope checker of a device (see the module docstring).

    Parameters
    ----------
    config : DeviceConfig
    plant : NominalPlant, optional
        Shared model instance (built from ``config`` when omitted).
    """

    def __init__(self, config: DeviceConfig, plant: NominalPlant | None = None):
        self.config = config
        self.plant = plant if plant is not None else NominalPlant(config)
        self.kinematics = self.plant.kinematics
        self._limit_values = self._limits_of(config)

    # ------------------------------------------------------------------ frequencies
    def forbidden(self, frequency_hz: float, k) -> list[tuple[int, str, float]]:
        """(harmonic, limit name, frequency Hz) of every harmonic ``k`` at a forbidden frequency."""
        lim = self.config.limits
        lo, hi = lim.frequency_range_hz
        out = []
        for kk in np.asarray(k, dtype=int).ravel():
            fk = float(kk * frequency_hz)
            if not lo <= fk <= hi:
                out.append((int(kk), "limits.frequency_range_hz", fk))
            elif any(b_lo <= fk <= b_hi for b_lo, b_hi in lim.excluded_bands_hz):
                out.append((int(kk), "limits.excluded_bands_hz", fk))
        return out

    def allowed_rows(self, frequency_hz: float, n_rows: int) -> np.ndarray:
        """Boolean mask (n_rows,): which rows 1..n_rows of a table may carry current."""
        bad = {kk for kk, _, _ in self.forbidden(frequency_hz, np.arange(1, n_rows + 1))}
        return np.array([kk not in bad for kk in range(1, n_rows + 1)], dtype=bool)

    # ------------------------------------------------------------------ checks
    def check_table(self, frequency_hz: float, currents: np.ndarray,
                    allowance: PlantTolerance | None = None) -> EnvelopeReport:
        """The envelope of a dense current table (K, 6) (A, row k-1 = harmonic k) at ``frequency_hz``.

        The plate motion, leg displacements and voltages are the nominal plant's prediction. With
        ``allowance`` (a table played on a plant not measured yet: a goal's), the limits of the drive
        (:data:`DRIVE_LIMITS`: leg stroke, peak coil current, amplifier voltage; the plant plays
        ``M I``) are the worst over the nominal plant and every plant within the allowance
        (:meth:`plant_worst`), and the report names the allowance (``allowance``, ``plant_bound``:
        the limits where a plant within it is worse than the nominal one, ``nominal_ratios``).
        """
        f = float(frequency_hz)
        if not (math.isfinite(f) and f > 0):
            raise ConfigError(f"frequency_hz: must be finite and > 0 Hz, got {frequency_hz!r}")
        I = np.asarray(currents, dtype=complex)
        if I.ndim != 2 or I.shape[1] != 6 or not np.all(np.isfinite(I)) or I.shape[0] > MAX_HARMONIC:
            raise ConfigError(
                f"currents: expected a finite (K <= {MAX_HARMONIC}, 6) table of coil-current phasors (A), "
                f"got shape {I.shape}"
            )
        rows = np.flatnonzero(np.any(I != 0, axis=1)) + 1
        values: dict[str, float] = {}
        ratios: dict[str, float] = {}
        worst: dict[str, int] = {}
        self._frequencies(f, rows, values, ratios)
        if rows.size == 0:
            for name in LIMIT_ORDER[2:]:
                values[name], ratios[name] = (GRAVITY_MPS2, 0.0) if "contact" in name else (0.0, 0.0)
            values["limits.coil_temperature_c"] = self.config.actuators.ambient_temperature_c
            return EnvelopeReport(f, values, ratios, self._limits(), (), worst)
        K = I.shape[0]
        k = np.arange(1, K + 1)
        out = self.plant.predict_all(f, I, ("voltage", "leg", "accel"))
        acc, ang, margin = motion_extremes(out["accel"], k, self.config.limits.working_radius_m)
        self._motion_values(acc, ang, margin, values, ratios)
        legs_linear = table_peak(out["leg"], k)
        motion = PlateMotion.from_phasors(f, k, out["accel"])
        legs_exact = self.exact_stroke(motion)
        legs = np.maximum(legs_linear, legs_exact)
        self._peak("limits.leg_stroke_m", legs, values, ratios, worst)
        self._actuators(I, table_peak(I, k), table_peak(out["voltage"], k), values, ratios, worst)
        forbidden = tuple(kk for kk, _, _ in self.forbidden(f, rows))
        if allowance is None or allowance.is_zero():
            return EnvelopeReport(f, values, ratios, self._limits(), forbidden, worst)
        nominal = dict(ratios)
        peaks = self.plant_worst(f, I, allowance, legs_linear, legs_exact)
        r_values: dict[str, float] = {}
        r_ratios: dict[str, float] = {}
        r_worst: dict[str, int] = {}
        self._peak("limits.leg_stroke_m", peaks["leg"], r_values, r_ratios, r_worst)
        self._peak("limits.coil_current_a", peaks["current"], r_values, r_ratios, r_worst)
        self._peak("limits.amplifier_voltage_v", peaks["voltage"], r_values, r_ratios, r_worst)
        bound = frozenset(name for name in DRIVE_LIMITS if r_ratios[name] > ratios[name])
        for name in bound:
            values[name], ratios[name], worst[name] = r_values[name], r_ratios[name], r_worst[name]
        return EnvelopeReport(f, values, ratios, self._limits(), forbidden, worst, allowance, nominal, bound)

    def plant_worst(self, frequency_hz: float, currents: np.ndarray, allowance: PlantTolerance,
                    legs_linear: np.ndarray | None = None,
                    legs_exact: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Bounds over every plant within ``allowance`` of a table's actuator-side quantities (the
        :data:`DRIVE_LIMITS`): the plant plays the drive ``M I`` through the nominal model
        (:func:`worst_over_plants`).

        Returns {"leg": peak leg displacement, "current": peak coil current, "voltage": peak amplifier
        voltage}, each (6,). The legs' second-order terms (the
        exact inverse kinematics' excess over the linear legs given in ``legs_exact`` and
        ``legs_linear``: 0.1 % of LineSinkX's stroke) are the nominal plant's, grown with the square of
        the worst linear amplitude."""
        f = float(frequency_hz)
        I = np.asarray(currents, dtype=complex)
        rows = np.flatnonzero(np.any(I != 0, axis=1))
        if rows.size == 0:
            return dict.fromkeys(("leg", "current", "voltage"), np.zeros(6))
        k = rows + 1
        Ik = I[rows]
        resp = self.plant.responses(f * k.astype(float), ("leg", "voltage"))
        eye = np.broadcast_to(np.eye(6, dtype=complex), resp["leg"].shape)
        H = np.concatenate([eye, resp["leg"], resp["voltage"]], axis=1)          # (K, 18, 6)

        def fn(theta):
            # y_o(theta) = Im sum_k (H_k M I_k)_o e^{i k theta} = sum_lm Re(M_lm W_olm)
            E = np.exp(1j * np.outer(theta, k))                                  # (n, K)
            up, down = worst_over_plants(-1j * np.einsum("tk,kol,km->tolm", E, H, Ik), allowance)
            return np.maximum(up, down)

        peaks = refined_max(fn, PEAK_SAMPLES_PER_PERIOD * int(k.max()))
        legs = peaks[6:12]
        if legs_linear is not None and legs_exact is not None:
            excess = np.maximum(np.asarray(legs_exact) - legs_linear, 0.0)
            grow = np.divide(legs, legs_linear, out=np.ones(6), where=np.asarray(legs_linear) > 0)
            legs = legs + excess * grow**2
        return {"leg": legs, "current": peaks[:6], "voltage": peaks[12:18]}

    def drive_ratio(self, motion: PlateMotion, allowance: PlantTolerance, enough: float = 1.0,
                    nominal: EnvelopeReport | None = None) -> float:
        """The largest ratio of the :data:`DRIVE_LIMITS` of ``motion``'s nominal feed-forward table over
        every plant within ``allowance`` (:meth:`check_table` with it), for a planner that must stay
        within what the generator accepts. When a quick bound is at most ``enough``, that bound is
        returned instead (an upper bound; the checker's own value is computed only above it): the
        nominal peak (``nominal``: the motion's :meth:`check_motion` report, computed if not given)
        plus the triangle inequality's bound of what ``M - 1`` adds, the stroke with 3 % more for the
        growth of the legs' second-order terms (0.5 % of the stroke's first harmonic at 65 % of it)."""
        active = motion.pruned()
        if active.is_zero():
            return 0.0
        f = float(active.frequency_hz)
        I = self.plant.feedforward(active, int(active.k.max()))
        if nominal is None:
            nominal = self.check_motion(active)
        rows = np.flatnonzero(np.any(I != 0, axis=1))
        resp = self.plant.responses(f * (rows + 1.0), ("leg", "voltage"))
        A = np.abs(I[rows])                                                      # (K, 6)
        # |((M - 1) I)_l| <= |u_l - 1| |I_l| + |u_l| coupling sum_{m != l} |I_m|, harmonic by harmonic.
        hull = allowance.factor_hull()
        dI = (float(np.max(np.abs(hull - 1.0))) * A
              + float(np.max(np.abs(hull))) * allowance.coupling * (A.sum(axis=1, keepdims=True) - A))
        lim, v = self.config.limits, nominal.values
        quick = max((v["limits.coil_current_a"] + float(np.max(dI.sum(axis=0)))) / lim.coil_current_a,
                    1.03 * (v["limits.leg_stroke_m"] + float(np.max(np.einsum("kol,kl->o", np.abs(resp["leg"]), dI))))
                    / lim.leg_stroke_m,
                    (v["limits.amplifier_voltage_v"]
                     + float(np.max(np.einsum("kol,kl->o", np.abs(resp["voltage"]), dI))))
                    / lim.amplifier_voltage_v)
        if quick <= enough:
            return quick
        report = self.check_table(f, I, allowance)
        return max(report.ratios[name] for name in DRIVE_LIMITS)

    def check_motion(self, motion: PlateMotion, currents: np.ndarray | None = None) -> EnvelopeReport:
        """The envelope of a plate motion: its own peaks, margin and exact stroke, and its table's
        current, thermal and voltage limits (``currents``: its table, default the nominal feed-forward
        of its harmonics)."""
        if not isinstance(motion, PlateMotion):
            raise ConfigError(f"motion: expected a PlateMotion, got {type(motion).__name__}")
        return self._check_group([motion.pruned()], [currents])[0]

    def check_motions(self, motions: Sequence[PlateMotion]) -> list[EnvelopeReport]:
        """:meth:`check_motion` of each motion (its nominal feed-forward table), in order. Motions of
        one frequency and one set of harmonics share the vectorised passes (plate peaks and margin,
        current and voltage peaks, each channel's as for its motion alone: bit for bit with one
        harmonic, to the last bit of a wider table's sums with more); the exact stroke is per motion."""
        actives = []
        for i, motion in enumerate(motions):
            if not isinstance(motion, PlateMotion):
                raise ConfigError(f"motions[{i}]: expected a PlateMotion, got {type(motion).__name__}")
            actives.append(motion.pruned())
        out: list[EnvelopeReport | None] = [None] * len(actives)
        for idx in harmonic_groups(actives).values():
            for i, report in zip(idx, self._check_group([actives[i] for i in idx], [None] * len(idx))):
                out[i] = report
        return out  # type: ignore[return-value]

    def _check_group(self, actives: list[PlateMotion], currents: list) -> list[EnvelopeReport]:
        """The checks of :meth:`check_motion` for pruned motions of one frequency and one set of
        harmonics (``currents``: per motion its table or None for the nominal feed-forward)."""
        f = actives[0].frequency_hz
        k_act = actives[0].k
        S = len(actives)
        freq_values: dict[str, float] = {}
        freq_ratios: dict[str, float] = {}
        self._frequencies(f, k_act, freq_values, freq_ratios)
        ext = motion_extremes_many(np.stack([a.phasors() for a in actives]) if k_act.size
                                   else np.zeros((S, 0, 6), complex), k_act, self.config.limits.working_radius_m)
        tables = []
        for a, I in zip(actives, currents):
            if I is None:
                top = int(a.k.max()) if a.num_harmonics else 0
                I = self.plant.feedforward(a, top) if top else np.zeros((1, 6), complex)
            tables.append(np.asarray(I, dtype=complex))
        volts = [self.plant.predict(f, I, "voltage") if np.any(I) else np.zeros_like(I) for I in tables]
        # Current and voltage peaks of every motion in one pass (one set of harmonics: the feed-forward
        # tables have the same rows; a table given to check_motion is a group of its own).
        peaks = table_peak(np.concatenate([np.concatenate([I, V], axis=1) for I, V in zip(tables, volts)], axis=1),
                           np.arange(1, tables[0].shape[0] + 1)).reshape(S, 2, 6)
        forbidden = tuple(kk for kk, _, _ in self.forbidden(f, k_act))
        strokes = self.exact_strokes(actives)
        reports = []
        for i in range(len(actives)):
            values, ratios = dict(freq_values), dict(freq_ratios)
            worst: dict[str, int] = {}
            self._motion_values(float(ext[i, 0]), float(ext[i, 1]), float(ext[i, 2]), values, ratios)
            self._peak("limits.leg_stroke_m", strokes[i], values, ratios, worst)
            self._actuators(tables[i], peaks[i][0], peaks[i][1], values, ratios, worst)
            reports.append(EnvelopeReport(f, values, ratios, self._limits(), forbidden, worst))
        return reports

    def check_plate(self, frequency_hz: float, accel: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
        """(values, ratios) of the :data:`PLATE_LIMITS` of a plate motion given by its acceleration
        phasors ``accel`` (K, 6) (rows harmonics 1..K; m/s^2 and rad/s^2), e.g. a measured one."""
        X = np.asarray(accel, dtype=complex)
        if X.ndim != 2 or X.shape[1] != 6 or not np.all(np.isfinite(X)):
            raise ConfigError(f"accel: expected a finite (K, 6) table of plate acceleration phasors, got {X.shape}")
        values: dict[str, float] = {}
        ratios: dict[str, float] = {}
        k = np.arange(1, X.shape[0] + 1)
        acc, ang, margin = motion_extremes(X, k, self.config.limits.working_radius_m)
        self._motion_values(acc, ang, margin, values, ratios)
        return values, ratios

    # ------------------------------------------------------------------ pieces
    def _limits(self) -> dict[str, float]:
        """Limit name -> limit value (a report's own copy)."""
        return dict(self._limit_values)

    @staticmethod
    def _limits_of(config: DeviceConfig) -> dict[str, float]:
        lim = config.limits
        return {
            "limits.frequency_range_hz": float(lim.frequency_range_hz[1]),
            "limits.excluded_bands_hz": float("nan"),
            "limits.plate_accel_mps2": lim.plate_accel_mps2,
            "limits.plate_angular_accel_radps2": lim.plate_angular_accel_radps2,
            "limits.contact_margin_mps2": lim.contact_margin_mps2,
            "limits.leg_stroke_m": lim.leg_stroke_m,
            "limits.coil_current_a": lim.coil_current_a,
            "limits.coil_temperature_c": lim.coil_temperature_c,
            "limits.amplifier_voltage_v": lim.amplifier_voltage_v,
        }

    def _frequencies(self, f: float, rows, values: dict, ratios: dict) -> None:
        bad = self.forbidden(f, rows)
        for name in ("limits.frequency_range_hz", "limits.excluded_bands_hz"):
            hits = [fk for _, n, fk in bad if n == name]
            values[name] = hits[0] if hits else float("nan")
            ratios[name] = math.inf if hits else 0.0

    def _motion_values(self, acc: float, ang: float, margin: float, values: dict, ratios: dict) -> None:
        lim = self.config.limits
        values["limits.plate_accel_mps2"] = acc
        ratios["limits.plate_accel_mps2"] = acc / lim.plate_accel_mps2
        values["limits.plate_angular_accel_radps2"] = ang
        ratios["limits.plate_angular_accel_radps2"] = ang / lim.plate_angular_accel_radps2
        values["limits.contact_margin_mps2"] = margin
        allowed_loss = GRAVITY_MPS2 - lim.contact_margin_mps2
        ratios["limits.contact_margin_mps2"] = max(0.0, GRAVITY_MPS2 - margin) / allowed_loss

    def exact_stroke(self, motion: PlateMotion, legs: LegTrajectory | None = None) -> np.ndarray:
        """Peak |leg displacement| per leg (6,) (m) of ``motion`` from the exact inverse kinematics
        (``legs``: its leg trajectory with harmonics up to 2 top, if already computed)."""
        if motion.is_zero():
            return np.zeros(6)
        top = int(motion.k.max())
        if legs is None or legs.k.size < 2 * top:
            legs = leg_trajectory(self.kinematics, motion, kmax=2 * top)
        return self._refined_strokes([legs], top)[0]

    def exact_strokes(self, motions: Sequence[PlateMotion]) -> np.ndarray:
        """:meth:`exact_stroke` of pruned motions of one frequency and one set of harmonics, (S, 6),
        in one vectorised pass (the kinematics and the peak search per leg and motion as alone)."""
        motions = list(motions)
        if not motions or motions[0].is_zero():   # a group's motions are all zero, or none is
            return np.zeros((len(motions), 6))
        top = int(motions[0].k.max())
        return self._refined_strokes(leg_trajectories(self.kinematics, motions, kmax=2 * top), top)

    def _refined_strokes(self, legs: list[LegTrajectory], top: int) -> np.ndarray:
        # The exact displacement is band-limited to 2 top to second order: refine its peak from
        # its harmonics and mean, and never report less than the sampled peak.
        S = len(legs)
        k = legs[0].k
        table = np.concatenate([lt.harmonics_m for lt in legs], axis=1)   # (K, S * 6)
        offset = np.concatenate([lt.mean_m for lt in legs])
        n = PEAK_SAMPLES_PER_PERIOD * 2 * top
        refined = refined_max(
            lambda th: np.abs(offset + _synthesize_columns(table, k, th)), n,
            at=lambda th: np.abs(offset + _synthesize_at(table, k, th)),
        )
        return np.maximum(refined, np.concatenate([lt.peak_m for lt in legs])).reshape(S, 6)

    def _peak(self, name: str, peaks: np.ndarray, values: dict, ratios: dict, worst: dict) -> None:
        j = int(np.argmax(peaks))
        values[name] = float(peaks[j])
        ratios[name] = float(peaks[j]) / self._limit_values[name]
        worst[name] = j

    def _actuators(self, I, current_peak, voltage_peak, values: dict, ratios: dict, worst: dict) -> None:
        a, lim = self.config.actuators, self.config.limits
        self._peak("limits.coil_current_a", current_peak, values, ratios, worst)
        i_rms = rms(I)
        j = int(np.argmax(i_rms))
        rise = a.thermal_resistance_k_per_w * a.resistance_ohm
        values["limits.coil_temperature_c"] = float(a.ambient_temperature_c + rise * i_rms[j] ** 2)
        allowed = max(lim.coil_temperature_c - a.ambient_temperature_c, 1e-12)
        ratios["limits.coil_temperature_c"] = float(i_rms[j] / math.sqrt(allowed / rise))
        worst["limits.coil_temperature_c"] = j
        self._peak("limits.amplifier_voltage_v", voltage_peak, values, ratios, worst)


__all__ = [
    "LIMIT_ORDER",
    "DRIVE_LIMITS",
    "PLATE_LIMITS",
    "Envelope",
    "EnvelopeReport",
    "motion_extremes",
    "harmonic_groups",
    "motion_extremes_many",
    "PlantTolerance",
    "refined_max",
    "worst_over_plants",
    "table_peak",
]
