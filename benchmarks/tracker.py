"""Part tracker accuracy and speed on rendered sequences with ground truth.

For 1, 5, 10 and 20 parts (washers, pins, square tiles, trapezoid tabs, hexagons) moving smoothly,
turning, and pairs approaching each other to about a millimetre, the simulated camera renders a
1280 x 1024 sequence (or one of the camera file of --camera) at 10 fps (triggered at the plate's
cycle start, the plate vibrating), and the tracker (calibrated from the plate's markers on the
first frame, starting from a nominal camera mount) tracks it. Printed per sequence:

  tracked %      part-frames reported TRACKED (the rest: PREDICTED with a reason, e.g. touching)
  pos RMS/max    position error of TRACKED reports (mm)
  pred RMS       position error of PREDICTED reports (mm; nan when there were none)
  theta RMS/max  orientation error modulo each part's symmetry (deg; disks excluded)
  id swaps       times a part's matched track id changed; id-less frames are not swaps
  ms/frame       PartTracker.update on one core (cv2.setNumThreads(1), CPU affinity 1): wall time,
                 and the thread's CPU time, which is what the frame costs when the core is not shared
  render ms      the simulated camera's time per frame (median, wall and CPU), same conditions

Targets (issue 6): position RMS <= 0.2 mm, orientation RMS <= 0.3 deg, zero id swaps,
<= 10 ms per frame on one core.

examples:
  ppod bench tracker
  ppod bench tracker --parts 1 5 --frames 50
  ppod bench tracker --quick --out out/bench
  ppod bench tracker --camera ppod_ros/data/camera_640.yaml --parts 1 5   # the stack's 640 x 512 camera
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HELP = "part tracker: pose accuracy, id swaps and ms per frame on rendered sequences"

TARGETS = {"pos_rms_mm": 0.2, "theta_rms_deg": 0.3, "ms_per_frame": 10.0, "id_swaps": 0}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--parts", type=int, nargs="+", default=[1, 5, 10, 20], help="part counts (default: %(default)s)"
    )
    parser.add_argument(
        "--frames", type=int, default=100, help="frames per sequence (default: %(default)s, 10 s)"
    )
    parser.add_argument("--seed", type=int, default=1, help="scene and noise seed (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="30 frames per sequence")
    parser.add_argument("--all-cores", action="store_true", help="do not restrict timing to one core")
    parser.add_argument("--camera", metavar="FILE", default=None,
                        help="camera file to render and track with (default: the 1280 x 1024 default camera)")


@dataclass
class SequenceScore:
    parts: int
    frames: int
    part_frames: int = 0
    tracked: int = 0
    pos_err_m: list[float] = field(default_factory=list)
    theta_err_rad: list[float] = field(default_factory=list)
    predicted_err_m: list[float] = field(default_factory=list)
    id_swaps: int = 0
    tracks_created: int = 0
    update_s: list[float] = field(default_factory=list)
    update_cpu_s: list[float] = field(default_factory=list)
    render_s: list[float] = field(default_factory=list)
    render_cpu_s: list[float] = field(default_factory=list)
    reasons: dict[str, int] = field(default_factory=dict)

    def row(self) -> dict[str, float]:
        pos = np.array(self.pos_err_m)
        th = np.degrees(np.array(self.theta_err_rad)) if self.theta_err_rad else np.zeros(1)
        ms = np.array(self.update_s[1:] or self.update_s) * 1e3  # the first frame also calibrates
        cpu_ms = np.array(self.update_cpu_s[1:] or self.update_cpu_s) * 1e3
        return {
            "parts": self.parts,
            "frames": self.frames,
            "tracked_pct": 100.0 * self.tracked / max(self.part_frames, 1),
            "pos_rms_mm": float(np.sqrt(np.mean(pos**2)) * 1e3) if pos.size else math.nan,
            "pos_max_mm": float(pos.max() * 1e3) if pos.size else math.nan,
            "theta_rms_deg": float(np.sqrt(np.mean(th**2))),
            "theta_max_deg": float(np.abs(th).max()),
            "predicted_rms_mm": float(np.sqrt(np.mean(np.square(self.predicted_err_m))) * 1e3)
            if self.predicted_err_m
            else math.nan,
            "id_swaps": self.id_swaps,
            "tracks_created": self.tracks_created,
            "ms_median": float(np.median(ms)),
            "ms_p95": float(np.percentile(ms, 95)),
            "ms_mean": float(ms.mean()),
            "cpu_ms_median": float(np.median(cpu_ms)),
            "cpu_ms_p95": float(np.percentile(cpu_ms, 95)),
            # The first frame also renders the static layer (plate and markers) once.
            "render_ms_median": float(np.median(self.render_s[1:] or self.render_s) * 1e3),
            "render_cpu_ms_median": float(np.median(self.render_cpu_s[1:] or self.render_cpu_s) * 1e3),
            "not_tracked": dict(self.reasons),
        }


def run_sequence(n_parts: int, frames: int, seed: int, camera=None) -> SequenceScore:
    """Render and track one sequence (``camera``: a CameraConfig, default ``CameraConfig()``); returns
    its score."""
    import cv2
    from scipy.optimize import linear_sum_assignment

    from ppod_ros.motion import PlateMotion
    from ppod_ros.vision import CameraConfig, PartTracker, TrackStatus, wrap_angle
    from ppod_sim.camera import CameraRenderer, TriggeredCamera
    from ppod_sim.camera.scenarios import make_scene

    cv2.setNumThreads(1)
    true_camera = camera if camera is not None else CameraConfig()
    # The tracker starts from the nominal mount (straight down, centred) and calibrates from markers.
    nominal = true_camera.with_changes(position_m=(0.0, 0.0, 0.70), rotation_deg=(0.0, 0.0, 0.0))
    scene = make_scene(n_parts, seed=seed)
    motion = PlateMotion.single(30.0, amplitude=[10, 0, 0, 0, 100, 0], phase=[0, 0, 0, 0, 3 * math.pi / 2, 0])
    camera = TriggeredCamera(CameraRenderer(true_camera, seed=seed), motion)
    tracker = PartTracker(nominal, list(dict.fromkeys(scene.specs)))
    score = SequenceScore(n_parts, frames)
    last_id: dict[int, int] = {}
    seen_ids: set[int] = set()
    for k in range(frames):
        t = camera.trigger_time(k / true_camera.fps)
        truth = scene.poses(t)
        t0, c0 = time.perf_counter(), time.thread_time()
        frame = camera.capture(scene.render_parts(t), t)
        score.render_cpu_s.append(time.thread_time() - c0)
        score.render_s.append(time.perf_counter() - t0)
        t0, c0 = time.perf_counter(), time.thread_time()
        result = tracker.update(frame.image, t)
        score.update_cpu_s.append(time.thread_time() - c0)
        score.update_s.append(time.perf_counter() - t0)
        reports = [p for p in result.parts if p.status != TrackStatus.LOST]
        score.part_frames += n_parts
        if not reports:
            continue
        # Match reports to truth by position (5 mm gate): a report of another part is a swap.
        cost = np.array([[math.hypot(p.x_m - q[0], p.y_m - q[1]) for q in truth] for p in reports])
        rows, cols = linear_sum_assignment(cost)
        for r, c in zip(rows, cols):
            if cost[r, c] > 0.005:
                continue
            p = reports[r]
            if p.status == TrackStatus.TRACKED:
                score.tracked += 1
                score.pos_err_m.append(cost[r, c])
                if p.symmetry_rad > 0:
                    score.theta_err_rad.append(wrap_angle(p.theta_rad - truth[c, 2], p.symmetry_rad))
            else:
                score.predicted_err_m.append(cost[r, c])
                score.reasons[p.reason] = score.reasons.get(p.reason, 0) + 1
            if c in last_id and last_id[c] != p.id:
                score.id_swaps += 1
            last_id[c] = p.id
            seen_ids.add(p.id)
    score.tracks_created = len(seen_ids)
    return score


def _pin_to_one_core() -> set[int] | None:
    if not hasattr(os, "sched_getaffinity"):
        return None
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {max(before)})
    return before


def run(args: argparse.Namespace) -> int:
    from ppod_ros.vision import CameraConfig

    frames = 30 if args.quick else args.frames
    camera = CameraConfig.from_yaml(args.camera) if args.camera else CameraConfig()
    restore = None if args.all_cores else _pin_to_one_core()
    try:
        rows = []
        for n in args.parts:
            t0 = time.perf_counter()
            row = run_sequence(n, frames, args.seed, camera).row()
            row["wall_s"] = time.perf_counter() - t0
            rows.append(row)
    finally:
        if restore is not None:
            os.sched_setaffinity(0, restore)
    _print_table(rows, one_core=restore is not None, size=(camera.width, camera.height))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "tracker.json").write_text(json.dumps({"targets": TARGETS, "rows": rows}, indent=2))
    _plot(rows, out / "tracker.png")
    print(f"\nwrote {out / 'tracker.json'} and {out / 'tracker.png'}")
    return 0


def _print_table(rows: list[dict], one_core: bool, size: tuple[int, int] = (1280, 1024)) -> None:
    cores = "one core" if one_core else "all cores"
    print(f"Part tracker on rendered {size[0]}x{size[1]} sequences (10 fps, {cores}; cv2 threads = 1)")
    cols = [
        ("parts", 5, "d", "parts"),
        ("frames", 6, "d", "frames"),
        ("tracked_pct", 8, ".1f", "tracked%"),
        ("pos_rms_mm", 8, ".4f", "posRMSmm"),
        ("pos_max_mm", 8, ".4f", "posMAXmm"),
        ("theta_rms_deg", 8, ".3f", "thRMSdeg"),
        ("theta_max_deg", 8, ".3f", "thMAXdeg"),
        ("predicted_rms_mm", 9, ".3f", "predRMSmm"),
        ("id_swaps", 8, "d", "id swaps"),
        ("tracks_created", 6, "d", "tracks"),
        ("ms_median", 8, ".2f", "wall ms"),
        ("ms_p95", 8, ".2f", "wall p95"),
        ("cpu_ms_median", 8, ".2f", "CPU ms"),
        ("cpu_ms_p95", 8, ".2f", "CPU p95"),
        ("render_ms_median", 9, ".1f", "render ms"),
        ("render_cpu_ms_median", 9, ".1f", "rndr CPU"),
    ]
    print(" ".join(f"{title:>{w}}" for _, w, _, title in cols))
    for r in rows:
        print(" ".join(f"{r[key]:>{w}{fmt}}" for key, w, fmt, _ in cols))
    print(
        "\nnot TRACKED (part-frames by reason): "
        + "; ".join(f"{r['parts']} parts: {r['not_tracked'] or 'none'}" for r in rows)
    )
    ok = {
        "position RMS <= 0.2 mm": all(r["pos_rms_mm"] <= TARGETS["pos_rms_mm"] for r in rows),
        "orientation RMS <= 0.3 deg": all(r["theta_rms_deg"] <= TARGETS["theta_rms_deg"] for r in rows),
        "zero id swaps": all(r["id_swaps"] == 0 for r in rows),
        "median <= 10 ms per frame (wall)": all(r["ms_median"] <= TARGETS["ms_per_frame"] for r in rows),
        "median <= 10 ms per frame (CPU)": all(r["cpu_ms_median"] <= TARGETS["ms_per_frame"] for r in rows),
    }
    print("targets: " + ", ".join(f"{k}: {'met' if v else 'MISSED'}" for k, v in ok.items()))


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["parts"] for r in rows]
    x = np.arange(len(rows))
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    ax = axes[0]
    ax.bar(x - 0.2, [r["pos_rms_mm"] for r in rows], 0.4, label="RMS")
    ax.bar(x + 0.2, [r["pos_max_mm"] for r in rows], 0.4, label="max")
    ax.axhline(TARGETS["pos_rms_mm"], color="k", ls="--", lw=1, label="target (RMS)")
    ax.set(title="position error (mm)", xticks=x, xticklabels=n, xlabel="parts")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.bar(x - 0.2, [r["theta_rms_deg"] for r in rows], 0.4, label="RMS")
    ax.bar(x + 0.2, [r["theta_max_deg"] for r in rows], 0.4, label="max")
    ax.axhline(TARGETS["theta_rms_deg"], color="k", ls="--", lw=1, label="target (RMS)")
    ax.set(title="orientation error (deg, modulo symmetry)", xticks=x, xticklabels=n, xlabel="parts")
    ax.legend(fontsize=8)
    ax = axes[2]
    ax.bar(x - 0.2, [r["ms_median"] for r in rows], 0.4, label="wall, median")
    ax.bar(x + 0.2, [r["cpu_ms_median"] for r in rows], 0.4, label="CPU, median")
    ax.axhline(TARGETS["ms_per_frame"], color="k", ls="--", lw=1, label="target")
    ax.set(title="tracker ms per frame", xticks=x, xticklabels=n, xlabel="parts")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
