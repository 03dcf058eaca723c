"""sim_device: the simulated PPOD's ROS side (the device itself is reached over CAN only).

One process owns the simulated world (:class:`~ppod_sim.world.SimWorld`: device, plate plant,
accelerometers, parts, camera, device clock) and the localhost CAN bridge the other nodes connect
to. Its ROS side publishes what a real device's surroundings would provide, plus clearly marked
simulation-only ground truth:

  /clock                               device time (nodes run with use_sim_time under ``ppod up --sim``)
  ppod/camera/image_raw, camera_info   the triggered overhead camera, rendered only while subscribed
  ppod/sim/ground_truth/part_poses     true part poses at each camera trigger (simulation only)
  ppod/sim/ground_truth/plate_acceleration  true plate acceleration harmonics (simulation only)
  ppod/sim/scenario                    latched YAML: device, mismatch, seed, rate, the placed scene

Not a lifecycle node: the simulated device runs from start-up to shutdown like the real one, and
its firmware (watchdog, e-stop) protects it whatever the host does.
"""

from __future__ import annotations

import math
import os
import threading
import time
from importlib import resources
from pathlib import Path

import numpy as np
import yaml
from ppod_msgs.msg import PartPose, PartPoseArray, PlateAcceleration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

from ppod_nodes.common import qos, topics
from ppod_nodes.common.convert import phasors_to_msg, seconds_to_stamp
from ppod_nodes.common.events import QuietPublishers
from ppod_nodes.common.params import Param, declare, read
from ppod_nodes.common.runner import make_main
from ppod_ros.can.protocol import DeviceState
from ppod_ros.device import Mismatch, load_device_config
from ppod_ros.motion import acceleration_error
from ppod_ros.vision import CameraConfig
from ppod_sim.camera import RenderedFrame
from ppod_sim.device import watchdog_story
from ppod_sim.scene import load_scene
from ppod_sim.truth import CycleTruth, save_cycles
from ppod_sim.world import PartsTruth, SimWorld

SCENARIO = topics.SIM_SCENARIO


def default_scene_path() -> Path:
    return Path(str(resources.files("ppod_sim") / "data" / "scene.yaml"))


