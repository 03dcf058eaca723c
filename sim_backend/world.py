"""The simulated world without ROS: the device, the parts on its plate, and the triggered camera.

:class:`SimWorld` wires three simulations together on the device's clock:

* the device (:class:`~ppod_sim.process.SimProcess`: firmware, plant, accelerometers, CAN bridge);
* the parts (:class:`~ppod_ros.physics.PartDynamics`): after every completed plate cycle they are
  advanced over that cycle with the plate's *actual* motion in it (``CycleTruth.motion()``, ramps and
  mismatch included), then kept out of each other (:func:`~ppod_sim.scene.separate`); a part whose
  centre leaves the plate falls off and is no longer simulated;
* the camera: a frame ticks every 1/fps of device time and is exposed at the first cycle start after
  the tick (a triggered camera: same plate phase every frame), with the parts' poses at that instant.
  Rendering runs in its own thread, only while ``camera_enabled`` is set (someone subscribes).

Listeners get every cycle (``on_cycle(truth, parts)``), every frame tick (``on_tick(stamp_s, parts)``,
with or without a camera: ground truth at the frame rate) and every rendered frame
(``on_frame(frame, parts)``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ppod_ros.device.config import DeviceConfig
from ppod_ros.physics import DynamicsState, PartDynamics, SolverSettings
from ppod_ros.physics.settings import REASONS
from ppod_ros.vision.camera import CameraConfig
from ppod_sim.camera import CameraRenderer, RenderedFrame, RenderPart
from ppod_sim.process import SimProcess
from ppod_sim.scene import Scene
from ppod_sim.separation import pack_circles, separate
from ppod_sim.truth import CycleTruth

log = logging.getLogger(__name__)

#: The parts physics' solver settings (one thread: see SimWorld.__init__). The rigid parts' stick-slip
#: is the costly part: a contact that pivots (at rest while the part turns about it) is held by the
#: regularised Coulomb law -mu N u / eps, whose stiffness (mu g / eps) limits the explicit steps to
#: about eps / (mu g). At the solver's default eps (1e-6 m/s) the planner's pivot took up to 700 000
#: steps per second of device time, more CPU than the second itself (issue 16). Here eps is 3e-6 m/s
#: and the sticking test starts below 3 eps (9e-6 m/s; 1e-5 before). On four recorded demo runs
#: (25-60 s; ppod bench sim_parts) the parts took 1.2-2.1x less CPU, their heaviest second of device
#: time 2.1-3.1x less (1.53 -> 0.49 s, 2.65 -> 1.06 s), and every part stayed within 0.018 mm and
#: 0.029 deg of the old model integrated with 100x tighter tolerances (the deviation grows with the
#: time spent pivoting, in proportion to eps: 1e-5 was 2.5x cheaper again in the heaviest second but
#: 0.07 mm and 0.11 deg off after 60 s). The tracker's noise is about 0.1 mm. rigid_rtol stays 1e-8:
#: 1e-6 with this eps made the pivot "lose contact" 15 times in 60 s. The solver's defaults, which
#: the planner's predictions use, are unchanged.
SIM_SOLVER = SolverSettings(threads=1, friction_eps_mps=3e-6, stick_capture=3.0)


@dataclass(frozen=True)
class PartsTruth:
    """The parts at one instant: poses (N, 3), twists (N, 3), on the plate, contact lost."""

    time_s: float
    poses: np.ndarray
    twists: np.ndarray
    on_plate: np.ndarray
    contact_lost: np.ndarray


class SimWorld:
    """See the module docstring.

    Parameters
    ----------
    config : DeviceConfig
    scene : Scene
    camera : CameraConfig or None
        None: no camera.
    port, rate, seed : see :class:`~ppod_sim.process.SimProcess` (seed defaults to the scene's).
    plate_half_size_m : float
        Parts whose centre leaves the square |x|, |y| <= this fall off the plate.
    separation_gap_m : float
        Clearance kept between parts' outlines (their circle covers).
    tick_fps : float
        Frame-tick rate without a camera (with one, the camera's fps).
    """

    def __init__(self, config: DeviceConfig, scene: Scene, camera: CameraConfig | None = None, *,
                 port: int = 0, rate: float = 1.0, seed: int | None = None, plate_half_size_m: float = 0.175,
                 separation_gap_m: float = 0.002, solver: SolverSettings | None = None, channel: str | None = None,
                 tick_fps: float = 10.0):
        self.scene = scene
        self.process = SimProcess(config, port=port, rate=rate, seed=scene.seed if seed is None else seed,
                                  channel=channel)
        self.device = self.process.device
        # The parts physics runs beside the device loop: one thread, so no call ever waits for a
        # second thread or loads a parallel kernel mid-run (a stall there delays device time).
        solver = solver if solver is not None else SIM_SOLVER
        self.dynamics = PartDynamics([p.part for p in scene.parts], scene.poses, settings=solver,
                                     time_s=self.device.time_s)
        self.circles = pack_circles([p.circles for p in scene.parts])  # packed once, not per cycle
        self.masses = scene.masses_kg
        self.on_plate = np.ones(len(scene.parts), bool)
        self.half_size = plate_half_size_m
        self.gap = separation_gap_m
        self.on_cycle: list[Callable[[CycleTruth, PartsTruth], None]] = []
        self.on_frame: list[Callable[[RenderedFrame, PartsTruth], None]] = []
        self.on_tick: list[Callable[[float, PartsTruth], None]] = []
        self.camera_enabled = threading.Event()
        self.renderer = None if camera is None else CameraRenderer(camera, seed=scene.seed)
        self.fps = camera.fps if camera is not None else tick_fps
        self._next_tick_s = self.device.time_s
        self._frames: queue.Queue = queue.Queue(maxsize=2)
        self.frames_dropped = 0
        self.frames_rendered = 0
        self.physics_s = 0.0
        self._lock = threading.Lock()
        self._truth = self._snapshot(self.dynamics.state)
        self._render_thread: threading.Thread | None = None
        self._stop_render = threading.Event()
        # The parts are advanced in a thread of their own, fed each completed cycle: the device
        # thread keeps its real-time pace (its heartbeat watchdog must not see physics stalls).
        self._cycles: queue.Queue = queue.Queue()
        self._physics_thread: threading.Thread | None = None
        self.device.cycle_callbacks.append(self._cycles.put)
        # Back-pressure: the device waits while the parts lag more than max_backlog_cycles behind
        # it (a heavy stretch of stick-slip, say), so poses, frames and the plate stay one world;
        # the pacer then gives up the lag (the run is slower than real time, and says so).
        self.max_backlog_cycles = 3
        self.backpressure_s = 0.0
        self.process.on_step.append(self._wait_for_parts)

    @property
    def url(self) -> str:
        return self.process.url

    # ------------------------------------------------------------------ per cycle
    def _snapshot(self, state: DynamicsState) -> PartsTruth:
        return PartsTruth(state.time_s, state.configurations.copy(), state.twists.copy(), self.on_plate.copy(),
                          state.contact_lost.copy())

    def parts_truth(self) -> PartsTruth:
        with self._lock:
            return self._truth

    def _physics_loop(self) -> None:
        while True:
            truth = self._cycles.get()
            if truth is None:
                return
            self._cycle(truth)

    def _wait_for_parts(self, _device) -> None:
        if self._physics_thread is None or not self._physics_thread.is_alive():
            return
        t0 = time.monotonic()
        while self._cycles.unfinished_tasks > self.max_backlog_cycles and time.monotonic() - t0 < 2.0:
            time.sleep(0.001)
        self.backpressure_s += time.monotonic() - t0

    def drain(self, timeout_s: float = 5.0) -> None:
        """Wait until the parts have caught up with every completed cycle."""
        deadline = time.monotonic() + timeout_s
        while self._cycles.unfinished_tasks and time.monotonic() < deadline:
            time.sleep(0.005)

    def _cycle(self, truth: CycleTruth) -> None:
        try:
            self.advance_parts(truth)
        finally:
            self._cycles.task_done()

    def advance_parts(self, truth: CycleTruth) -> None:
        """Advance the parts over one completed plate cycle (called per cycle by the physics thread;
        benchmarks feed it cycles directly to time the parts physics alone)."""
        start, period = truth.start_time_s, 1.0 / truth.frequency_hz
        if self.fps > 0 and start >= self._next_tick_s - 1e-9:
            while self._next_tick_s <= start + 1e-9:
                self._next_tick_s += 1.0 / self.fps
            for cb in self.on_tick:
                cb(start, self._truth)
            if self.renderer is not None and self.camera_enabled.is_set():
                self._queue_frame(truth)
        # The truth's phasors refer to this cycle's start; the dynamics wants absolute device time.
        motion = truth.motion(absolute_time=True)
        t0 = time.perf_counter()
        state = self.dynamics.advance(motion, start, period)
        hopped = np.flatnonzero(self.on_plate & (state.status != 0))
        for i in hopped:
            # Contact lost (or the integration gave up): the part hops and lands where it is. The
            # dynamics cannot follow a flight; the part is put back on the plate at rest.
            log.warning("part %d (%s) lost contact (%s) at (%.3f, %.3f): put back on the plate at rest",
                        i, self.scene.parts[i].label, REASONS.get(int(state.status[i]), "?"),
                        *state.configurations[i, :2])
        if hopped.size:
            self.dynamics.set_parts(hopped, state.configurations[hopped])
            state = self.dynamics.state
        xy, v = state.configurations[:, :2].copy(), state.twists[:, :2].copy()
        active = self.on_plate & ~state.contact_lost
        moved = separate(xy, v, state.configurations[:, 2], self.circles, self.masses, active, self.gap)
        if moved.size:
            self.dynamics.set_parts(moved, np.column_stack([xy[moved], state.configurations[moved, 2]]),
                                    np.column_stack([v[moved], state.twists[moved, 2]]))
        off = self.on_plate & (np.abs(xy).max(axis=1) > self.half_size)
        if np.any(off):
            for i in np.flatnonzero(off):
                log.warning("part %d (%s) fell off the plate at (%.3f, %.3f)", i, self.scene.parts[i].label,
                            *xy[i])
            self.on_plate &= ~off
        self.physics_s += time.perf_counter() - t0
        snap = self._snapshot(self.dynamics.state if moved.size else state)
        with self._lock:
            self._truth = snap
        for cb in self.on_cycle:
            cb(truth, snap)

    # ------------------------------------------------------------------ camera
    def _queue_frame(self, truth: CycleTruth) -> None:
        # Poses at this cycle's start: the state before this cycle's advance.
        parts = self._truth
        disp = truth.motion().displacement(0.0)
        try:
            self._frames.put_nowait((truth.start_time_s, parts, disp))
        except queue.Full:
            self.frames_dropped += 1

    def _render_loop(self) -> None:
        while not self._stop_render.is_set():
            try:
                stamp, parts, disp = self._frames.get(timeout=0.1)
            except queue.Empty:
                continue
            shown = [RenderPart(p.label, p.outline, *parts.poses[i], p.height_m)
                     for i, p in enumerate(self.scene.parts) if parts.on_plate[i]]
            frame = self.renderer.render(shown, stamp, plate_displacement=disp)
            self.frames_rendered += 1
            for cb in self.on_frame:
                cb(frame, parts)

    # ------------------------------------------------------------------ running
    def run(self, stop: threading.Event | None = None, duration_s: float | None = None) -> None:
        """Run the device (and with it the parts and the camera) until ``stop`` or ``duration_s``."""
        if self.renderer is not None and self._render_thread is None:
            self._render_thread = threading.Thread(target=self._render_loop, daemon=True, name="sim-camera")
            self._render_thread.start()
        if self._physics_thread is None:
            self._physics_thread = threading.Thread(target=self._physics_loop, daemon=True, name="sim-parts")
            self._physics_thread.start()
        self.process.run(stop, duration_s)

    def close(self) -> None:
        if self._physics_thread is not None:
            self._cycles.put(None)
            self._physics_thread.join(timeout=5)
        self._stop_render.set()
        if self._render_thread is not None:
            self._render_thread.join(timeout=5)
        self.process.close()
