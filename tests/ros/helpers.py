"""Helpers for tests that start processes: bounded waits on their output, pid bookkeeping."""

from __future__ import annotations

import os
import queue
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: The test listener's log line once it has received 11 messages (tests/support/motion_listener.py).
#: A count, not a message name: DDS discovery may let the first few messages pass unseen.
LISTENER_ELEVENTH = r"\[motion_listener\].*received talk-\d+ .*; 11 so far"


def process_env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONUNBUFFERED"] = "1"
    env.update(extra)
    return env


class Proc:
    """A child process whose combined output is read in a thread, for bounded waits on lines."""

    def __init__(self, cmd: list[str], env: dict[str, str] | None = None):
        self.cmd = cmd
        self.p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1,
                                  env=env or process_env(), stdin=subprocess.DEVNULL)
        self.lines: list[str] = []
        self._q: queue.Queue[str] = queue.Queue()
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            self.lines.append(line.rstrip("\n"))
            self._q.put(line)

    def wait_for(self, pattern: str, timeout_s: float) -> re.Match:
        rx = re.compile(pattern)
        for line in self.lines:
            m = rx.search(line)
            if m:
                return m
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=0.1)
            except queue.Empty:
                if self.p.poll() is not None and self._q.empty():
                    break
                continue
            m = rx.search(line)
            if m:
                return m
        raise AssertionError(f"{pattern!r} not seen within {timeout_s} s; output:\n" + "\n".join(self.lines[-60:]))

    def wait(self, timeout_s: float) -> int:
        code = self.p.wait(timeout=timeout_s)
        self._t.join(timeout=2)
        return code

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.kill()
            self.p.wait(timeout=5)

    @property
    def output(self) -> str:
        return "\n".join(self.lines)


def ppod(*args: str, env: dict[str, str] | None = None) -> Proc:
    return Proc([sys.executable, "-m", "ppod_nodes.cli.main", *args], env=env)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie is gone for our purposes once reaped; check /proc state.
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split()[2]
    except FileNotFoundError:
        return False
    return state != "Z"


def wait_gone(pids: list[int], timeout_s: float) -> list[int]:
    deadline = time.monotonic() + timeout_s
    alive = list(pids)
    while alive and time.monotonic() < deadline:
        alive = [p for p in alive if pid_alive(p)]
        time.sleep(0.05)
    return alive
