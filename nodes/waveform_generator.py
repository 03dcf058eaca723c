"""waveform_generator: plate-motion goals in, voice-coil current tables out over CAN.

Lifecycle node (STYLE.md rule 9); the logic is ppod_ros.actuation.generator.WaveformGenerator:
  configure  load the device description, open the CAN bus, protocol-version handshake
  activate   receive device frames, send heartbeats, accept goals and corrections
  deactivate ramp the plate to rest, disable the device, stop heartbeats
  cleanup    close the bus
  shutdown   ramp to rest and disable from any state (Ctrl-C, SIGTERM, launcher stop)

Goals come on a topic (ppod/plate_motion_goal) or the SetPlateMotion service (with dry_run); each
is checked against every device limit and either sent (ramped) or rejected whole naming the limit,
with nothing sent. Corrections (HarmonicCorrection, from accel_feedback) are clipped and applied to
the active goal only. The emergency-stop service works in every state, also before configure.
ppod/capture_raw (Trigger) asks the device for raw_cycles whole cycles of raw accelerometer samples
and writes them, when they arrive, as an .npz recording under raw_dir (for ppod calibrate accel).
Publishes the active motion and its status (transient local), the device status and diagnostics.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from ppod_msgs.msg import DeviceStatus, HarmonicCorrection, PlateMotionStatus
from ppod_msgs.msg import PlateMotion as PlateMotionMsg
from ppod_msgs.srv import SetPlateMotion
from std_srvs.srv import Trigger

from ppod_nodes.common import diagnostics as diag
from ppod_nodes.common import qos, topics
from ppod_nodes.common.convert import motion_from_msg, motion_to_msg
from ppod_nodes.common.lifecycle import PpodLifecycleNode
from ppod_nodes.common.params import Param
from ppod_nodes.common.runner import make_main
from ppod_ros.actuation.generator import GeneratorState, GoalOutcome, WaveformGenerator
from ppod_ros.actuation.planning import GoalPlanner
from ppod_ros.can import DeviceLink, open_bus, open_bus_waiting, send_estop
from ppod_ros.can.keeper import keeper_supported
from ppod_ros.can.load import MeteredBus
from ppod_ros.can.protocol import MAX_RAW_CYCLES
from ppod_ros.device import load_device_config
from ppod_ros.errors import ConfigError, DeviceError
from ppod_ros.estimation import write_recording
from ppod_ros.estimation.recording import recording_from_captures
from ppod_ros.motion import PlateMotion

RESET_ESTOP = topics.RESET_ESTOP


class WaveformGeneratorNode(PpodLifecycleNode):
    RUNTIME_PARAMS = ("status_rate_hz",)  # applied at once (apply_parameter); the rest are read-only
    PARAMS = (
        Param("device_config", "", "device description YAML; empty: the packaged default (docs/device.md)"),
        Param("can_interface", "", "override can.interface (virtual, remote, socketcan, ...)"),
        Param("bus_wait_s", 10.0, "keep trying to open the bus this long at configure (s)", min_value=0.0),
        Param("can_channel", "", "override can.channel (e.g. ws://127.0.0.1:54701/ for the simulator)"),
        Param("heartbeat_clock", "wall", "heartbeats on the wall clock from their own thread ('wall', for "
              "real-time devices) or on the ROS clock ('ros': simulated time faster than real time)",
              choices=("wall", "ros")),
        Param("heartbeat_keeper", "auto", "with wall-clock heartbeats: 'process' sends them from a keeper process "
              "whose lease the node renews (a stall of this process's Python shorter than the lease, e.g. a DDS "
              "publish while a new reader is matched, does not stop them), 'thread' from the node's own thread, "
              "'auto' a keeper where the bus allows a second process (remote, socketcan)",
              choices=("auto", "process", "thread")),
        Param("heartbeat_lease_s", 1.0, "the keeper's lease: it stops beating when the node has not renewed it for "
              "this long (a frozen node; a dead one stops it at once) (s)", min_value=0.1, max_value=2.0),
        Param("stall_dump", True, "with wall-clock heartbeats: when the heartbeat thread cannot run for two "
              "periods (with a keeper: its lease), write every thread's Python stack to stderr (the node's "
              "log): what held the process"),
        Param("handshake_timeout_s", 5.0, "wait for the device's VERSION reply (s)", min_value=0.1),
        Param("status_rate_hz", 10.0, "rate of PlateMotionStatus and DeviceStatus (Hz)", min_value=0.5,
              max_value=100.0),
        Param("shutdown_timeout_s", 3.0, "bound on the ramp-down at deactivate and shutdown (s)", min_value=0.1),
        Param("raw_cycles", 4, "whole cycles of raw samples per ppod/capture_raw request", min_value=1,
              max_value=MAX_RAW_CYCLES),
        Param("raw_dir", "", "where ppod/capture_raw writes its .npz recordings; empty: "
              "~/.cache/ppod/<device>/raw"),
    )

    def __init__(self, **kwargs):
        super().__init__("waveform_generator", **kwargs)
        self.config = None
        self.bus = None
        self.link: DeviceLink | None = None
        self.gen: WaveformGenerator | None = None
        self._subs: list = []
        self._hb_timer = None
        self._status_timer = None
        self._last_state = None
        self.status_pub = self.create_lifecycle_publisher(PlateMotionStatus, topics.MOTION_STATUS, qos.LATCHED)
        self.active_pub = self.create_lifecycle_publisher(PlateMotionMsg, topics.ACTIVE_MOTION, qos.LATCHED)
        self.device_pub = self.create_lifecycle_publisher(DeviceStatus, topics.DEVICE_STATUS, qos.STREAM)
        # Services exist in every state; they answer "not active" until activated (estop always works).
        self.create_service(SetPlateMotion, topics.SET_MOTION, self._on_set_motion)
        self.create_service(Trigger, topics.STOP, self._on_stop)
        self.create_service(Trigger, topics.ESTOP, self._on_estop)
        self.create_service(Trigger, RESET_ESTOP, self._on_reset_estop)
        self.create_service(Trigger, topics.CAPTURE_RAW, self._on_capture_raw)
        self._raw_pending: dict[int, tuple[float, str]] = {}  # capture id -> (frequency, goal name)
        self._raw_next = 0

    # ------------------------------------------------------------------ lifecycle
    def on_configure_node(self, params):
        config = load_device_config(params["device_config"] or None)
        overrides = {k: params[f"can_{k}"] for k in ("interface", "channel") if params[f"can_{k}"]}
        self.config = config.with_can(**overrides) if overrides else config
        # Metered: DeviceStatus.bus_load is the wire time of every frame seen over the last second.
        self.bus = MeteredBus(open_bus_waiting(self.config.can, params["bus_wait_s"]), self.config.can.bitrate)
        self.link = DeviceLink(self.bus, self.config)
        try:
            self.link.start()
            version = self.link.handshake(params["handshake_timeout_s"])
        except (DeviceError, ConfigError):  # no answer, or a description beyond the device's limits
            self._close()
            raise
        self.gen = WaveformGenerator(self.link, GoalPlanner(self.config))
        self.link.on_raw.append(self._on_raw)
        self.get_logger().info(f"device '{self.config.name}' on {self.config.can.interface} "
                               f"{self.config.can.channel}: protocol {version.major}.{version.minor}, "
                               f"{version.n_channels} accelerometer channels")

    def on_activate_node(self):
        if self.params["heartbeat_clock"] == "ros":
            self._hb_timer = self.create_timer(self.config.can.heartbeat_period_s, self._heartbeat)
        else:
            # Its own thread: a busy executor (or a slow callback) cannot starve the device watchdog;
            # with a keeper process, neither can anything that holds this process's GIL for less
            # than the lease (ppod_ros/can/keeper.py). The link starts a keeper where the backend lets a
            # second process open the bus ("auto" and "process"), else beats from the thread.
            keeper = self.params["heartbeat_keeper"]
            interface = self.config.can.interface
            if keeper == "process" and not keeper_supported(interface):
                self.get_logger().warning(f"heartbeat_keeper 'process': the {interface} backend cannot be opened "
                                          f"by a second process; heartbeats from the node's thread")
            self.link.start_heartbeat(stall_dump=sys.stderr if self.params["stall_dump"] else None,
                                      keeper_lease_s=None if keeper == "thread" else self.params["heartbeat_lease_s"])
        self._subs = [
            self.create_subscription(PlateMotionMsg, topics.GOAL, self._on_goal_msg, qos.COMMANDS),
            self.create_subscription(HarmonicCorrection, topics.CORRECTION, self._on_correction, qos.COMMANDS),
        ]
        self._status_timer = self.create_timer(1.0 / self.params["status_rate_hz"], self._publish_status)
        self._heartbeat()
        self._publish_active(None)

    def apply_parameter(self, name, value):
        if name == "status_rate_hz" and self._status_timer is not None:
            self.destroy_timer(self._status_timer)
            self._status_timer = self.create_timer(1.0 / value, self._publish_status)

    def on_deactivate_node(self):
        for sub in self._subs:
            self.destroy_subscription(sub)
        self._subs = []
        if self._status_timer is not None:
            self.destroy_timer(self._status_timer)
            self._status_timer = None
        if self.gen is not None and not self.gen.ramp_down_and_disable(self.params["shutdown_timeout_s"]):
            self.get_logger().warning("device did not report rest before disable (its watchdog will ramp it down)")
        if self._hb_timer is not None:
            self.destroy_timer(self._hb_timer)
            self._hb_timer = None
        self.link.stop_heartbeat()
        c = self.link.counters
        if c.heartbeat_max_interval_s > 0:
            (self.get_logger().warning if c.heartbeats_lost else self.get_logger().info)(
                f"heartbeats: longest interval {1e3 * c.heartbeat_max_interval_s:.0f} ms "
                f"(period {1e3 * self.config.can.heartbeat_period_s:.0f} ms); {c.heartbeats_late} more than "
                f"two periods apart, {c.heartbeats_lost} of them not covered by a keeper"
                + (f"; keeper: {c.keeper}" if c.keeper else ""))
        self._publish_status()

    def on_cleanup_node(self):
        self._close()

    def on_shutdown_node(self):
        if self.lifecycle_state == "active":
            self.on_deactivate_node()
        self._close()

    def release_on_destroy(self):
        # No ramp down without the executor: the heartbeats stop, and the device's watchdog ramps
        # the plate down (as when the process dies).
        self._close()

    def _close(self):
        if self.link is not None:
            self.link.stop()
        if self.bus is not None:
            self.bus.shutdown()
        self.link = self.bus = self.gen = None

    # ------------------------------------------------------------------ goals
    def _submit(self, motion: PlateMotion | None, error: ConfigError | None, dry_run: bool) -> GoalOutcome:
        if self.lifecycle_state != "active":
            return GoalOutcome(False, f"waveform_generator is {self.lifecycle_state}, not active")
        outcome = GoalOutcome.rejected(error) if error is not None else self.gen.submit(motion, dry_run)
        if not outcome.accepted:
            self.get_logger().warning(f"goal rejected: {outcome.reason}")
            self.diagnostics.set("goal", diag.WARN, f"rejected: {outcome.reason}", limit=outcome.limit)
            self._publish_status(rejection=outcome)
        elif not dry_run:
            self.get_logger().info(f"goal '{motion.name}' accepted (table {outcome.seq}, ramp "
                                   f"{outcome.plan.ramp_s:g} s, peak current "
                                   f"{outcome.plan.prediction.current_peak_a.max():.2f} A)")
            self._publish_active(outcome.plan.motion)
            self._publish_status()
        return outcome

    @staticmethod
    def _convert(msg: PlateMotionMsg) -> tuple[PlateMotion | None, ConfigError | None]:
        try:
            return motion_from_msg(msg), None
        except ConfigError as exc:
            return None, exc

    def _on_goal_msg(self, msg: PlateMotionMsg) -> None:
        self._submit(*self._convert(msg), dry_run=False)

    def _on_set_motion(self, request, response):
        out = self._submit(*self._convert(request.motion), dry_run=request.dry_run)
        response.accepted, response.reason = out.accepted, out.reason
        response.limit = out.limit
        response.limit_value = out.limit_value if math.isfinite(out.limit_value) else 0.0
        response.requested_value = out.requested if math.isfinite(out.requested) else 0.0
        if out.plan is not None:
            response.predicted_current_peak_a = out.plan.prediction.current_peak_a.tolist()
            response.predicted_stroke_peak_m = out.plan.stroke_peak_m.tolist()
            response.contact_margin_mps2 = out.plan.contact_margin_mps2
        return response

    def _on_correction(self, msg: HarmonicCorrection) -> None:
        plan = self.gen.active_plan if self.gen is not None else None
        if plan is None or msg.goal_name != plan.motion.name:
            return  # a correction for another (or a finished) goal is never applied
        # ... nor one for the goal before with the same name (the key names the motion itself).
        goal_key = bytes(msg.goal_key) if len(msg.goal_key) else None
        k = np.asarray(msg.k, dtype=int)
        table = (np.asarray(msg.real_a) + 1j * np.asarray(msg.imag_a)).reshape(-1, 6) if k.size else np.zeros((0, 6))
        measured = None
        if msg.measured_table_seq and len(msg.measured_real) and len(msg.measured_real) % 6 == 0 \
                and len(msg.measured_imag) == len(msg.measured_real):
            measured = (np.asarray(msg.measured_real) + 1j * np.asarray(msg.measured_imag)).reshape(-1, 6)
        # Iteration 0 is the goal's starting correction (stored or predicted by the learned plant).
        out = self.gen.apply_correction(goal_key, k, table, absolute=msg.absolute, start=msg.iteration == 0,
                                        measured_accel=measured, measured_seq=int(msg.measured_table_seq) or None)
        level = diag.OK if out.applied and not out.reason else diag.WARN
        extra = {}
        if out.result is not None:
            extra = {"scale": out.result.scale, "limited_by": out.result.limited_by or "",
                     "blocked_rows": list(out.result.blocked_rows),
                     "plate_limits_on": "measured plate" if out.result.measured_ratios is not None else "nominal plant"}
        self.diagnostics.set("correction", level, out.reason or "applied", iteration=msg.iteration,
                             applied=out.applied, **extra)

    # ------------------------------------------------------------------ stop, estop
    def _on_stop(self, _request, response):
        if self.gen is None:
            response.success, response.message = False, f"not configured ({self.lifecycle_state})"
            return response
        try:
            self.gen.stop()
        except DeviceError as exc:
            response.success, response.message = False, f"stop not sent ({exc}); the device's watchdog ramps " \
                                                         f"it down when heartbeats stop reaching it"
            self.diagnostics.set("bus", diag.ERROR, response.message)
            return response
        self._publish_active(None)
        response.success, response.message = True, "ramping the plate to rest"
        return response

    # ------------------------------------------------------------------ raw captures on request
    def _on_capture_raw(self, _request, response):
        """Ask the device for ``raw_cycles`` whole cycles of every channel's raw samples.

        The capture arrives over CAN later (the device pauses its summaries while sending it); it is
        written as an .npz recording (docs/feedback.md, "Recorded data") that ``ppod calibrate accel``
        and the estimator read, and the path is logged.
        """
        if self.gen is None or self.lifecycle_state != "active":
            response.success, response.message = False, f"not active ({self.lifecycle_state})"
            return response
        plan = self.gen.active_plan
        freq = plan.frequency_hz if plan is not None else self.config.sim.idle_frequency_hz
        capture_id = self._raw_next
        self._raw_next = (self._raw_next + 1) % 16  # the protocol's 4-bit capture id
        cycles = int(self.params["raw_cycles"])
        try:
            self.link.request_raw((1 << self.config.accelerometers.num_channels) - 1, cycles, capture_id)
        except DeviceError as exc:
            response.success, response.message = False, f"raw capture not requested: {exc}"
            return response
        self._raw_pending[capture_id] = (freq, plan.motion.name if plan is not None else "")
        response.success = True
        response.message = (f"raw capture {capture_id} requested: {self.config.accelerometers.num_channels} channels x "
                            f"{cycles} cycles at {freq:g} Hz, written to {self._raw_dir()} when received "
                            f"(summaries pause while it is sent)")
        return response

    def _raw_dir(self) -> Path:
        if self.params["raw_dir"]:
            return Path(self.params["raw_dir"]).expanduser()
        return Path.home() / ".cache" / "ppod" / self.config.name / "raw"

    def _on_raw(self, capture) -> None:
        freq, goal = self._raw_pending.pop(capture.capture_id, (math.nan, ""))
        if not math.isfinite(freq):
            self.get_logger().warn(f"raw capture {capture.capture_id} was not requested by this node: ignored")
            return
        stamp = self.get_clock().now().nanoseconds
        path = self._raw_dir() / f"raw_{stamp}_{capture.capture_id}.npz"
        try:
            rec = recording_from_captures([capture], freq, self.config.accelerometers.layout.names,
                                          meta={"device": self.config.name, "motion": goal or "raw",
                                                "start_cycle": int(capture.start_cycle)})
            path.parent.mkdir(parents=True, exist_ok=True)
            write_recording(rec, path)
        except (ConfigError, OSError) as exc:
            self.get_logger().error(f"raw capture {capture.capture_id} not written: {exc}")
            return
        self.get_logger().info(f"raw capture {capture.capture_id}: {capture.samples.shape[0]} samples x "
                               f"{capture.samples.shape[1]} channels -> {path}")

    def _on_estop(self, _request, response):
        try:
            if self.gen is not None:
                self.gen.estop()
            else:  # not configured: open the bus just for the emergency-stop frame
                config = load_device_config(self.get_parameter("device_config").value or None)
                overrides = {k: self.get_parameter(f"can_{k}").value for k in ("interface", "channel")}
                config = config.with_can(**{k: v for k, v in overrides.items() if v})
                bus = open_bus(config.can)
                try:
                    send_estop(bus, config.can.device_node_id)
                finally:
                    bus.shutdown()
        except (DeviceError, ConfigError) as exc:
            response.success, response.message = False, f"emergency stop NOT sent: {exc}"
            self.get_logger().error(response.message)
            return response
        self.get_logger().warning("EMERGENCY STOP sent")
        self._publish_active(None)
        response.success, response.message = True, "emergency stop sent; reset with ppod/reset_emergency_stop"
        return response

    def _on_reset_estop(self, _request, response):
        if self.gen is None:
            response.success, response.message = False, f"not configured ({self.lifecycle_state})"
            return response
        try:
            self.gen.reset_estop()
        except DeviceError as exc:
            response.success, response.message = False, f"reset not sent: {exc}"
            return response
        response.success, response.message = True, "emergency stop reset; the device is disabled until a goal"
        return response

    # ------------------------------------------------------------------ periodic
    def _heartbeat(self) -> None:
        try:
            self.link.heartbeat()
        except DeviceError as exc:
            self.diagnostics.set("bus", diag.ERROR, f"heartbeat not sent: {exc}")

    def _publish_active(self, motion: PlateMotion | None) -> None:
        if self.active_pub.is_activated:
            stamp = self.get_clock().now().to_msg()
            self.active_pub.publish(motion_to_msg(motion or PlateMotion.zero(name=""), stamp))

    def _publish_status(self, rejection: GoalOutcome | None = None) -> None:
        if self.gen is None or not self.status_pub.is_activated:
            return
        state, reason, progress = self.gen.state()
        plan = self.gen.active_plan
        msg = PlateMotionStatus(state=int(state), ramp_progress=float(progress), reason=reason)
        msg.header.stamp = self.get_clock().now().to_msg()
        if plan is not None:
            msg.goal_name = plan.motion.name
            msg.active = motion_to_msg(plan.motion)
            msg.predicted_current_peak_a = plan.prediction.current_peak_a.tolist()
        if rejection is not None:
            msg.state, msg.reason, msg.limit = int(GeneratorState.REJECTED), rejection.reason, rejection.limit
            msg.limit_value = rejection.limit_value if math.isfinite(rejection.limit_value) else 0.0
            msg.requested_value = rejection.requested if math.isfinite(rejection.requested) else 0.0
        self.status_pub.publish(msg)
        if state != self._last_state and state == GeneratorState.FAULT:
            self.get_logger().error(f"device fault: {reason}")
        if state != self._last_state and state == GeneratorState.REJECTED and rejection is None:
            self.get_logger().warning(reason)  # the device refused the table: said once, kept in the status
            self.diagnostics.set("goal", diag.WARN, reason)
        self._last_state = state
        self._publish_device_status()

    def _publish_device_status(self) -> None:
        s, health = self.link.status, self.link.health()
        msg = DeviceStatus(state=int(s.state) if s.state is not None else DeviceStatus.STATE_FAULT)
        msg.header.stamp = self.get_clock().now().to_msg()
        v = self.link.version
        msg.protocol_version = (v.major << 8 | v.minor) if v is not None else 0
        msg.fault_flags, msg.faults = int(s.faults), s.fault_names
        msg.device_time_s = float(s.device_time_s) if math.isfinite(s.device_time_s) else 0.0
        msg.cycle_count, msg.amplitude_scale = int(s.cycle_count), float(s.amplitude_scale)
        msg.coil_current_rms_a = [float(x) for x in s.coil_rms_a]
        msg.coil_temperature_c = [float(x) for x in s.coil_temperature_c]
        msg.heartbeat_age_s = float(s.heartbeat_age_s) if math.isfinite(s.heartbeat_age_s) else -1.0
        msg.frames_rx = int(health["frames_accepted"])
        msg.frames_tx = int(health["frames_sent"])
        msg.frames_rejected = int(health["frames_rejected"])
        msg.bus_load = float(self.bus.load()) if isinstance(self.bus, MeteredBus) else 0.0
        self.device_pub.publish(msg)
        level = diag.ERROR if health["stale"] or s.fault_names else diag.OK
        text = "device silent (no STATUS)" if health["stale"] else (", ".join(s.fault_names) or health["state"])
        self.diagnostics.set("device", level, text, **health, **self.gen.ack_counters)


main = make_main(WaveformGeneratorNode)

if __name__ == "__main__":
    raise SystemExit(main())
