"""Stored results per device: identified plants and learned corrections, reused across restarts.

Layout of the cache directory (configurable, e.g. ``~/.cache/ppod``)::

    <cache_dir>/<device_id>/plant/G_<excitation Hz, 3 decimals>Hz.npz   one identified G per frequency
    <cache_dir>/<device_id>/corrections/<goal key hex>.npz             one learned correction per goal

G_k at fundamental f is the plant's response at the excitation frequency k f, so the plant is stored
per device and excitation frequency, with the fundamental and harmonic that measured it kept as
provenance; harmonic 2 of a goal at 15 Hz (30 Hz) reuses harmonic 1 of an identification at 30 Hz.
Frequencies match to the nearest mHz. Writes are atomic (temporary file, then rename). Corrections
are keyed by :attr:`PlateMotion.key` (the goal's physical identity).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ppod_ros.control.plant import PlantModel
from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion

_DEVICE_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def _device_dir(root: Path, device_id: str) -> Path:
    if not isinstance(device_id, str) or not _DEVICE_ID.match(device_id):
        raise ConfigError(
            f"device_id: expected 1-64 characters of letters, digits, '.', '_' or '-', got {device_id!r}"
        )
    return root / device_id


def _load_npz(path: Path, required: set[str]) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as data:
            out = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: not a readable cache file: {exc}") from exc
    missing = sorted(required - set(out))
    if missing:
        raise ConfigError(f"{path}: missing arrays {missing}")
    return out


class PlantStore:
    """Identified plants per device and excitation frequency, as NPZ files under ``cache_dir``."""

    def __init__(self, cache_dir: str | Path):
        self.root = Path(cache_dir)

    def path(self, device_id: str, excitation_hz: float) -> Path:
        return _device_dir(self.root, device_id) / "plant" / f"G_{excitation_hz:.3f}Hz.npz"

    def save(self, device_id: str, plant: PlantModel, meta: dict[str, Any] | None = None) -> list[Path]:
        """Store every harmonic of ``plant`` (overwrites: this is how a refresh lands)."""
        paths = []
        for k in plant.k:
            path = self.path(device_id, k * plant.frequency_hz)
            path.parent.mkdir(parents=True, exist_ok=True)
            G = plant.matrix(int(k))
            info = {
                "device_id": device_id,
                "source": plant.source,
                "fundamental_hz": plant.frequency_hz,
                "k": int(k),
                "saved_unix_s": time.time(),
                **(meta or {}),
            }
            tmp = path.with_suffix(".tmp.npz")
            np.savez(
                tmp,
                G_re=G.real,
                G_im=G.imag,
                excitation_hz=np.float64(k * plant.frequency_hz),
                meta_json=np.array(json.dumps(info)),
            )
            tmp.replace(path)  # atomic: a reader never sees half a file
            paths.append(path)
        return paths

    def load(self, device_id: str, frequency_hz: float, k: list[int] | np.ndarray) -> PlantModel | None:
        """The stored plant for harmonics ``k`` at ``frequency_hz``, or None if any is missing."""
        G = []
        sources = set()
        for kk in k:
            path = self.path(device_id, int(kk) * frequency_hz)
            if not path.exists():
                return None
            data = _load_npz(path, {"G_re", "G_im", "meta_json"})
            G.append(data["G_re"] + 1j * data["G_im"])
            sources.add(json.loads(str(data["meta_json"])).get("source", "identified"))
        try:
            return PlantModel(frequency_hz, np.asarray(k, int), np.stack(G), source="/".join(sorted(sources)))
        except ConfigError as exc:
            raise ConfigError(f"stored plant of {device_id} at {frequency_hz:g} Hz: {exc}") from exc

    def entries(self, device_id: str) -> list[dict[str, Any]]:
        """Metadata of every stored frequency of a device, sorted by excitation frequency."""
        folder = _device_dir(self.root, device_id) / "plant"
        out = []
        for path in sorted(folder.glob("G_*Hz.npz")):
            data = _load_npz(path, {"meta_json", "excitation_hz"})
            out.append(
                {
                    "path": str(path),
                    "excitation_hz": float(data["excitation_hz"]),
                    **json.loads(str(data["meta_json"])),
                }
            )
        return sorted(out, key=lambda e: e["excitation_hz"])

    def get_or_identify(
        self,
        device_id: str,
        frequency_hz: float,
        k: list[int] | np.ndarray,
        identify: Callable[[], PlantModel],
        refresh: bool = False,
    ) -> PlantModel:
        """The stored plant, or ``identify()`` (a PlantModel) stored and returned; ``refresh`` forces it."""
        plant = None if refresh else self.load(device_id, frequency_hz, k)
        if plant is None:
            plant = identify()
            if not isinstance(plant, PlantModel) or not plant.covers(k):
                raise ConfigError(f"identify() must return a PlantModel covering harmonics {list(k)}")
            self.save(device_id, plant)
            plant = plant.restricted([int(x) for x in k])
        return plant


class CorrectionStore:
    """Learned corrections per device and goal; in memory, and on disk when ``cache_dir`` is given."""

    def __init__(self, cache_dir: str | Path | None = None):
        self.root = None if cache_dir is None else Path(cache_dir)
        self._memory: dict[tuple[str, bytes], tuple[np.ndarray, np.ndarray]] = {}

    def _path(self, device_id: str, goal: PlateMotion) -> Path | None:
        if self.root is None:
            return None
        return _device_dir(self.root, device_id) / "corrections" / f"{goal.key.hex()}.npz"

    def save(
        self,
        device_id: str,
        goal: PlateMotion,
        k: np.ndarray,
        correction_a: np.ndarray,
        meta: dict[str, Any] | None = None,
    ) -> None:
        """Remember ``correction_a`` (K, 6) complex (A) on harmonics ``k`` for ``goal``."""
        ks = np.asarray(k, int)
        corr = np.asarray(correction_a, complex)
        if corr.shape != (ks.size, 6) or not np.all(np.isfinite(corr)):
            raise ConfigError(f"correction_a: expected finite shape ({ks.size}, 6), got {corr.shape}")
        _device_dir(Path("."), device_id)  # validate the id even when memory-only
        self._memory[(device_id, goal.key)] = (ks.copy(), corr.copy())
        path = self._path(device_id, goal)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            info = {"goal": goal.to_dict(), "saved_unix_s": time.time(), **(meta or {})}
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, k=ks, re=corr.real, im=corr.imag, meta_json=np.array(json.dumps(info)))
            tmp.replace(path)

    def load(self, device_id: str, goal: PlateMotion) -> tuple[np.ndarray, np.ndarray] | None:
        """(k (K,), correction (K, 6)) learned for ``goal``, or None."""
        hit = self._memory.get((device_id, goal.key))
        if hit is not None:
            return hit[0].copy(), hit[1].copy()
        path = self._path(device_id, goal)
        if path is None or not path.exists():
            return None
        data = _load_npz(path, {"k", "re", "im"})
        ks, corr = data["k"].astype(int), data["re"] + 1j * data["im"]
        if corr.shape != (ks.size, 6) or not np.all(np.isfinite(corr)):
            raise ConfigError(f"{path}: stored correction has shape {corr.shape} for harmonics {ks.tolist()}")
        self._memory[(device_id, goal.key)] = (ks, corr)
        return ks.copy(), corr.copy()

    def initial_for(self, device_id: str, goal: PlateMotion, k: np.ndarray) -> np.ndarray | None:
        """A stored correction re-laid onto harmonics ``k`` (zeros where it has none), or None."""
        hit = self.load(device_id, goal)
        if hit is None:
            return None
        out = np.zeros((len(k), 6), complex)
        for row, kk in enumerate(hit[0]):
            where = np.flatnonzero(np.asarray(k) == kk)
            if where.size:
                out[where[0]] = hit[1][row]
        return out


__all__ = ["CorrectionStore", "PlantStore"]
