"""Calibrate a device's accelerometer array from operating data (``ppod calibrate accel``).

Fits every channel's gain and sensing axis from recorded cycles over several motions (the array is
redundant: 12 channels for 6 rigid-body components), prints per channel what changed with its
uncertainty and the misfit, cross-validates (each motion held out in turn: misfit with the nominal
layout and with the calibration fitted on the other motions) and stores the calibration per device
(<cache-dir>/<device>/accel_calibration.json), where the accel_feedback node loads it at configure.
An ill-conditioned set of motions is refused, naming the channels and the motions to add.

Inputs (one kind per run):
  recordings   .npz / .csv accelerometer recordings (one segment per motion), or .mcap files that
               ppod record wrote (the /ppod/accel_summaries topic, split into steady motions)
  --ppod2-json the PPOD2 lab's JSON of saved cycles, with its own layout
  --simulated  play six calibration motions on an in-process simulated device (its default sensor
               errors) and calibrate from them

examples:
  ppod calibrate accel --simulated
  ppod calibrate accel --ppod2-json tests/data/ppod2_real_subset.json --device-id ppod2 --no-store
  ppod calibrate accel out/session.mcap
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

HELP = "calibrate the accelerometer array (gain and axis per channel) from recorded motions"
#: Records whose readings are below this RMS (m/s^2) carry no motion (an undriven plate): skipped.
MIN_MOTION_RMS_MPS2 = 1.0
#: Splitting recorded summaries into steady motions: a summary whose fundamental differs from the
#: running segment's mean by more than this fraction starts a new segment; shorter segments (ramps)
#: are dropped.
SEGMENT_CHANGE = 0.1
MIN_SEGMENT_SUMMARIES = 5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("what", choices=["accel"], help="what to calibrate (the accelerometer array)")
    parser.add_argument("recordings", nargs="*", type=Path, help="recordings (.npz, .csv, .mcap)")
    parser.add_argument("--ppod2-json", type=Path, help="the PPOD2 lab's saved cycles (layout included)")
    parser.add_argument("--simulated", action="store_true", help="calibrate an in-process simulated device")
    parser.add_argument("--device-config", default="", help="device description YAML (default: packaged)")
    parser.add_argument("--device-id", default="", help="store under this device id (default: the config's name)")
    parser.add_argument("--cache-dir", type=Path, default=Path.home() / ".cache" / "ppod",
                        help="where calibrations are stored per device (default: %(default)s)")
    parser.add_argument("--no-store", action="store_true", help="print the result only")
    parser.add_argument("--seed", type=int, default=None, help="simulator seed (--simulated)")


def _mcap_reader(path: Path):
    """An AccelRecording (summaries, one segment per steady motion) from the summaries in an MCAP file."""
    from ppod_nodes.common import topics
    from ppod_nodes.record.mcap_io import read_mcap
    from ppod_ros.errors import ConfigError
    from ppod_ros.estimation import AccelRecording

    rows, channels, freq = [], None, None
    for rec in read_mcap(path, ["/" + topics.ACCEL_SUMMARIES]):
        msg = rec.decode()
        C, K = len(msg.channels), len(msg.k)
        P = (np.asarray(msg.real_mps2) + 1j * np.asarray(msg.imag_mps2)).reshape(K, C)
        if not math.isfinite(msg.frequency_hz):
            continue
        if freq is None:
            channels, freq, k = tuple(msg.channels), msg.frequency_hz, np.asarray(msg.k)
        if msg.frequency_hz != freq or tuple(msg.channels) != channels:
            continue
        rows.append(P)
    if not rows:
        raise ConfigError(f"{path}: no /{topics.ACCEL_SUMMARIES} messages (record them with ppod record)")
    seg, current, members = [], 0, []
    for P in rows:
        if members:
            mean = np.mean(members, axis=0)[0]
            if np.linalg.norm(P[0] - mean) > SEGMENT_CHANGE * max(np.linalg.norm(mean), 1e-9):
                current += 1
                members = []
        members.append(P)
        seg.append(current)
    seg = np.array(seg)
    keep = np.isin(seg, [s for s in np.unique(seg) if np.sum(seg == s) >= MIN_SEGMENT_SUMMARIES])
    if not keep.any():
        raise ConfigError(f"{path}: no steady motion of at least {MIN_SEGMENT_SUMMARIES} summaries")
    _, relabel = np.unique(seg[keep], return_inverse=True)
    return AccelRecording(freq, channels, k=k, summaries=np.stack(rows)[keep], summary_segment=relabel,
                          meta={"motion": path.stem})


def _motions(args, layout):
    from ppod_ros.errors import ConfigError
    from ppod_ros.estimation import read_recording
    from ppod_ros.estimation.calibration import MotionData
    from ppod_ros.estimation.recording import register_reader

    register_reader(".mcap", _mcap_reader)
    out = []
    for path in args.recordings:
        rec = read_recording(path)
        for m in MotionData.from_recording(rec, layout):
            out.append(MotionData(f"{path.stem}:{m.name}", m.frequency_hz, m.k, m.phasors))
    if not out:
        raise ConfigError("recordings: give recordings, --ppod2-json or --simulated")
    return out


def run(args: argparse.Namespace) -> int:
    from ppod_ros.device import load_device_config
    from ppod_ros.errors import ConfigError
    from ppod_ros.estimation.calibration import MotionData, calibrate, save_calibration
    from ppod_ros.estimation.ppod2 import read_ppod2_json

    kinds = [bool(args.recordings), args.ppod2_json is not None, args.simulated]
    if sum(kinds) != 1:
        raise ConfigError("give exactly one input: recordings, --ppod2-json FILE or --simulated")
    config = load_device_config(args.device_config or None)
    device_id = args.device_id or config.name
    if args.simulated:
        from ppod_sim.calibration import calibrate_simulated_device

        cal = calibrate_simulated_device(config, seed=args.seed, progress=print)
    else:
        if args.ppod2_json is not None:
            layout, records = read_ppod2_json(args.ppod2_json)
            motions = []
            for name, r in records.items():
                if np.sqrt(np.mean(r.samples_mps2**2)) < MIN_MOTION_RMS_MPS2:
                    print(f"skipping {name}: readings below {MIN_MOTION_RMS_MPS2} m/s^2 RMS (no motion)")
                    continue
                motions.append(MotionData.from_samples(name, r.time_s, r.samples_mps2, r.frequency_hz))
        else:
            layout = config.accelerometers.layout
            motions = _motions(args, layout)
        print(f"calibrating {layout.num_channels} channels from {len(motions)} motions "
              f"(each held out in turn for cross-validation) ...")
        cal = calibrate(layout, motions)
    print(f"\n{'channel':10s} {'gain':>15s} {'axis change':>18s} {'misfit':>8s}")
    for i, n in enumerate(cal.names):
        print(f"{n:10s} {cal.gain[i]:8.4f} +- {cal.gain_std[i]:.4f} {cal.axis_change_deg[i]:8.2f} +- "
              f"{cal.axis_std_deg[i]:.2f} deg {100 * cal.misfit[i]:7.2f} %")
    print(f"\n{'held-out motion':28s} {'nominal':>9s} {'calibrated':>11s}   (misfit: residual / reading)")
    for name, v in cal.report.items():
        c = "n/a" if not math.isfinite(v["calibrated"]) else f"{100 * v['calibrated']:.2f} %"
        print(f"{name:28s} {100 * v['nominal']:7.2f} % {c:>11s}")
    print(f"\nplate bending (saddle read by the vertical channels, per unit p''z): cos 2theta "
          f"{100 * cal.bending[0]:+.2f} %, sin 2theta {100 * cal.bending[1]:+.2f} %")
    print("\nunobservable (fixed by convention):")
    for u in cal.unobservable:
        print(f"  - {u}")
    if not args.no_store:
        print(f"\nstored {save_calibration(cal, args.cache_dir, device_id)} (accel_feedback loads it at configure)")
    return 0
