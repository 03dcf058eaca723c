"""Recorded accelerometer data: raw samples or per-cycle harmonic summaries, read from files.

A recording holds one fundamental frequency, named channels, and either raw samples (sample times
from a device cycle start, NaN for missing samples) or per-cycle, per-channel harmonic phasors, split
into segments (one segment per learning iteration, say), optionally with the coil-current command
applied in each segment and the goal. Readers are chosen by file suffix from a table
(:data:`READERS`): ``.npz`` and ``.csv`` here; an MCAP reader registers itself with
:func:`register_reader` and returns the same :class:`AccelRecording`. Formats: docs/feedback.md.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion


@dataclass(frozen=True, eq=False)
class AccelRecording:
    """Accelerometer data of one frequency, validated on construction.

    Parameters
    ----------
    frequency_hz : float
    channels : tuple of str, length C
    time_s, samples_mps2, segment : arrays (N,), (N, C), (N,) int, or None
        Raw samples: times from a device cycle start (s), readings (m/s^2; NaN = missing), and the
        segment of each sample (default all 0).
    k, summaries, summary_segment : arrays (K,), complex (cycles, K, C), (cycles,) int, or None
        Per-cycle harmonic summaries (m/s^2 phasors) and the segment of each cycle.
    command_k, commands_a : arrays (Kc,), complex (S, Kc, 6), or None
        Coil-current phasors (A) applied during each segment 0..S-1.
    goal : PlateMotion or None
    meta : dict
        Free metadata (device id, seed, ...), JSON-serialisable.
    """

    frequency_hz: float
    channels: tuple[str, ...]
    time_s: np.ndarray | None = None
    samples_mps2: np.ndarray | None = None
    segment: np.ndarray | None = None
    k: np.ndarray | None = None
    summaries: np.ndarray | None = None
    summary_segment: np.ndarray | None = None
    command_k: np.ndarray | None = None
    commands_a: np.ndarray | None = None
    goal: PlateMotion | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        f = self.frequency_hz
        if not (isinstance(f, (int, float, np.integer, np.floating)) and math.isfinite(f) and f > 0):
            raise ConfigError(f"recording.frequency_hz: must be a finite number > 0 Hz, got {f!r}")
        chans = tuple(str(c) for c in self.channels)
        C = len(chans)
        if C == 0 or len(set(chans)) != C:
            raise ConfigError(f"recording.channels: expected distinct channel names, got {list(chans)}")
        set_ = object.__setattr__
        set_(self, "frequency_hz", float(f))
        set_(self, "channels", chans)
        raw = self.samples_mps2 is not None
        summ = self.summaries is not None
        if raw == summ:
            raise ConfigError(
                "recording: give either raw samples (time_s, samples_mps2) or summaries (k, summaries)"
            )
        if raw:
            y = np.asarray(self.samples_mps2, float)
            t = np.asarray(self.time_s, float) if self.time_s is not None else None
            if y.ndim != 2 or y.shape[1] != C:
                raise ConfigError(f"recording.samples_mps2: expected shape (N, {C}), got {y.shape}")
            if t is None or t.shape != (y.shape[0],) or not np.all(np.isfinite(t)):
                raise ConfigError(f"recording.time_s: expected {y.shape[0]} finite sample times (s)")
            set_(self, "samples_mps2", y)
            set_(self, "time_s", t)
            set_(self, "segment", self._labels(self.segment, y.shape[0], "segment"))
        else:
            ks = np.asarray(self.k)
            P = np.asarray(self.summaries, complex)
            if ks.ndim != 1 or ks.dtype.kind not in "iu" or np.any(ks < 1):
                raise ConfigError(f"recording.k: expected harmonic numbers >= 1, got {ks.tolist()}")
            if P.ndim != 3 or P.shape[1:] != (ks.size, C):
                raise ConfigError(
                    f"recording.summaries: expected shape (cycles, {ks.size}, {C}), got {P.shape}"
                )
            set_(self, "k", ks.astype(int))
            set_(self, "summaries", P)
            set_(self, "summary_segment", self._labels(self.summary_segment, P.shape[0], "summary_segment"))
        if (self.commands_a is None) != (self.command_k is None):
            raise ConfigError("recording: commands_a and command_k go together")
        if self.commands_a is not None:
            ck = np.asarray(self.command_k).astype(int)
            cmd = np.asarray(self.commands_a, complex)
            if cmd.ndim != 3 or cmd.shape[1:] != (ck.size, 6) or not np.all(np.isfinite(cmd)):
                raise ConfigError(
                    f"recording.commands_a: expected finite (segments, {ck.size}, 6), got {cmd.shape}"
                )
            if cmd.shape[0] <= int(self.segments()[-1]):
                raise ConfigError(
                    f"recording.commands_a: {cmd.shape[0]} commands for segments {self.segments()}"
                )
            set_(self, "command_k", ck)
            set_(self, "commands_a", cmd)
        if self.goal is not None and not isinstance(self.goal, PlateMotion):
            raise ConfigError("recording.goal: expected a PlateMotion")

    @staticmethod
    def _labels(value: Any, n: int, name: str) -> np.ndarray:
        lab = np.zeros(n, int) if value is None else np.asarray(value)
        if lab.shape != (n,) or lab.dtype.kind not in "iu" or np.any(lab < 0):
            raise ConfigError(f"recording.{name}: expected {n} segment numbers >= 0")
        return lab.astype(int)

    @property
    def kind(self) -> str:
        return "samples" if self.samples_mps2 is not None else "summaries"

    def segments(self) -> list[int]:
        lab = self.segment if self.kind == "samples" else self.summary_segment
        return sorted(set(lab.tolist()))

    def segment_data(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(time_s (n,), samples (n, C)) or (k (K,), summaries (cycles, K, C)) of segment ``s``."""
        if self.kind == "samples":
            sel = self.segment == s
            return self.time_s[sel], self.samples_mps2[sel]
        return self.k, self.summaries[self.summary_segment == s]

    def command(self, s: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(k (Kc,), command (Kc, 6) complex, A) applied during segment ``s``, if recorded."""
        return None if self.commands_a is None else (self.command_k, self.commands_a[s])


# ---------------------------------------------------------------------- NPZ
_NPZ_KEYS = {
    "frequency_hz",
    "channels",
    "time_s",
    "samples_mps2",
    "segment",
    "k",
    "summary_re",
    "summary_im",
    "summary_segment",
    "command_k",
    "command_re",
    "command_im",
    "goal_yaml",
    "meta_json",
}


def _read_npz(path: Path) -> AccelRecording:
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: not a readable .npz recording: {exc}") from exc
    unknown = sorted(set(arrays) - _NPZ_KEYS)
    if unknown:
        raise ConfigError(f"{path}: unknown arrays {unknown}; expected some of {sorted(_NPZ_KEYS)}")
    for key in ("frequency_hz", "channels"):
        if key not in arrays:
            raise ConfigError(f"{path}: required array '{key}' is missing")
    get = arrays.get
    summaries = None
    if "summary_re" in arrays or "summary_im" in arrays:
        summaries = get("summary_re") + 1j * get("summary_im")
    commands = None if "command_re" not in arrays else get("command_re") + 1j * get("command_im")
    goal = (
        None
        if "goal_yaml" not in arrays
        else PlateMotion.from_yaml_text(str(get("goal_yaml")), f"{path}: goal")
    )
    try:
        return AccelRecording(
            float(get("frequency_hz")),
            tuple(get("channels").tolist()),
            get("time_s"),
            get("samples_mps2"),
            get("segment"),
            get("k"),
            summaries,
            get("summary_segment"),
            get("command_k"),
            commands,
            goal,
            json.loads(str(get("meta_json"))) if "meta_json" in arrays else {},
        )
    except (ConfigError, TypeError) as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def _write_npz(rec: AccelRecording, path: Path) -> None:
    out: dict[str, Any] = {"frequency_hz": np.float64(rec.frequency_hz), "channels": np.array(rec.channels)}
    if rec.kind == "samples":
        out.update(time_s=rec.time_s, samples_mps2=rec.samples_mps2, segment=rec.segment)
    else:
        out.update(
            k=rec.k,
            summary_re=rec.summaries.real,
            summary_im=rec.summaries.imag,
            summary_segment=rec.summary_segment,
        )
    if rec.commands_a is not None:
        out.update(command_k=rec.command_k, command_re=rec.commands_a.real, command_im=rec.commands_a.imag)
    if rec.goal is not None:
        out["goal_yaml"] = np.array(rec.goal.to_yaml())
    if rec.meta:
        out["meta_json"] = np.array(json.dumps(rec.meta))
    np.savez_compressed(path, **out)


# ---------------------------------------------------------------------- CSV
def _read_csv(path: Path) -> AccelRecording:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: {exc.strerror or exc}") from exc
    header: dict[str, str] = {}
    body = []
    for line in text.splitlines():
        if line.startswith("#"):
            key, sep, value = line[1:].partition(":")
            if not sep:
                raise ConfigError(f"{path}: header line {line!r} is not '# key: value'")
            header[key.strip()] = value.strip()
        elif line.strip():
            body.append(line)
    unknown = sorted(set(header) - {"frequency_hz", "meta_json"})
    if unknown or "frequency_hz" not in header:
        raise ConfigError(
            f"{path}: header needs '# frequency_hz: F' (and optionally '# meta_json: ...'), "
            f"unknown keys {unknown}"
        )
    rows = list(csv.reader(io.StringIO("\n".join(body))))
    if len(rows) < 2:
        raise ConfigError(f"{path}: expected a column header row and data rows")
    cols = [c.strip() for c in rows[0]]
    try:
        data = np.array([[float(v) if v.strip() else math.nan for v in r] for r in rows[1:]])
        freq = float(header["frequency_hz"])
    except ValueError as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    if data.shape[1] != len(cols):
        raise ConfigError(f"{path}: rows have {data.shape[1]} values for {len(cols)} columns")
    meta = json.loads(header["meta_json"]) if "meta_json" in header else {}
    col = {c: i for i, c in enumerate(cols)}
    seg_of = (lambda key: data[:, col[key]].astype(int)) if "segment" in col else (lambda key: None)
    try:
        if cols[0] == "time_s":
            chans = [c for c in cols[1:] if c != "segment"]
            return AccelRecording(
                freq, tuple(chans), data[:, 0], data[:, [col[c] for c in chans]], seg_of("segment"), meta=meta
            )
        if cols[:2] == ["cycle", "k"]:
            names = [c[:-3] for c in cols if c.endswith(".re")]
            ks = np.unique(data[:, 1]).astype(int)
            cycles = np.unique(data[:, 0]).astype(int)
            P = np.full((cycles.size, ks.size, len(names)), np.nan + 0j)
            ci, ki = np.searchsorted(cycles, data[:, 0]), np.searchsorted(ks, data[:, 1])
            for j, n in enumerate(names):
                P[ci, ki, j] = data[:, col[n + ".re"]] + 1j * data[:, col[n + ".im"]]
            seg = None
            if "segment" in col:
                seg = np.zeros(cycles.size, int)
                seg[ci] = data[:, col["segment"]].astype(int)
            return AccelRecording(freq, tuple(names), k=ks, summaries=P, summary_segment=seg, meta=meta)
    except (ConfigError, KeyError) as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    raise ConfigError(
        f"{path}: first columns must be 'time_s' (samples) or 'cycle,k' (summaries), got {cols[:2]}"
    )


def _write_csv(rec: AccelRecording, path: Path) -> None:
    if rec.commands_a is not None or rec.goal is not None:
        raise ConfigError(f"{path}: CSV recordings hold no commands or goal; write .npz instead")
    buf = io.StringIO()
    buf.write(f"# frequency_hz: {rec.frequency_hz!r}\n")
    if rec.meta:
        buf.write(f"# meta_json: {json.dumps(rec.meta)}\n")
    w = csv.writer(buf, lineterminator="\n")
    if rec.kind == "samples":
        w.writerow(["time_s", "segment", *rec.channels])
        for t, s, row in zip(rec.time_s, rec.segment, rec.samples_mps2):
            w.writerow([repr(float(t)), int(s), *("" if math.isnan(v) else repr(float(v)) for v in row)])
    else:
        w.writerow(["cycle", "k", "segment", *(f"{c}.{p}" for c in rec.channels for p in ("re", "im"))])
        for i, (s, block) in enumerate(zip(rec.summary_segment, rec.summaries)):
            for k, row in zip(rec.k, block):
                vals = [repr(float(x)) for z in row for x in (z.real, z.imag)]
                w.writerow([i, int(k), int(s), *("" if v == "nan" else v for v in vals)])
    path.write_text(buf.getvalue(), encoding="utf-8")


# ---------------------------------------------------------------------- registry
#: Readers and writers by file suffix; an MCAP reader adds ".mcap" with :func:`register_reader`.
READERS: dict[str, Callable[[Path], AccelRecording]] = {".npz": _read_npz, ".csv": _read_csv}
WRITERS: dict[str, Callable[[AccelRecording, Path], None]] = {".npz": _write_npz, ".csv": _write_csv}


def register_reader(suffix: str, reader: Callable[[Path], AccelRecording]) -> None:
    """Make :func:`read_recording` open files ending in ``suffix`` (e.g. ".mcap") with ``reader``."""
    if not (isinstance(suffix, str) and suffix.startswith(".")):
        raise ConfigError(f"suffix: expected a file suffix such as '.mcap', got {suffix!r}")
    READERS[suffix.lower()] = reader


def _lookup(table: Mapping[str, Any], path: Path, what: str) -> Any:
    fn = table.get(path.suffix.lower())
    if fn is None:
        raise ConfigError(
            f"{path}: no accelerometer-recording {what} for '{path.suffix}' files "
            f"(known: {', '.join(sorted(table))})"
        )
    return fn


def read_recording(path: str | Path) -> AccelRecording:
    """Read a recording, choosing the reader by file suffix."""
    path = Path(path)
    return _lookup(READERS, path, "reader")(path)


def write_recording(recording: AccelRecording, path: str | Path) -> Path:
    """Write a recording (.npz: everything; .csv: samples or summaries without commands and goal).

    Atomic: written to a hidden file beside ``path`` and renamed, so a reader watching the directory
    never opens a half-written recording (a test reading a raw capture as soon as it appeared got a
    truncated zip), and a failed write leaves no file at ``path``."""
    path = Path(path)
    writer = _lookup(WRITERS, path, "writer")
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        writer(recording, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def recording_from_captures(captures: Sequence[Any], frequency_hz: float, names: Sequence[str],
                            meta: dict[str, Any] | None = None) -> AccelRecording:
    """Raw captures of the device (``ppod_ros.can.RawCapture``) as a recording, one segment each.

    Sample n of a capture was taken ``(n % N) T / N + (n // N) T`` after the start of its first cycle
    (``N`` samples per cycle, ``T = 1 / frequency_hz``): times from a cycle start, as the estimator
    wants them. ``names`` are the layout's channel names (a capture names channels by index); every
    capture must hold the same channels.
    """
    if not captures:
        raise ConfigError("captures: expected at least one raw capture")
    if not (frequency_hz > 0 and math.isfinite(frequency_hz)):
        raise ConfigError(f"frequency_hz: expected the plate's frequency (Hz) of the captures, got {frequency_hz}")
    chans = tuple(captures[0].channels)
    if any(tuple(c.channels) != chans for c in captures) or not chans or max(chans) >= len(names):
        raise ConfigError(f"captures: every capture must hold the same channels, within the {len(names)} of the "
                          f"layout; got {[tuple(c.channels) for c in captures]}")
    times, samples, segments = [], [], []
    for i, cap in enumerate(captures):
        y = np.asarray(cap.samples, dtype=float)
        n = np.arange(y.shape[0])
        N = int(cap.samples_per_cycle)
        times.append(((n % N) / N + n // N) / frequency_hz)
        samples.append(y)
        segments.append(np.full(y.shape[0], i, dtype=int))
    return AccelRecording(float(frequency_hz), tuple(names[c] for c in chans), time_s=np.concatenate(times),
                          samples_mps2=np.concatenate(samples), segment=np.concatenate(segments),
                          meta=dict(meta or {}))


__all__ = ["READERS", "AccelRecording", "read_recording", "recording_from_captures", "register_reader",
           "write_recording"]
