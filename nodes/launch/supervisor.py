"""A small process supervisor: ``ros2 launch`` for machines without it.

Each node runs as its own OS process (``python -m MODULE --ros-args -r __node:=NAME --params-file
FILE``), in its own session so that the terminal's Ctrl-C reaches only the supervisor, which then
stops the children in order; the kernel sends each child SIGTERM if the supervisor itself dies
(``PR_SET_PDEATHSIG``), so no orphan outlives it. Output lines are forwarded with a ``[name]``
prefix. A child that exits on its own is reported with its status, never silently restarted;
required nodes take the others down with them.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from ppod_nodes.common.params import params_file_text
from ppod_nodes.launch.spec import NodeSpec
from ppod_nodes.ros_env import REALTIME_ENV

_COLORS = ["36", "33", "35", "32", "34", "31", "96", "93"]
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In the child before exec: get SIGTERM when the supervisor dies."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


#: The signals the stop sequence (and the parent's death) sends a child.
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _child_setup(nice: int):
    """What the child does before exec: take the stop signals at their defaults, die with the
    parent, lower its priority by ``nice``.

    A disposition of SIG_IGN and a blocked signal survive exec: a supervisor started as a background
    job of a non-interactive shell (a script, CI) has SIGINT ignored, and its children would ignore
    the SIGINT that stops them and wait out the shutdown timeout. Reset, a Python child raises
    KeyboardInterrupt on it again, and a node's own handlers (rclpy's) are installed as before."""

    def setup() -> None:
        for sig in _STOP_SIGNALS:
            signal.signal(sig, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)
        _die_with_parent()
        if nice:
            os.nice(nice)

    return setup


def describe_exit(code: int | None) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


@dataclass
class Child:
    spec: NodeSpec
    process: subprocess.Popen
    params_file: Path
    reader: threading.Thread | None = None
    stopping: bool = False
    reported: bool = False
    lines: list[str] = field(default_factory=list)


class Supervisor:
    """Start, watch and stop node processes.

    Parameters
    ----------
    env : dict
        Environment for the children (DDS discovery range, domain id, ...).
    sim : bool
        Choose each node's ``sim_params`` (True) or ``hardware_params`` (False).
    out : text stream
        Where prefixed child output goes (default: stdout).
    log_dir : Path, optional
        Also write each child's output to ``log_dir/NAME.log``.
    """

    def __init__(self, env: dict[str, str], sim: bool, out: IO[str] | None = None, log_dir: Path | None = None,
                 color: bool | None = None, keep_lines: int = 200, substitutions: dict | None = None):
        self.env = env
        self.sim = sim
        self.out = out or sys.stdout
        self.log_dir = log_dir
        self.color = self.out.isatty() if color is None else color
        self.children: list[Child] = []
        self._tmp = Path(tempfile.mkdtemp(prefix="ppod-up-"))
        self._lock = threading.Lock()
        self._keep = keep_lines
        self.substitutions = substitutions or {}

    # ------------------------------------------------------------------ output
    def say(self, text: str) -> None:
        with self._lock:
            print(f"[ppod up] {text}", file=self.out, flush=True)

    def _forward(self, child: Child, index: int) -> None:
        prefix = f"[{child.spec.name}]"
        if self.color:
            prefix = f"\033[{_COLORS[index % len(_COLORS)]}m{prefix}\033[0m"
        log_path = self.log_dir / f"{child.spec.name}.log" if self.log_dir else os.devnull
        with open(log_path, "a") as logf:
            assert child.process.stdout is not None
            for line in child.process.stdout:
                line = line.rstrip("\n")
                child.lines.append(line)
                del child.lines[:-self._keep]
                with self._lock:
                    print(f"{prefix} {line}", file=self.out, flush=True)
                logf.write(line + "\n")
                logf.flush()

    # ------------------------------------------------------------------ start
    def start(self, spec: NodeSpec) -> Child:
        params_file = self._tmp / f"{spec.name}.yaml"
        params_file.write_text(params_file_text(spec.name, spec.parameters(self.sim, self.substitutions)))
        cmd = [sys.executable, "-u", "-m", spec.module, *spec.args, "--ros-args", "-r", f"__node:={spec.name}",
               "--params-file", str(params_file)]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                text=True, bufsize=1, env=self._child_env(spec), start_new_session=True,
                                preexec_fn=_child_setup(spec.nice))
        child = Child(spec, proc, params_file)
        child.reader = threading.Thread(target=self._forward, args=(child, len(self.children)), daemon=True,
                                        name=f"log-{spec.name}")
        child.reader.start()
        self.children.append(child)
        self.say(f"started {spec.name} (pid {proc.pid}): python -m {spec.module}"
                 + (f" (nice {spec.nice})" if spec.nice else "")
                 + (f" (real-time priority {spec.realtime_priority} asked)" if spec.realtime_priority else ""))
        return child

    def _child_env(self, spec: NodeSpec) -> dict[str, str]:
        """The launcher's environment, without a real-time request of its own, plus the node's."""
        env = dict(self.env if self.env is not None else os.environ)
        env.pop(REALTIME_ENV, None)
        env.update(spec.env)
        return env

    # ------------------------------------------------------------------ watch
    def dead_children(self) -> list[Child]:
        """Children that exited without being asked to; each is reported once."""
        dead = []
        for child in self.children:
            code = child.process.poll()
            if code is not None and not child.stopping and not child.reported:
                child.reported = True
                if child.reader:
                    child.reader.join(timeout=1.0)
                self.say(f"{child.spec.name} exited unexpectedly ({describe_exit(code)})"
                         + ("" if child.spec.required else "; it is not required, the others keep running"))
                dead.append(child)
        return dead

    def running(self) -> list[Child]:
        return [c for c in self.children if c.process.poll() is None]

    # ------------------------------------------------------------------ stop
    def stop_all(self, timeout_s: float, before_signal: Callable[[Child], None] | None = None) -> bool:
        """Stop every child in reverse start order: SIGINT, then SIGTERM, then SIGKILL.

        Returns True if every child exited before the SIGKILL stage.
        """
        clean = True
        for child in reversed(self.children):
            child.stopping = True
            if child.process.poll() is not None:
                continue
            if before_signal is not None:
                before_signal(child)
            self._signal(child, signal.SIGINT)
            if not self._wait(child, timeout_s):
                self.say(f"{child.spec.name} did not stop within {timeout_s:g} s; sending SIGTERM")
                self._signal(child, signal.SIGTERM)
                if not self._wait(child, 3.0):
                    self.say(f"{child.spec.name} still running; sending SIGKILL")
                    self._signal(child, signal.SIGKILL, group=True)
                    self._wait(child, 3.0)
                    clean = False
        for child in self.children:
            # Anything the node itself spawned in its session goes too.
            self._signal(child, signal.SIGKILL, group=True)
            if child.reader:
                child.reader.join(timeout=2.0)
            code = child.process.poll()
            if not child.reported:
                self.say(f"{child.spec.name} stopped ({describe_exit(code)})")
                child.reported = True
        return clean

    @staticmethod
    def _wait(child: Child, timeout_s: float) -> bool:
        try:
            child.process.wait(timeout=timeout_s)
            return True
        except subprocess.TimeoutExpired:
            return False

    @staticmethod
    def _signal(child: Child, sig: int, group: bool = False) -> None:
        try:
            if group:
                os.killpg(child.process.pid, sig)
            else:
                child.process.send_signal(sig)
        except ProcessLookupError:
            pass  # already gone: that is what we wanted

    def close(self) -> None:
        for path in self._tmp.glob("*"):
            path.unlink(missing_ok=True)
        self._tmp.rmdir()


def wait_interruptible(seconds: float, stop: threading.Event, poll: Callable[[], bool], step_s: float = 0.1) -> bool:
    """Sleep up to ``seconds`` while ``poll()`` stays True and ``stop`` is unset; True if it ran out."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if stop.wait(step_s) or not poll():
            return False
    return True
