"""Where a running ``ppod up`` says what it started (so ``ppod estop`` finds the simulator's bus).

``$PPOD_RUN_DIR/stack-domain-D.yaml`` (default ``/tmp/ppod-$UID/``; D the stack's ROS domain) holds
the launcher's pid, the mode, its ROS domain and, with ``--sim``, the simulated device's CAN bridge
URL. One file per domain: stacks in two domains run side by side, and each one's ``ppod estop``
(in that domain's shell) finds its own simulator. The file is removed when the stack stops; a file
whose pid is gone is ignored. A second stack in the same ROS domain is refused (``Stack.start``):
the two would share node, service and topic names.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml


def run_dir() -> Path:
    return Path(os.environ.get("PPOD_RUN_DIR", f"/tmp/ppod-{os.getuid()}"))


def path(domain: str | int | None = None) -> Path:
    """The run file of ``domain`` (default: this process's ``ROS_DOMAIN_ID``, else 0)."""
    if domain is None:
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
    return run_dir() / f"stack-domain-{str(domain).strip() or '0'}.yaml"


def write(info: dict[str, Any]) -> Path:
    """Write the run file of ``info["domain"]`` for this process."""
    target = path(info["domain"])
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(yaml.safe_dump({"pid": os.getpid(), **info}))
    tmp.replace(target)
    return target


def read(domain: str | int | None = None) -> dict[str, Any] | None:
    """The info of the stack running in ``domain``, or None when no launcher of ours is alive there."""
    try:
        info = yaml.safe_load(path(domain).read_text())
        os.kill(int(info["pid"]), 0)
    except (OSError, ValueError, TypeError, KeyError, yaml.YAMLError):
        return None
    return info


def remove(domain: str | int | None = None) -> None:
    """Remove ``domain``'s run file if this process wrote it."""
    target = path(domain)
    try:
        info = yaml.safe_load(target.read_text())
        if int(info.get("pid", -1)) == os.getpid():
            target.unlink()
    except (OSError, ValueError, TypeError, AttributeError, yaml.YAMLError):
        pass
