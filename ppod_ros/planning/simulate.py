"""Run a planning task against the full part dynamics (no asymptotic shortcut, no ROS, no camera):
what the planner's tests and ``ppod bench planner`` use to check that plans work on the physics.

By default the plate plays each motion exactly (no plant mismatch) and switches at once; a pose
the task sees is the true one plus Gaussian noise standing in for the tracker. A part that loses
contact lands where it is, at rest (as on the simulated device). Optionally, as the stack does:

- ``latency_s``: the task sees the poses of that long ago (the tracker's latency);
- ``ramp_s``: every switch is the generator's ramp (a linear crossfade of the phasors; across
  frequencies, down then up), or the motion's own ``ramp_time_s`` when it has one;
- ``plant``: a :class:`PlantError` (gain, phase and coupling errors of the played motion) that
  starts with each new motion and decays as the accelerometer feedback's transient does, or an
  :class:`ActuatorPlantError`, the plant as the running stack plays it (actuator errors and the
  drive's third harmonic, the feedback's learned start and transient, and the generator's checker
  scaling its corrections);
- ``separate``: a callback that keeps parts out of each other after each step (the simulated
  device's ppod_sim.scene.separate; ppod_ros does not import the simulator).

Parts do not touch each other unless ``separate`` is given.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ppod_ros.actuation.corrections import limit_over
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion, crossfade
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.physics import PartDynamics
from ppod_ros.planning.sensorless import SensorlessTask
from ppod_ros.planning.task import Task, TaskStep


@dataclass(frozen=True)
class PlantError:
    """The played motion is (I + E) X for a goal X, with E = diag(gain e^(i phase)) - I + coupling,
    scaled by ``first_fraction`` for the first ``unlearned_goals`` motions and ``learned_fraction``
    after (the feedback's learned plant predicts the start), decaying as exp(-t / decay_s)."""

    E: np.ndarray                         # (6, 6) complex
    decay_s: float = 0.3
    unlearned_goals: int = 2
    learned_fraction: float = 0.25

    @classmethod
    def random(cls, rng: np.random.Generator, gain: float = 0.15, phase_deg: float = 10.0, coupling: float = 0.05,
               **kwargs) -> PlantError:
        g = 1.0 + rng.uniform(-gain, gain, 6)
        ph = np.radians(rng.uniform(-phase_deg, phase_deg, 6))
        C = rng.uniform(-coupling, coupling, (6, 6))
        np.fill_diagonal(C, 0.0)
        # Coupling relative to each axis's typical scale (m/s^2 and rad/s^2 differ by 10x).
        scale = np.array([10.0, 10.0, 10.0, 100.0, 100.0, 100.0])
        C = C * scale[:, None] / scale[None, :]
        return cls(np.diag(g * np.exp(1j * ph)) - np.eye(6) + C, **kwargs)

    def played(self, motion, since_switch_s: float, goal_number: int, frame_s: float = 0.0):
        if motion is None or motion.is_zero():
            return motion
        frac = 1.0 if goal_number <= self.unlearned_goals else self.learned_fraction
        f = frac * math.exp(-max(0.0, since_switch_s) / self.decay_s)
        if f < 1e-4:
            return motion
        X = motion.phasors()
        X = X + f * (X @ self.E.T)
        return PlateMotion.from_phasors(motion.frequency_hz, motion.k, X, name=motion.name)


@dataclass
class ActuatorPlantError:
    """The plant as the running stack plays it (the simulated device's drive, the accelerometer
    feedback and the generator's checker), for closed loops without ROS.

    The actuators play ``M`` times the commanded currents (per actuator gain and phase errors and
    cross-coupling, as ``ppod_sim``'s drive), so a goal ``X`` played with the nominal feed-forward
    alone is ``P X`` with ``P = G0 M G0^-1`` per harmonic. The feedback starts a new goal from the
    correction its learned plant predicts and, after ``first_estimate_s`` (the ramp, settling and the
    first estimate), corrects the rest with time constant ``decay_s`` (the learning iterations).
    ``learning`` says what the learned plant predicts: "learner" (the benchmark's): the feedback's
    own :class:`~ppod_ros.control.learned_plant.PlantLearner`, taught a sample (the currents played
    and the plate they gave, with ``sample_noise``) at the first estimate and every
    ``sample_period_s`` after it while a motion plays, so a motion starts exact in the current
    directions already sampled and partly learned in others (measured against the stack's own
    feedback loop with the same actuator errors: docs/planner.md, "The plant learned motion by
    motion"); "goals": nothing for the first ``unlearned_goals`` motions, then all but
    ``learned_residual``, whatever was played. The generator applies at most the fraction ``s_max`` of
    the correction for which its checker keeps every limit (computed per motion by bisection, as the
    generator scales a correction back): the actuator-side limits through the nominal plant, the
    plate-side ones on the plate the feedback measures (here the true plate) with the nominal
    reading within ``limits.plant_model_allowance`` over them.

    ``third_harmonic``: as the simulated device's drive (``ppod_sim.drive``), each actuator's
    nonlinearity adds that fraction of its harmonic-k current at 3k (its played current: the one
    that plays ``X`` through the nominal plant), which the plate plays through the nominal plant at
    3k. The learned plant does not predict it (a learned start leaves it whole: on the running stack
    it is most of the 2.7-3.6 % a learned goal starts off, docs/feedback.md); the feedback's
    iterations remove it as they remove the rest.
    """

    M: np.ndarray                         # (6, 6) complex actuator error matrix
    device: object
    # Measured on the running stack's feedback (``ppod bench feedback --sections switching``, goals
    # switched every 1.5 s: every new goal from the third on starts a median 3.9 % off, most of it the
    # plant's third harmonic; the first two 12-18 %), and its iterations (the first estimate about 1 s
    # after a switch, then halving the error about every 0.7 s).
    unlearned_goals: int = 2
    learned_residual: float = 0.04
    first_estimate_s: float = 1.0
    decay_s: float = 1.0
    third_harmonic: float = 0.0
    learning: str = "goals"               # "goals" or "learner" (the class docstring)
    sample_period_s: float = 0.5          # "learner": a sample at the first estimate and every this after it
    sample_noise: float = 0.005           # "learner": each sample's measured plate phasors carry complex
                                          # Gaussian noise of this rms, relative to their own rms (the
                                          # accelerometer estimate's error), drawn from ``seed``
    seed: int = 0

    def __post_init__(self):
        from ppod_ros.control.learned_plant import PlantLearner
        from ppod_ros.planning.envelope import _envelope

        if self.learning not in ("goals", "learner"):
            raise ConfigError(f"ActuatorPlantError.learning: {self.learning!r} is not 'goals' or 'learner'")
        self._checker = _envelope(self.device)  # the planner's shared instance of the one checker
        self._smax: dict[bytes, float] = {}
        self._g0: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self.scaled_motions = 0               # motions whose corrections the checker scaled back
        self.learner = PlantLearner()
        self._learned: dict[tuple, np.ndarray] = {}   # (frequency, harmonics): the learned plant's inverse
        self._goal, self._taken = -1, 0       # the motion playing (its number) and its samples so far
        self._rng = np.random.default_rng(self.seed)

    @classmethod
    def random(cls, rng: np.random.Generator, device=None, gain: float = 0.15, phase_deg: float = 10.0,
               coupling: float = 0.05, third_harmonic: float | None = None, **kwargs) -> ActuatorPlantError:
        """Errors drawn as the simulated device's drive draws them; ``third_harmonic`` None: the
        device's simulated mismatch (``sim.mismatch.third_harmonic``, 0.03 in the packaged device)."""
        from ppod_ros.device import default_device_config

        device = device or default_device_config()
        g = 1.0 + rng.uniform(-gain, gain, 6)
        ph = np.radians(rng.uniform(-phase_deg, phase_deg, 6))
        C = rng.uniform(-coupling, coupling, (6, 6))
        np.fill_diagonal(C, 0.0)
        if third_harmonic is None:
            third_harmonic = float(device.sim.mismatch.third_harmonic)
        return cls(np.diag(g * np.exp(1j * ph)) @ (np.eye(6) + C), device, third_harmonic=third_harmonic,
                   **kwargs)

    def _maps(self, motion, factor: int = 1):
        """The nominal plant G0 (K, 6, 6) at the motion's harmonics (times ``factor``) and its
        inverse, once per set (every step of a closed loop plays a motion at the same few frequencies)."""
        key = (float(motion.frequency_hz), tuple(int(k) * factor for k in motion.k))
        if key not in self._g0:
            G0 = self._checker.plant.frequency_response(motion.frequency_hz * np.array(key[1], float))
            self._g0[key] = (G0, np.linalg.inv(G0))
        return self._g0[key]

    def distortion(self, motion) -> tuple[np.ndarray, np.ndarray]:
        """The harmonics 3k and the plate's acceleration phasors (K, 6) there that the actuators'
        nonlinearity adds to ``motion`` (``third_harmonic``; as ``ppod_sim.drive.ActuatorDrive``)."""
        G0, G0inv = self._maps(motion)
        current = np.einsum("kij,kj->ki", G0inv, motion.phasors())   # the played currents (K, 6)
        mag2 = np.abs(current) ** 2
        cubed = np.divide(current ** 3, mag2, out=np.zeros_like(current), where=mag2 > 0)
        G3, _ = self._maps(motion, 3)
        return 3 * motion.k, self.third_harmonic * np.einsum("kij,kj->ki", G3, cubed)

    def uncorrected(self, motion):
        """``P X``: the motion the nominal feed-forward alone plays."""
        G0, G0inv = self._maps(motion)
        X = np.einsum("kij,jl,klm,km->ki", G0, self.M, G0inv, motion.phasors())
        return PlateMotion.from_phasors(motion.frequency_hz, motion.k, X, name=motion.name)

    def max_correction(self, motion) -> float:
        """The largest fraction of the full correction the generator's checker lets through."""
        key = motion.key
        if key not in self._smax:
            G0, G0inv = self._maps(motion)
            X = motion.phasors()
            ff = np.einsum("kij,kj->ki", G0inv, X)
            full = np.einsum("ij,kjl,kl->ki", np.linalg.inv(self.M), G0inv, X) - ff
            kmax = int(motion.k.max())

            allowance = float(self.device.limits.plant_model_allowance)
            P = self.uncorrected(motion).phasors()

            def ok(s: float) -> bool:
                # As the generator judges a corrected table (actuation/corrections.py): every limit
                # on the nominal plant, except the plate-side ones, which are judged on the measured
                # plate (here the true one) with the nominal reading bounded by the allowance.
                table = np.zeros((kmax, 6), complex)
                table[motion.k - 1] = ff + s * full
                ratios = self._checker.check_table(motion.frequency_hz, table).ratios
                true = None
                if allowance > 0:
                    plate = np.zeros((kmax, 6), complex)
                    plate[motion.k - 1] = X + (1.0 - s) * (P - X)
                    true = self._checker.check_plate(motion.frequency_hz, plate)[1]
                return not any(limit_over(n, ratios, true, 1.0, allowance) for n in ratios)

            if ok(1.0):
                s_max = 1.0
            else:
                lo, hi = 0.0, 1.0
                for _ in range(10):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if ok(mid) else (lo, mid)
                s_max = lo
                self.scaled_motions += 1
            self._smax[key] = s_max
        return self._smax[key]

    def _corrected(self, motion, since_switch_s: float, start: float) -> float:
        """The fraction of an error the feedback has corrected ``since_switch_s`` after the switch:
        ``start`` (what it predicted) until its first estimate, then the rest learned with time
        constant ``decay_s``; at most what the checker lets through (``max_correction``)."""
        t = max(0.0, since_switch_s - self.first_estimate_s)
        return min(self.max_correction(motion), 1.0 - (1.0 - start) * math.exp(-t / self.decay_s)
                   if since_switch_s >= self.first_estimate_s else start)

    def _learned_inverse(self, motion) -> np.ndarray:
        """The inverse (K, 6, 6) of the plant learned so far at the motion's harmonics (the nominal
        plant's where the learner has nothing or its plant is not used, as the feedback does)."""
        from ppod_ros.control.plant import PlantModel

        key = (float(motion.frequency_hz), tuple(int(k) for k in motion.k))
        if key not in self._learned:
            G0, G0inv = self._maps(motion)
            try:
                model = self.learner.model(PlantModel(motion.frequency_hz, motion.k, G0))
                self._learned[key] = G0inv if model.source != "learned" else np.linalg.inv(model.G)
            except (ConfigError, np.linalg.LinAlgError):
                self._learned[key] = G0inv
        return self._learned[key]

    def _played_learned(self, motion, since_switch_s: float, goal_number: int, frame_s: float) -> np.ndarray:
        """``learning == "learner"``: the plate phasors (K, 6) of ``motion`` over the frame of
        ``frame_s`` from ``since_switch_s`` after the switch to motion number ``goal_number``: the
        currents start from the learned plant's prediction ``I0 = G^-1 X`` and move towards the exact
        ``I* = (G0 M)^-1 X`` as the feedback iterates (:meth:`_corrected`); the learner is taught a
        sample (the currents and what they played) when the frame ends at or after the first estimate
        and every ``sample_period_s`` after it."""
        G0, G0inv = self._maps(motion)
        X = motion.phasors()
        exact = np.einsum("ij,kjl,kl->ki", np.linalg.inv(self.M), G0inv, X)
        start = np.einsum("kij,kj->ki", self._learned_inverse(motion), X)
        s = self._corrected(motion, since_switch_s, 0.0)
        current = start + s * (exact - start)
        Y = np.einsum("kij,jl,kl->ki", G0, self.M, current)
        if goal_number != self._goal:
            self._goal, self._taken = goal_number, 0
        if since_switch_s + frame_s >= self.first_estimate_s + self._taken * self.sample_period_s - 1e-9:
            kmax = int(motion.k.max())
            goal, measured = (np.zeros((kmax, 6), complex) for _ in range(2))
            noise = (self._rng.normal(size=Y.shape) + 1j * self._rng.normal(size=Y.shape)) / math.sqrt(2.0)
            goal[motion.k - 1] = X
            measured[motion.k - 1] = Y + self.sample_noise * math.sqrt(np.mean(np.abs(Y) ** 2)) * noise
            if self.learner.observe(motion.frequency_hz, goal, motion.k, current, measured):
                self._learned.clear()
            self._taken += 1
        return Y

    def played(self, motion, since_switch_s: float, goal_number: int, frame_s: float = 0.0):
        if motion is None or motion.is_zero():
            return motion
        if self.learning == "learner":
            Y = self._played_learned(motion, since_switch_s, goal_number, frame_s)
        else:
            start = 0.0 if goal_number <= self.unlearned_goals else 1.0 - self.learned_residual
            s = self._corrected(motion, since_switch_s, start)
            P = self.uncorrected(motion).phasors()
            X = motion.phasors()
            Y = X + (1.0 - s) * (P - X)
        if not self.third_harmonic:
            return PlateMotion.from_phasors(motion.frequency_hz, motion.k, Y, name=motion.name)
        # Not predicted by the learned plant (nothing corrected at the start), then learned away.
        left = 1.0 - self._corrected(motion, since_switch_s, 0.0)
        k3, D = self.distortion(motion)
        ks = np.union1d(motion.k, k3)
        table = np.zeros((len(ks), 6), complex)
        table[np.searchsorted(ks, motion.k)] += Y
        np.add.at(table, np.searchsorted(ks, k3), left * D)
        return PlateMotion.from_phasors(motion.frequency_hz, ks, table, name=motion.name)


def _ramp(motion, default_s: float) -> float:
    """The ramp to ``motion``: its own ``ramp_time_s`` when it has one, else the default (as the
    generator does); none without a default (the plate switches at once)."""
    if default_s <= 0 or motion is None:
        return default_s
    return motion.ramp_time_s if motion.ramp_time_s else default_s


@dataclass(frozen=True)
class SimulatedRun:
    step: TaskStep | None        # the task's last step
    configurations: np.ndarray  # (N, 3) final [x, y, theta]
    elapsed_s: float            # device time from the first step to the end
    hops: int                   # contact losses (parts put back at rest)
    motions: int                # motions the task asked for
    trajectory: np.ndarray      # (T, N, 3) the true configurations at every step, then the final ones
    times: np.ndarray | None = None          # (T,) device time of each trajectory row
    steps: list | None = None                 # every step the task returned
    switch_times: tuple[float, ...] = ()      # device time of each motion switch


def _searched(task, step) -> bool:
    """The step's motion came from a search (the planning time the stack pays before it plays)."""
    searched = getattr(task, "plan_searched", None)
    if searched is None:
        return True
    return bool(step.plan_ms > 0 and searched and searched[-1])


def run_on_dynamics(task: Task | SensorlessTask, parts: Sequence[PointPart | RigidPart], starts, *,
                    horizon_s: float = 60.0, dt_s: float = 0.1, position_noise_m: float = 5e-5,
                    angle_noise_rad: float = math.radians(0.1), seed: int = 0, latency_s: float = 0.0,
                    ramp_s: float = 0.0, plant: PlantError | ActuatorPlantError | None = None,
                    separate: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                    keep_steps: bool = False, command_latency_s: float = 0.0) -> SimulatedRun:
    """Step ``task`` every ``dt_s`` on the parts' poses until it ends or ``horizon_s`` passes.
    A SensorlessTask is shown no poses. ``separate(configurations, twists)`` modifies both in
    place and returns the indices it moved. ``command_latency_s``: a motion the task returns from a
    search (a MultiTask step that searched its candidates; every motion of another task) starts
    playing this long (whole frames) after the frame it was planned on, as in the running stack
    where the field planner node publishes it when its planning thread is done; the frames in
    between are not stepped (the node skips them). A stop takes a MultiTask a few ms: it plays at
    once."""
    rng = np.random.default_rng(seed)
    dyn = PartDynamics(list(parts), np.array(starts, dtype=float))
    sensorless = isinstance(task, SensorlessTask)
    motion, t, step, hops, motions = None, 0.0, None, 0, 0
    previous, switched_at = None, 0.0
    path, times, steps, switches = [], [], [], []
    lag = max(0, int(round(latency_s / dt_s)))
    command_lag = max(0, int(round(command_latency_s / dt_s)))
    pending: tuple[float, object] | None = None   # (when it plays, the motion) under command_latency_s
    while t < horizon_s + 1e-9:
        path.append(dyn.state.configurations)
        times.append(t)
        poses = None
        if not sensorless:
            poses = path[max(0, len(path) - 1 - lag)].copy()
            poses[:, :2] += rng.normal(0.0, position_noise_m, (len(parts), 2))
            poses[:, 2] += rng.normal(0.0, angle_noise_rad, len(parts))
        new = None
        if pending is not None:
            if t >= pending[0] - 1e-9:
                new, pending = pending[1], None
        else:
            step = task.step(t, poses)
            if keep_steps:
                steps.append(step)
            if step.motion is not None:
                if command_lag and _searched(task, step):
                    pending = (t + command_lag * dt_s, step.motion)
                    report = getattr(task, "command_latency", None)
                    if report is not None:   # as the field planner node reports it on publishing
                        report(command_lag * dt_s)
                else:
                    new = step.motion
        if new is not None:
            if motion is None and dyn.time_s != t:   # the first motion plays late: the parts rested till now
                dyn = PartDynamics(list(parts), dyn.state.configurations, time_s=t)
            r = _ramp(motion, ramp_s)
            previous = crossfade(previous, motion, min(1.0, (t - switched_at) / r)) if r > 0 and motion \
                is not None else motion
            motion, motions, switched_at = new, motions + 1, t
            switches.append(t)
        if step.done or step.failed_reason:
            break
        if motion is not None:
            since = t - switched_at
            played = motion
            r = _ramp(motion, ramp_s)
            if r > 0 and since < r:
                played = crossfade(previous, motion, min(1.0, (since + 0.5 * dt_s) / r))
            if plant is not None:
                played = plant.played(played, since, motions, dt_s)
            if played is not None:
                state = dyn.advance(played, t, dt_s)
                for i in np.flatnonzero(state.status != 0):
                    dyn.set_part(int(i), state.configurations[i])
                    hops += 1
                if separate is not None:
                    st = dyn.state
                    cfg, tw = st.configurations.copy(), st.twists.copy()
                    moved = separate(cfg, tw)
                    if len(moved):
                        dyn.set_parts(np.asarray(moved, dtype=int), cfg[moved], tw[moved])
        t += dt_s
    final = dyn.state.configurations
    return SimulatedRun(step, final, t, hops, motions, np.array(path + [final]), np.array(times + [t]),
                        steps if keep_steps else None, tuple(switches))


__all__ = ["ActuatorPlantError", "PlantError", "SimulatedRun", "run_on_dynamics"]
