"""Per-device JSON files under a cache folder (``CACHE/DEVICE_ID/NAME``): written atomically (a
reader never sees half a file), read with one clear error for an unreadable file. The stored
accelerometer calibration and misfit history use it."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from ppod_ros.errors import ConfigError


def device_file(cache_dir: str | Path, device_id: str, name: str) -> Path:
    """``cache_dir/device_id/name`` (``~`` expanded)."""
    return Path(cache_dir).expanduser() / device_id / name


def write_json(path: Path, data: Any) -> Path:
    """Write ``data`` as JSON to ``path`` atomically (folders created); returns ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}-", suffix=path.suffix)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=1)
    os.replace(tmp, path)
    return path


def read_json(path: Path, what: str) -> Any | None:
    """The JSON in ``path``, or None when it does not exist; ConfigError naming ``what`` if unreadable."""
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable {what}: {exc}") from exc


__all__ = ["device_file", "read_json", "write_json"]
