"""Where a running ``ppod up`` says what it started (so ``ppod estop`` finds the simulator's bus).

``$PPOD_RUN_DIR/stack.yaml`` (default ``/tmp/ppod-$UID/stack.yaml``) holds the launcher's pid, the
mode, its ROS domain and, with ``--sim``, the simulated device's CAN bridge URL. It is removed when
the stack stops; a file whose pid is gone is ignored. A second stack in the same ROS domain is
refused (``Stack.start``): the two would share node, service and topic names.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml


def run_dir() -> Path:
    return Path(os.environ.get("PPOD_RUN_DIR", f"/tmp/ppod-{os.getuid()}"))


def write(info: dict[str, Any]) -> Path:
    path = run_dir() / "stack.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(yaml.safe_dump({"pid": os.getpid(), **info}))
    tmp.replace(path)
    return path


def read() -> dict[str, Any] | None:
    """The running stack's info, or None when no launcher of ours is alive."""
    path = run_dir() / "stack.yaml"
    try:
        info = yaml.safe_load(path.read_text())
        os.kill(int(info["pid"]), 0)
    except (OSError, ValueError, TypeError, KeyError, yaml.YAMLError):
        return None
    return info


def remove() -> None:
    path = run_dir() / "stack.yaml"
    try:
        info = yaml.safe_load(path.read_text())
        if int(info.get("pid", -1)) == os.getpid():
            path.unlink()
    except (OSError, ValueError, TypeError, AttributeError, yaml.YAMLError):
        pass
