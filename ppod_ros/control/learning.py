"""Learning control on harmonics: make the plate's measured acceleration match the goal.

Per harmonic k of the controlled set (1..3 at least, up to the goal's highest harmonic if larger),
with the tracking error e_k = goal_k - measured_k (harmonics the goal lacks have goal 0, so the
plate's own distortion is driven to zero too), the coil-current correction is updated by

    c_k <- c_k + gain * G_k^-1 e_k

with G_k the plant model (nominal or identified). With the true plant G*_k, the error evolves as
e <- (I - gain G*_k G_k^-1) e: it shrinks whenever the model is within the loop's margin (about 15 %
gain and 10 degrees phase error leave a factor of about 0.25 per iteration at gain 1). Every update
passes the device limits (peak current, step per iteration), the error measure is PHYSICS.md's
``||e|| / ||goal||`` (:func:`ppod_ros.motion.acceleration_error`), and the controller watches for
divergence (error growing N times in a row: it stops and asks for a ramp-down), convergence (error
within tolerance) and stalls (too little progress: a hint to re-identify the plant).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ppod_ros.control.limits import DeviceLimits, LimitFunction, LimitReport, check_within, peak_a
from ppod_ros.control.plant import PlantModel, PlantSource, as_plant
from ppod_ros.errors import ConfigError
from ppod_ros.estimation import PlateEstimate
from ppod_ros.estimation.harmonic_fit import settings_from_dict
from ppod_ros.motion import DEFAULT_LENGTH_SCALE_M, PlateMotion, acceleration_error

RUNNING, CONVERGED, STALLED, DIVERGED = "running", "converged", "stalled", "diverged"


@dataclass(frozen=True)
class LearningSettings:
    """Tuning of :class:`LearningController` (docs/feedback.md, "Learning control").

    Attributes
    ----------
    gain : float
        Learning gain in (0, 2); 1 cancels the whole error in one step when the model is exact.
    tolerance : float
        Converged when ``||e|| / ||goal||`` is at most this.
    min_harmonics : int
        Harmonics 1..max(min_harmonics, goal's K) are controlled.
    divergence_iterations : int
        Stop when the error grew this many iterations in a row (by more than ``growth_margin``) and
        the last error is above ``tolerance`` (below it, the changes are measurement noise).
    growth_margin : float
        Relative growth that counts as growing (noise makes small ups and downs).
    abort_error_relative : float
        Stop at once when the relative error exceeds this.
    stall_iterations, stall_improvement : int, float
        Stalled when, not converged, the error fell by less than this fraction over that many
        iterations.
    length_scale_m : float
        L of the error measure.
    """

    gain: float = 1.0
    tolerance: float = 0.01
    min_harmonics: int = 3
    divergence_iterations: int = 3
    growth_margin: float = 0.02
    abort_error_relative: float = 3.0
    stall_iterations: int = 3
    stall_improvement: float = 0.5
    length_scale_m: float = DEFAULT_LENGTH_SCALE_M

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "learning") -> LearningSettings:
        """Strict reader of a parameter mapping; missing keys keep their defaults."""
        return settings_from_dict(cls, data, where)

    def __post_init__(self) -> None:
        if not 0 < self.gain < 2:
            raise ConfigError(f"learning.gain: must be in (0, 2), got {self.gain}")
        if not 0 < self.tolerance < 1:
            raise ConfigError(f"learning.tolerance: must be in (0, 1), got {self.tolerance}")
        for name in ("min_harmonics", "divergence_iterations", "stall_iterations"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise ConfigError(f"learning.{name}: must be an integer >= 1, got {getattr(self, name)!r}")
        for name in ("growth_margin", "stall_improvement", "abort_error_relative", "length_scale_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"learning.{name}: must be finite and > 0, got {v}")


@dataclass(frozen=True)
class ControlStep:
    """What one update measured and decided.

    Attributes
    ----------
    iteration : int
        Number of updates so far (the measurement was taken with the correction of iteration - 1).
    k : ndarray of int, shape (Kc,)
        Controlled harmonics 1..Kc.
    correction_a : complex ndarray, shape (Kc, 6)
        The correction to send (absolute: replaces the generator's correction table), coil-current
        phasors (A) per harmonic and actuator. After divergence, the last one applied (frozen).
    measured, goal : complex ndarray, shape (Km, 6)
        Measured and goal phasors over harmonics 1..Km (Km >= Kc: all harmonics measured).
    error_norm, error_relative : float
        ||e|| (m/s^2, angular axes scaled by L) and ||e|| / ||goal|| over harmonics 1..Km.
    out_of_goal_relative : float
        Norm of the measured harmonics the goal lacks, relative to the norm of those it contains
        (the fundamental's, for a one-harmonic goal).
    state : str
        "running", "converged", "stalled" (progress too slow: re-identify) or "diverged".
    converged : bool
    ramp_down : bool
        True once diverged: the plate must be ramped down; the controller no longer updates
        (until :meth:`LearningController.reset`).
    limits : LimitReport
        Cuts made by the device limits in this update.
    message : str
    """

    iteration: int
    k: np.ndarray
    correction_a: np.ndarray
    measured: np.ndarray
    goal: np.ndarray
    error_norm: float
    error_relative: float
    out_of_goal_relative: float
    state: str
    converged: bool
    ramp_down: bool
    limits: LimitReport
    message: str = ""


def controlled_harmonics(goal: PlateMotion, min_harmonics: int = 3) -> np.ndarray:
    """Harmonics 1..max(min_harmonics, goal's highest k)."""
    kmax = max(min_harmonics, int(goal.k.max()) if goal.k.size else 0)
    return np.arange(1, kmax + 1)


def feedforward(goal: PlateMotion, plant: PlantModel, ks: Sequence[int]) -> np.ndarray:
    """Open-loop currents G_k^-1 goal_k (Kc, 6) over harmonics ``ks`` (zero where the goal has none)."""
    table = goal.phasor_table(int(max(ks)))
    return plant.solve(table[np.asarray(ks) - 1], ks)


class LearningController:
    """Per-harmonic learning control of one goal.

    Parameters
    ----------
    goal : PlateMotion
    plant : PlantModel, frequency-response callable or table
        The model G_k used in the update (covering the controlled harmonics).
    limits : DeviceLimits or callable
        ``limits(previous, proposed, feedforward) -> (correction, LimitReport)``.
    settings : LearningSettings
    feedforward_a : complex array_like, shape (Kc, 6), optional
        The currents the waveform generator applies without correction (A); default G_k^-1 goal_k
        from ``plant`` (pass the generator's own if it uses another model). Limits apply to
        feed-forward plus correction.
    initial_correction_a : complex array_like, shape (Kc, 6), optional
        Start from a cached correction (default zero).
    harmonics : int, optional
        Control harmonics 1..harmonics (default: 1..max(min_harmonics, the goal's highest); the
        feedback loop passes the rows of the generator's table, which include the third-order
        distortion products of the goal's harmonics).
    """

    def __init__(
        self,
        goal: PlateMotion,
        plant: PlantModel | PlantSource,
        limits: DeviceLimits | LimitFunction,
        settings: LearningSettings | None = None,
        *,
        feedforward_a: np.ndarray | None = None,
        initial_correction_a: np.ndarray | None = None,
        harmonics: int | None = None,
    ):
        if not isinstance(goal, PlateMotion):
            raise ConfigError(f"goal: expected a PlateMotion, got {type(goal).__name__}")
        self.settings = settings or LearningSettings()
        self.goal = goal
        self.k = controlled_harmonics(goal, self.settings.min_harmonics)
        if harmonics is not None:
            if int(harmonics) < int(goal.k.max(initial=1)):
                raise ConfigError(f"harmonics: {harmonics} would leave out the goal's harmonic {int(goal.k.max())}")
            self.k = np.arange(1, int(harmonics) + 1)
        #: Controlled harmonics the last measurement lacked (not updated; the goal has none there).
        self.unmeasured: list[int] = []
        self.plant = as_plant(plant, goal.frequency_hz, self.k)
        if not callable(limits):
            raise ConfigError("limits: expected DeviceLimits or a callable (previous, proposed, feedforward)")
        self.limits = limits
        Kc = self.k.size
        self.feedforward_a = (
            self._table(feedforward_a, "feedforward_a")
            if feedforward_a is not None
            else feedforward(goal, self.plant, self.k)
        )
        self.correction_a = (
            self._table(initial_correction_a, "initial_correction_a")
            if initial_correction_a is not None
            else np.zeros((Kc, 6), complex)
        )
        if isinstance(limits, DeviceLimits):
            check_within(limits, self.correction_a, self.feedforward_a)
        self.iteration = 0
        self.state = RUNNING
        self.errors: list[float] = []
        self._since_plant = 0

    def _table(self, value: np.ndarray, name: str) -> np.ndarray:
        arr = np.asarray(value, dtype=complex)
        if arr.shape != (self.k.size, 6) or not np.all(np.isfinite(arr)):
            raise ConfigError(
                f"{name}: expected finite complex shape ({self.k.size}, 6) (harmonics "
                f"{self.k.tolist()} x actuators), got {np.shape(value)}"
            )
        return arr.copy()

    @property
    def command_a(self) -> np.ndarray:
        """Feed-forward plus correction (Kc, 6), what the coils carry."""
        return self.feedforward_a + self.correction_a

    def replace_plant(self, plant: PlantModel | PlantSource) -> None:
        """Use a new plant model (after re-identification); learned corrections are kept."""
        self.plant = as_plant(plant, self.goal.frequency_hz, self.k)
        self._since_plant = 0
        if self.state == STALLED:
            self.state = RUNNING

    def reset(self, correction_a: np.ndarray | None = None) -> None:
        """Start learning afresh (after a divergence was dealt with): state, history and correction."""
        self.correction_a = (
            np.zeros((self.k.size, 6), complex)
            if correction_a is None
            else self._table(correction_a, "correction_a")
        )
        self.iteration = 0
        self.state = RUNNING
        self.errors = []
        self._since_plant = 0

    def sync_correction(self, correction_a: np.ndarray) -> None:
        """Set the correction actually applied (e.g. from a recording) before the next update."""
        self.correction_a = self._table(correction_a, "correction_a")

    def update(self, measured: PlateEstimate | np.ndarray) -> ControlStep:
        """One iteration: error of the measurement (taken with the current correction), next correction.

        ``measured`` is a :class:`PlateEstimate` or phasors (Km, 6) on harmonics 1..Km, Km >= Kc.
        """
        M = self._measured(measured)
        Km = M.shape[0]
        G = self.goal.phasor_table(Km)
        L = self.settings.length_scale_m
        err, rel = acceleration_error(G, M, L)
        ogr = self._out_of_goal(M)
        note = (f"harmonics {self.unmeasured} not measured (the device summarises fewer): not corrected"
                if self.unmeasured else "")
        if self.state == DIVERGED:
            return self._step(M, G, err, rel, ogr, LimitReport(), "diverged earlier: no further updates")
        self.iteration += 1
        self._since_plant += 1
        self.errors.append(rel)
        s = self.settings
        why = self._diverging(rel)
        if why:
            # Stop learning: the correction stays what was last applied (no further change, so no
            # step beyond the limits); the node has the generator ramp the whole output down.
            self.state = DIVERGED
            return self._step(M, G, err, rel, ogr, LimitReport(), why)
        e = G[: self.k.size] - M[: self.k.size]
        proposed = self.correction_a + s.gain * self.plant.solve(e, self.k)
        self.correction_a, report = self.limits(self.correction_a, proposed, self.feedforward_a)
        if rel <= s.tolerance:
            self.state = CONVERGED
        elif self._stalled():
            self.state = STALLED
        else:
            self.state = RUNNING
        return self._step(M, G, err, rel, ogr, report, note)

    # ------------------------------------------------------------------ helpers
    def _measured(self, measured: PlateEstimate | np.ndarray) -> np.ndarray:
        if isinstance(measured, PlateEstimate):
            if not math.isclose(measured.frequency_hz, self.goal.frequency_hz, rel_tol=1e-9):
                raise ConfigError(
                    f"measured: estimate is at {measured.frequency_hz:g} Hz, the goal at "
                    f"{self.goal.frequency_hz:g} Hz"
                )
            missing = sorted(set(self.k.tolist()) - set(measured.k.tolist()))
            in_goal = [k for k in missing if k in set(self.goal.pruned().k.tolist())]
            if in_goal:
                raise ConfigError(f"measured: estimate lacks the goal's harmonics {in_goal}")
            # Unmeasured distortion rows read as zero, the goal there: no error, no update.
            self.unmeasured = missing
            return measured.table(max(int(measured.k.max()), int(self.k.max())))
        self.unmeasured = []
        M = np.asarray(measured, dtype=complex)
        if M.ndim != 2 or M.shape[1] != 6 or M.shape[0] < self.k.size or not np.all(np.isfinite(M)):
            raise ConfigError(
                f"measured: expected finite phasors (Km >= {self.k.size}, 6) on harmonics 1..Km, "
                f"got shape {M.shape}"
            )
        return M

    def _out_of_goal(self, M: np.ndarray) -> float:
        # Relative to the measured harmonics the goal contains (the fundamental, for most goals).
        scale = np.array([1, 1, 1, *[self.settings.length_scale_m] * 3])
        present = np.zeros(M.shape[0], bool)
        present[[k - 1 for k in self.goal.pruned().k if k <= M.shape[0]]] = True
        inside = np.linalg.norm(M[present] * scale)
        other = np.linalg.norm(M[~present] * scale)
        return float(other / inside) if inside > 0 else (0.0 if other == 0 else math.inf)

    def _diverging(self, rel: float) -> str:
        s = self.settings
        if not math.isfinite(rel) or rel > s.abort_error_relative:
            return f"error {rel:.3g} of the goal > abort_error_relative {s.abort_error_relative:g}: stopped"
        n = s.divergence_iterations
        h = self.errors
        # Within the tolerance, successive errors are measurement noise around the goal: their
        # growth is not divergence (seen on the simulated device: 0.049 % -> 0.062 % in 4 steps).
        growing = all(h[-i] > h[-i - 1] * (1 + s.growth_margin) for i in range(1, n + 1)) if len(h) > n else False
        if growing and h[-1] > s.tolerance:
            return (
                f"error grew {n} iterations in a row ({' -> '.join(f'{x:.3g}' for x in h[-n - 1 :])}): "
                f"stopped, ramp down"
            )
        return ""

    def _stalled(self) -> bool:
        s = self.settings
        n = s.stall_iterations
        if self._since_plant <= n or len(self.errors) <= n:
            return False
        return self.errors[-1] > (1 - s.stall_improvement) * self.errors[-1 - n]

    def _step(self, M, G, err, rel, ogr, report, message) -> ControlStep:
        return ControlStep(
            iteration=self.iteration,
            k=self.k.copy(),
            correction_a=self.correction_a.copy(),
            measured=M,
            goal=G,
            error_norm=err,
            error_relative=rel,
            out_of_goal_relative=ogr,
            state=self.state,
            converged=self.state == CONVERGED,
            ramp_down=self.state == DIVERGED,
            limits=report,
            message=message,
        )

    def peak_command_a(self) -> np.ndarray:
        """Peak bound (6,) of the current command, feed-forward plus correction (A)."""
        return peak_a(self.command_a)


__all__ = [
    "CONVERGED",
    "DIVERGED",
    "RUNNING",
    "STALLED",
    "ControlStep",
    "LearningController",
    "LearningSettings",
    "controlled_harmonics",
    "feedforward",
]