class SimDeviceNode(QuietPublishers, Node):
    PARAMS = (
        Param("device_config", "", "device description YAML; empty: the packaged default"),
        Param("mismatch", "default", "plant mismatch: the config's ('default') or none ('zero')",
              choices=("default", "zero")),
        Param("scene", "", "scene YAML (parts on the plate); empty: the packaged demo scene"),
        Param("camera_config", "", "camera YAML; empty: the default simulated camera"),
        Param("camera", True, "simulate the overhead camera"),
        Param("port", 54701, "CAN bridge TCP port on 127.0.0.1 (0: any free port)", min_value=0, max_value=65535),
        Param("rate", 1.0, "device seconds per wall second", min_value=0.01, max_value=1000.0),
        Param("seed", -1, "simulation seed (-1: the scene's)", min_value=-1),
        Param("clock_period_s", 0.01, "period of /clock in device time (s)", min_value=0.001, max_value=0.1),
        Param("truth_period_s", 0.1, "period of the ground-truth acceleration topic (s)", min_value=0.01),
    )

    def __init__(self, **kwargs):
        super().__init__("sim_device", **kwargs)
        declare(self, self.PARAMS)
        p = read(self, self.PARAMS)
        config = load_device_config(p["device_config"] or None)
        if p["mismatch"] == "zero":
            config = config.with_mismatch(Mismatch.zero())
        scene = load_scene(p["scene"] or default_scene_path())
        camera = None
        if p["camera"]:
            camera = CameraConfig.from_yaml(p["camera_config"]) if p["camera_config"] else CameraConfig()
        self.world = SimWorld(config, scene, camera, port=p["port"], rate=p["rate"],
                              seed=None if p["seed"] < 0 else p["seed"])
        self.camera = camera
        self._clock_pub = self.create_publisher(Clock, topics.CLOCK, 10)
        self._image_pub = self.create_publisher(Image, topics.IMAGE, qos.SENSOR_DATA)
        self._info_pub = self.create_publisher(CameraInfo, topics.CAMERA_INFO, qos.LATCHED)
        self._truth_pub = self.create_publisher(PartPoseArray, topics.SIM_TRUE_POSES, qos.STREAM)
        self._accel_pub = self.create_publisher(PlateAcceleration, topics.SIM_TRUE_ACCELERATION, qos.STREAM)
        scenario = self.create_publisher(String, SCENARIO, qos.LATCHED)
        scenario.publish(String(data=yaml.safe_dump({
            "device_config": p["device_config"], "device": config.name, "mismatch": p["mismatch"],
            "seed": scene.seed if p["seed"] < 0 else p["seed"], "rate": p["rate"], "camera": p["camera"],
            "camera_config": p["camera_config"], "scene": scene.to_dict(),
            "bridge": self.world.url}, sort_keys=False)))
        if camera is not None:
            self._info_pub.publish(self._camera_info())
        self._clock_period = p["clock_period_s"]
        self._truth_period = p["truth_period_s"]
        self._next_clock = 0.0
        self._next_truth = 0.0
        self._device_state = None
        self.world.process.on_step.append(self._on_step)
        self.world.on_cycle.append(self._on_cycle)
        self.world.on_frame.append(self._on_frame)
        self.world.on_tick.append(self._on_tick)
        # PPOD_SIM_RECORD_CYCLES=FILE.npz: keep every cycle's plate motion and store it on the way
        # out, to replay the run's parts physics (ppod bench sim_parts --cycles FILE.npz).
        self._record_path = os.environ.get("PPOD_SIM_RECORD_CYCLES") or None
        self._recorded: list[CycleTruth] = []
        if self._record_path:
            self.world.on_cycle.append(lambda truth, _parts: self._recorded.append(truth))
        self.create_timer(0.5, self._update_camera_enable)  # wall time: renders only while watched
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self.world.run, kwargs={"stop": self._stop}, daemon=True,
                                        name="sim-world")
        self._thread.start()
        self.get_logger().info(
            f"simulated device '{config.name}' (mismatch {p['mismatch']}, rate {p['rate']:g}x, "
            f"{len(scene.parts)} parts, camera {'on' if camera else 'off'}); CAN bridge on {self.world.url}")

    # ------------------------------------------------------------------ publishing
    def _on_step(self, device) -> None:
        t = device.time_s
        if device.state != self._device_state:
            # The firmware's state changes (enable, watchdog, e-stop, fault) are what an operator
            # looks for first after an incident: log them with the heartbeat age in device time.
            last = device.last_heartbeat_s
            before = "" if self._device_state is None else f"{self._device_state.name} -> "
            why = ""
            if device.state == DeviceState.WATCHDOG:
                why = "; " + watchdog_story(device, self.world.process.pacer.lag_s, time.time())
            self.get_logger().info(
                f"device state {before}"
                f"{device.state.name} at t={t:.4f} s (last heartbeat at "
                f"{'never' if last is None else f't={last:.4f} s'}; faults 0x{int(device.faults):x}{why})")
            self._device_state = device.state
        if t >= self._next_clock:
            self._next_clock = t + self._clock_period
            self._clock_pub.publish(Clock(clock=seconds_to_stamp(t)))

    def _on_cycle(self, truth: CycleTruth, parts: PartsTruth) -> None:
        if truth.start_time_s < self._next_truth:
            return
        self._next_truth = truth.start_time_s + self._truth_period
        msg = PlateAcceleration(frequency_hz=float(truth.frequency_hz), length_scale_m=0.1, cycles_used=1)
        msg.header.stamp = seconds_to_stamp(truth.start_time_s + 1.0 / truth.frequency_hz)
        msg.header.frame_id = "plate"
        k = np.arange(1, truth.accel.shape[0] + 1)
        msg.measured = phasors_to_msg(k, truth.accel)
        fund = np.linalg.norm(truth.accel[0] * np.array([1, 1, 1, 0.1, 0.1, 0.1]))
        if fund > 0:
            rest = np.zeros_like(truth.accel)
            rest[1:] = truth.accel[1:]
            msg.out_of_goal_relative = acceleration_error(np.zeros_like(truth.accel), rest)[0] / fund
        self._accel_pub.publish(msg)

    def _on_frame(self, frame: RenderedFrame, parts: PartsTruth) -> None:
        stamp = seconds_to_stamp(frame.stamp_s)
        img = frame.image
        msg = Image(height=img.shape[0], width=img.shape[1], encoding="mono8" if img.ndim == 2 else "bgr8",
                    is_bigendian=0, step=img.shape[1] * (1 if img.ndim == 2 else 3))
        msg.header.stamp, msg.header.frame_id = stamp, "camera"
        msg.data = img.tobytes()
        self._image_pub.publish(msg)

    def _on_tick(self, stamp_s: float, parts: PartsTruth) -> None:
        self._truth_pub.publish(self._truth_msg(parts, stamp_s))

    def _truth_msg(self, parts: PartsTruth, stamp_s: float) -> PartPoseArray:
        out = PartPoseArray()
        out.header.stamp, out.header.frame_id = seconds_to_stamp(stamp_s), "plate"
        for i, sp in enumerate(self.world.scene.parts):
            x, y, th = parts.poses[i]
            ok = parts.on_plate[i] and not parts.contact_lost[i]
            status = PartPose.STATUS_TRACKED if ok else PartPose.STATUS_LOST
            p = PartPose(id=i + 1, label=sp.label, status=status, vx=float(parts.twists[i, 0]),
                         vy=float(parts.twists[i, 1]), omega=float(parts.twists[i, 2]))
            p.pose.x, p.pose.y, p.pose.theta = float(x), float(y), float(th)
            fp = sp.part.footprint
            p.symmetry_rad = fp.symmetry_rad if fp is not None else 2 * math.pi
            p.stamp = out.header.stamp
            out.parts.append(p)
        return out

    def _camera_info(self) -> CameraInfo:
        c = self.camera
        info = CameraInfo(width=c.width, height=c.height, distortion_model="plumb_bob")
        info.header.frame_id = "camera"
        K = np.asarray(c.camera_matrix, dtype=float)
        info.k = K.reshape(9).tolist()
        info.d = np.asarray(c.dist_coeffs, dtype=float).reshape(-1).tolist()
        info.r = np.eye(3).reshape(9).tolist()
        info.p = np.hstack([K, np.zeros((3, 1))]).reshape(12).tolist()
        return info

    def _update_camera_enable(self) -> None:
        watched = self.count_subscribers(topics.IMAGE) > 0
        if self.world.renderer is not None and watched != self.world.camera_enabled.is_set():
            (self.world.camera_enabled.set if watched else self.world.camera_enabled.clear)()
            self.get_logger().info(f"camera {'on: rendering' if watched else 'idle: nobody subscribes'}")

    def finalize(self) -> None:
        """Stop the simulation thread and close the bridge (called by run_node on the way out)."""
        cpu = _thread_cpu_seconds()  # before the threads end
        self._stop.set()
        self._thread.join(timeout=5)
        self.world.close()
        w = self.world
        if self._record_path:
            save_cycles(self._record_path, self._recorded)
            self.get_logger().info(f"recorded {len(self._recorded)} cycles to {self._record_path}")
        self.get_logger().info(f"simulated {w.device.time_s:.1f} s of device time; parts physics "
                               f"{w.physics_s:.2f} s; {w.frames_rendered} frames rendered, {w.frames_dropped} dropped; "
                               f"device clock at most {1e3 * w.process.pacer.max_lag_s:.0f} ms behind real time, "
                               f"slipped {w.process.pacer.slipped_s:.2f} s in {w.process.pacer.slips} stalls; "
                               f"waited {w.backpressure_s:.2f} s for the parts physics; heartbeats at most "
                               f"{1e3 * w.device.longest_heartbeat_gap_s:.0f} ms of device time apart while enabled; "
                               f"waited {w.process.deliver_waited_s:.2f} s in {w.process.deliver_waits} steps for "
                               f"the bridge to read the host's frames")
        self.get_logger().info(f"CPU {time.process_time():.2f} s in all, by thread (live at the end): "
                               + ", ".join(f"{name} {sec:.2f} s" for name, sec in cpu))


def _thread_cpu_seconds() -> list[tuple[str, float]]:
    """CPU seconds of every live thread of this process, by name (largest first)."""
    out = []
    for t in threading.enumerate():
        try:
            out.append((t.name, time.clock_gettime(time.pthread_getcpuclockid(t.ident))))
        except (OSError, TypeError, AttributeError):
            continue
    return sorted(out, key=lambda item: -item[1])


main = make_main(SimDeviceNode)

if __name__ == "__main__":
    raise SystemExit(main())
