"""accel_feedback: the plate's measured acceleration and closed-loop learning control.

Lifecycle node (STYLE.md rule 9); the logic is ppod_ros.control.online.FeedbackLoop:
  configure  load the device description, open the CAN bus receive-only (this node never sends on
             it), build the estimator, the plant, the plant learner and the correction store
  activate   follow the generator's status; estimate from every accelerometer summary; while a goal
             is ACTIVE, publish its starting correction (iteration 0: stored for the goal, or
             predicted by the plant learned from earlier goals) and learning-control corrections
  deactivate stop estimating and correcting
  cleanup    close the bus

Publishes PlateAcceleration (measured harmonics, goal, error, iteration, converged) and
HarmonicCorrection (absolute, per actuator and harmonic, amperes) for the waveform generator, which
alone validates, limits and applies it. On divergence it asks the generator to ramp the plate down
(ppod/stop) and reports; channels that die are dropped while the rest still determine the motion,
otherwise the node reports a fault and stops correcting; a dead acquisition stops it too. The channel
set the loop uses changes only on persistent evidence (ChannelSet), reported on /diagnostics
("channel_set") with its reason, and learning restarts on a change. Publishes every received
summary as AccelSummary (recorded by default, for ppod calibrate accel); uses the device's stored
accelerometer calibration. Diagnostics: channel health, channel set, data rate, error.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
from ppod_msgs.msg import AccelSummary, HarmonicCorrection, PlateAcceleration, PlateMotionStatus
from std_srvs.srv import Trigger

from ppod_nodes.common import diagnostics as diag
from ppod_nodes.common import qos, topics
from ppod_nodes.common.convert import motion_from_msg, phasors_to_msg
from ppod_nodes.common.lifecycle import PpodLifecycleNode
from ppod_nodes.common.params import Param
from ppod_nodes.common.runner import make_main
from ppod_ros.can import DeviceLink, open_bus_waiting
from ppod_ros.control import CorrectionStore, LearningSettings
from ppod_ros.control.learned_plant import PlantLearningSettings
from ppod_ros.control.online import FeedbackLoop, LoopOutput, OnlineSettings
from ppod_ros.device import load_device_config
from ppod_ros.errors import ConfigError, PpodError
from ppod_ros.estimation import EstimationError
from ppod_ros.estimation.calibration import calibration_path, load_calibration
from ppod_ros.estimation.channel_set import ChannelSetSettings
from ppod_ros.estimation.misfit import MisfitHistory, load_misfit, save_misfit
from ppod_ros.motion import PlateMotion


class AccelFeedbackNode(PpodLifecycleNode):
    PARAMS = (
        Param("device_config", "", "device description YAML; empty: the packaged default"),
        Param("can_interface", "", "override can.interface"),
        Param("bus_wait_s", 10.0, "keep trying to open the bus this long at configure (s)", min_value=0.0),
        Param("can_channel", "", "override can.channel"),
        Param("control", True, "send corrections (false: estimate and publish only)"),
        Param("summaries_per_estimate", 3, "device summaries averaged per estimate", min_value=1, max_value=64),
        Param("settle_s", 0.6, "wait after a goal or correction before measuring (s)", min_value=0.0),
        Param("table_wait_s", 2.0, "after a correction, measure only the device's next table; give up waiting "
              "after this long (s)", min_value=0.0),
        Param("gain", 1.0, "learning gain", min_value=0.01, max_value=2.0),
        Param("tolerance", 0.01, "converged when error_relative <= this", min_value=1e-5, max_value=0.5),
        Param("cache_dir", "", "where learned corrections are kept per device and goal; empty: ~/.cache/ppod"),
        Param("learn_plant", True, "learn the plant online and start each new goal from the correction it predicts"),
        Param("plant_prior_weight_a2", 0.01, "ridge weight of the nominal plant in the learned one (A^2)",
              min_value=1e-9),
        Param("plant_coupling_weight_a2", 0.1, "ridge weight of actuator cross-coupling in the learned plant (A^2)",
              min_value=1e-9),
        Param("plant_forgetting", 0.95, "weight kept by earlier plant samples per new one", min_value=1e-3,
              max_value=1.0),
        Param("channel_drop_after", 3, "estimates a channel must be dropped in before it leaves the set",
              min_value=1, max_value=100),
        Param("channel_restore_after", 10, "estimates a removed channel must pass before it rejoins",
              min_value=1, max_value=1000),
        Param("use_calibration", True, "use the accelerometer calibration stored for this device (ppod calibrate)"),
    )

    def __init__(self, **kwargs):
        super().__init__("accel_feedback", **kwargs)
        self.loop: FeedbackLoop | None = None
        self.bus = self.link = None
        self._lock = threading.Lock()
        self._active_goal_key: bytes | None = None
        self._sub = None
        self._misfit_store: tuple[Path, str] | None = None
        self._received: list[float] = []
        self._last: LoopOutput | None = None
        self.accel_pub = self.create_lifecycle_publisher(PlateAcceleration, topics.ACCELERATION, qos.STREAM)
        self.corr_pub = self.create_lifecycle_publisher(HarmonicCorrection, topics.CORRECTION, qos.COMMANDS)
        self.summary_pub = self.create_lifecycle_publisher(AccelSummary, topics.ACCEL_SUMMARIES, qos.STREAM)
        self._stop_client = self.create_client(Trigger, topics.STOP)
        self._diag_timer = self.create_timer(1.0, self._report)

    # ------------------------------------------------------------------ lifecycle
    def on_configure_node(self, params):
        config = load_device_config(params["device_config"] or None)
        overrides = {k: params[f"can_{k}"] for k in ("interface", "channel") if params[f"can_{k}"]}
        config = config.with_can(**overrides) if overrides else config
        settings = OnlineSettings(summaries_per_estimate=params["summaries_per_estimate"],
                                  settle_s=params["settle_s"], control=params["control"],
                                  table_wait_s=params["table_wait_s"])
        learning = LearningSettings.from_dict({"gain": params["gain"], "tolerance": params["tolerance"]})
        cache = Path(params["cache_dir"]).expanduser() if params["cache_dir"] else Path.home() / ".cache" / "ppod"
        plant_learning = PlantLearningSettings(enabled=params["learn_plant"],
                                               prior_weight_a2=params["plant_prior_weight_a2"],
                                               forgetting=params["plant_forgetting"],
                                               coupling_weight_a2=params["plant_coupling_weight_a2"])
        calibration = load_calibration(cache, config.name) if params["use_calibration"] else None
        self.get_logger().info(f"accelerometer calibration: {calibration_path(cache, config.name)}"
                               if calibration is not None else "accelerometer calibration: none (nominal layout)")
        # The misfit learned from operation (healthy estimates), kept per device next to the calibration.
        try:
            misfit = load_misfit(cache, config.name)
        except ConfigError as exc:
            self.get_logger().warning(f"{exc}; learning the misfit afresh")
            misfit = None
        if misfit is None or misfit.names != tuple(config.accelerometers.layout.names):
            misfit = MisfitHistory(config.accelerometers.layout.names)
        self._misfit_store = (cache, config.name)
        self.loop = FeedbackLoop(config, settings, learning, store=CorrectionStore(cache),
                                 plant_learning=plant_learning, calibration=calibration,
                                 channel_set=ChannelSetSettings(params["channel_drop_after"],
                                                                params["channel_restore_after"]),
                                 misfit=misfit)
        self.bus = open_bus_waiting(config.can, params["bus_wait_s"])
        self.link = DeviceLink(self.bus, config)
        self.link.on_summary.append(self._on_summary)
        self.link.start()  # receive only: no handshake, no heartbeat; the generator owns the device

    def on_activate_node(self):
        self._sub = self.create_subscription(PlateMotionStatus, topics.MOTION_STATUS, self._on_status, qos.LATCHED)

    def on_deactivate_node(self):
        if self._sub is not None:
            self.destroy_subscription(self._sub)
            self._sub = None
        with self._lock:
            self._active_goal_key = None
            if self.loop is not None:
                self.loop.set_goal(None, self._now())
        self._save_misfit()

    def _save_misfit(self) -> None:
        if self.loop is None or self._misfit_store is None or self.loop.misfit is None:
            return
        try:
            with self._lock:
                if not self.loop.misfit.count.any():
                    return
                path = save_misfit(self.loop.misfit, *self._misfit_store)
        except OSError as exc:
            self.get_logger().warning(f"accelerometer misfit history not stored: {exc}")
            return
        self.get_logger().info(f"accelerometer misfit history: {path}")

    def on_cleanup_node(self):
        self._save_misfit()
        self.release_on_destroy()

    def on_shutdown_node(self):
        self.on_cleanup_node()

    def release_on_destroy(self):
        if self.link is not None:
            self.link.stop()
        if self.bus is not None:
            self.bus.shutdown()
        self.loop = self.link = self.bus = None

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ------------------------------------------------------------------ goal tracking
    def _on_status(self, msg: PlateMotionStatus) -> None:
        # A goal is taken up as soon as it starts ramping in, so that its starting correction joins
        # the goal's own ramp instead of following it after the plate has run uncorrected.
        ramping = msg.state == PlateMotionStatus.STATE_RAMPING
        active = (ramping or msg.state == PlateMotionStatus.STATE_ACTIVE) and msg.active.harmonics
        try:
            motion = motion_from_msg(msg.active) if active else None
        except ConfigError as exc:
            self.get_logger().error(f"cannot follow the active goal: {exc}")
            motion = None
        key = None if motion is None else motion.key
        if msg.state == PlateMotionStatus.STATE_REJECTED:
            return  # a rejected goal leaves the previous motion playing
        with self._lock:
            if key == self._active_goal_key:
                return
            self._active_goal_key = key
            ramp_left = (1.0 - min(max(msg.ramp_progress, 0.0), 1.0)) if ramping else 0.0
            self.loop.set_goal(motion, self._now(), ramp_left_fraction=ramp_left)
            initial = self.loop.initial_correction_a
            source = {"stored": " from its stored correction",
                      "predicted": " from the correction the learned plant predicts"}.get(self.loop.initial_source, "")
            fallback = self.loop.learner.last_fallback
        if motion is not None:
            if fallback:
                self.get_logger().warn(f"learned plant: {fallback}")
            self.get_logger().info(f"learning goal '{motion.name}'{source}")
            if initial is not None:
                self._send_correction(motion, self.loop.controller.k, initial, 0)

    # ------------------------------------------------------------------ summaries
    def _on_summary(self, summary) -> None:
        if self.lifecycle_state != "active" or self.loop is None:
            return
        self._received.append(time.monotonic())
        self._publish_summary(summary)
        with self._lock:
            goal = self.loop.goal
            freq = goal.frequency_hz if goal is not None else summary.frequency_hz
            if not np.isfinite(freq):
                return  # no goal and no known frequency: nothing to refer the phases to
            try:
                out = self.loop.on_summary(summary.k, summary.phasors, freq, summary.samples_per_cycle, self._now(),
                                           table_seq=summary.table_seq, cycle=summary.first_cycle)
            except EstimationError as exc:
                # A dead acquisition or too few channels: never push on it; stop and say why.
                self.diagnostics.set("channels", diag.ERROR, str(exc), **exc.channel_status)
                self._active_goal_key = None
                self.loop.set_goal(None, self._now())
                self._request_stop("the accelerometers can no longer determine the plate's motion")
                return
            except PpodError as exc:
                self.get_logger().error(f"feedback update failed: {exc}")
                return
        if out is None:
            return
        self._last = out
        if out.channel_change is not None:
            why = out.channel_change.describe()
            self.get_logger().warn(f"accelerometer channel set changed: {why}; learning restarts")
            self.diagnostics.set("channel_set", diag.WARN if self.loop.channels.removed else diag.OK,
                                 f"channel set changed: {why}", **self.loop.channels.removed)
        self._publish(out)

    def _publish_summary(self, summary) -> None:
        msg = AccelSummary(frequency_hz=float(summary.frequency_hz), samples_per_cycle=int(summary.samples_per_cycle))
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.channels = list(self.loop.estimator.layout.names)
        msg.k = [int(v) for v in summary.k]
        msg.real_mps2 = np.asarray(summary.phasors).real.reshape(-1).tolist()
        msg.imag_mps2 = np.asarray(summary.phasors).imag.reshape(-1).tolist()
        self.summary_pub.publish(msg)

    def _publish(self, out: LoopOutput) -> None:
        est, step, goal = out.estimate, out.step, out.goal
        msg = PlateAcceleration(frequency_hz=float(est.frequency_hz), length_scale_m=0.1,
                                residual_rms_mps2=float(est.residual_rms_mps2), cycles_used=int(round(est.cycles)))
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "plate"
        msg.measured = phasors_to_msg(est.k, est.phasors)
        if goal is not None:
            msg.goal_name = goal.name
            msg.goal = phasors_to_msg(est.k, goal.phasor_table(int(est.k.max()))[est.k - 1])
        if step is not None:
            msg.error_relative, msg.error_norm = float(step.error_relative), float(step.error_norm)
            msg.out_of_goal_relative = float(step.out_of_goal_relative)
            msg.iteration, msg.converged = int(step.iteration), bool(step.converged)
        self.accel_pub.publish(msg)
        dropped = {n: s for n, s in zip(est.channels, est.status) if s != "ok"}
        self.diagnostics.set("channels", diag.WARN if dropped else diag.OK,
                             f"{len(dropped)} channel(s) dropped" if dropped else "all channels ok", **dropped)
        if step is None:
            return
        if step.ramp_down:
            self.diagnostics.set("learning", diag.ERROR, f"diverged: {step.message}")
            self._request_stop(f"learning control diverged ({step.message})")
            return
        self._send_correction(goal, step.k, step.correction_a, step.iteration, out.table_seq, out.measured_accel)
        self.get_logger().info(f"'{goal.name}' iteration {step.iteration}: error {100 * step.error_relative:.2f} % "
                               f"measured on device table {out.table_seq}")
        level = diag.OK if step.state in ("converged", "running") else diag.WARN
        self.diagnostics.set("learning", level, f"{step.state}: error {100 * step.error_relative:.2f} %",
                             iteration=step.iteration, error_relative=step.error_relative,
                             out_of_goal_relative=step.out_of_goal_relative, stored=out.stored)

    def _send_correction(self, goal: PlateMotion, k: np.ndarray, table: np.ndarray, iteration: int,
                         table_seq: int | None = None, measured: np.ndarray | None = None) -> None:
        msg = HarmonicCorrection(goal_name=goal.name, iteration=int(iteration), absolute=True)
        msg.goal_key = list(goal.key)  # the generator refuses it for any other goal of the same name
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.k = [int(v) for v in k]
        msg.real_a = np.asarray(table).real.reshape(-1).tolist()
        msg.imag_a = np.asarray(table).imag.reshape(-1).tolist()
        if table_seq is not None and measured is not None:  # the measurement the step was taken on
            msg.measured_table_seq = int(table_seq)
            msg.measured_real = measured.real.reshape(-1).tolist()
            msg.measured_imag = measured.imag.reshape(-1).tolist()
        self.corr_pub.publish(msg)

    def _request_stop(self, why: str) -> None:
        self.get_logger().error(f"{why}: asking the waveform generator to ramp the plate down")
        if self._stop_client.service_is_ready():
            self._stop_client.call_async(Trigger.Request())
        else:
            self.get_logger().error("ppod/stop is not available; the device watchdog stays the last resort")

    def _report(self) -> None:
        now = time.monotonic()
        self._received = [t for t in self._received if now - t <= 5.0]
        rate = len(self._received) / 5.0
        level = diag.OK if rate > 0 or self.lifecycle_state != "active" else diag.WARN
        self.diagnostics.set("data", level, f"{rate:.1f} summaries/s", summaries_per_s=rate)


main = make_main(AccelFeedbackNode)

if __name__ == "__main__":
    raise SystemExit(main())
