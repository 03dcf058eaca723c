"""The heartbeat keeper: a small process that sends a host's heartbeats while the host renews its lease.

Why a process. A heartbeat thread inside a Python process runs only when it gets the interpreter's
lock (the GIL). Whatever holds the GIL for longer than the device's watchdog allows (150 ms) stops
the heartbeats, and the device ramps the plate to rest. Measured in the waveform generator: rclpy's
``Publisher.publish`` blocks for about 330 ms with the GIL held while Fast DDS matches a new reader
of its topic (Foxglove, ``ppod view``, any script subscribing mid-run; docs/device.md, "Heartbeat
stalls"). A separate process has its own interpreter: nothing the host's Python does can hold it.

What keeps it safe. The keeper sends heartbeats only while its lease runs: the host writes a byte
to the keeper's standard input every heartbeat period, and each byte renews the lease for
``lease_s``. So

- the host process dies (any way, SIGKILL included): the kernel closes the pipe, the keeper reads
  end-of-file and stops at once (within one period); the device's watchdog trips as before;
- the host process is frozen (SIGSTOP, a deadlock that holds the GIL): the lease runs out after
  ``lease_s`` and the heartbeats stop; the watchdog trips ``lease_s`` later than it would have with
  an in-process thread, and no later;
- the host's Python is held for less than ``lease_s`` (the DDS stall): the keeper beats on and the
  plate keeps its motion;
- the keeper itself dies: the host sees it gone and sends the heartbeats from its own thread again;
  a keeper that is stopped (SIGSTOP) sends none and the watchdog trips (the host's renewals fail
  once the pipe is full, and its thread beats again).

The keeper opens its own connection to the bus with the host's CAN settings, with a receive filter
that matches no frame (it only sends). That needs a bus more than one process can open: the
simulator's localhost bridge (``remote``) and SocketCAN. python-can's ``virtual`` bus is in-process
only; there, and on vendor backends that give a channel to one process, the host keeps its thread
(:func:`keeper_supported`).

A send that fails (bus-off) is skipped and logged (the 1st, 10th, 100th, then every 1000th), and
the keeper keeps trying: the host's own sends fail on such a bus as well, and the device's watchdog
ramps the plate down until the bus recovers. Its summary line (``HeartbeatKeeper.close``, in the
host's log) counts them.

Interrupts: the keeper ignores SIGINT and SIGTERM, which a launcher sends to the whole process group.
The host then ramps the plate down with the keeper still beating, and the keeper ends when the
host closes the pipe or exits.

Run as ``python -c BOOTSTRAP SPEC`` by :class:`HeartbeatKeeper` (``SPEC``: JSON, see
:func:`keeper_spec`). The bootstrap drops a real-time scheduling policy inherited from the host
for the imports and the bus's opening, and takes it back to beat.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import select
import signal
import subprocess
import sys
import threading
import time
from typing import Any

from ppod_ros.errors import ConfigError, DeviceError

log = logging.getLogger(__name__)

#: Backends a second process can open beside the host's own connection.
MULTI_PROCESS_BACKENDS = ("remote", "socketcan")

#: A receive filter that matches no frame: an extended identifier 0 (the protocol uses standard ones).
NO_FRAMES = [{"can_id": 0, "can_mask": 0x1FFFFFFF, "extended": True}]

#: The keeper exits after its lease has been out this long (a host that stopped renewing for good;
#: end-of-file is the normal end).
ORPHAN_AFTER_S = 30.0

_BOOTSTRAP = (
    "import os, sys\n"
    "policy = os.sched_getscheduler(0)\n"
    "param = os.sched_getparam(0)\n"
    "if policy != os.SCHED_OTHER:\n"
    "    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))\n"
    "from ppod_ros.can.keeper import main\n"
    "sys.exit(main(sys.argv[1], policy, param.sched_priority))\n"
)


def keeper_supported(interface: str) -> bool:
    """True when a second process can open ``interface`` beside the host (see the module docstring)."""
    return interface in MULTI_PROCESS_BACKENDS


def keeper_spec(can_settings, lease_s: float) -> dict[str, Any]:
    """The keeper's command-line specification from a :class:`~ppod_ros.device.schema.CanSettings`."""
    period = float(can_settings.heartbeat_period_s)
    if not (math.isfinite(lease_s) and lease_s >= 2 * period):
        raise ConfigError(f"heartbeat lease: must be at least two heartbeat periods ({2 * period:g} s), "
                          f"got {lease_s!r}")
    return {"interface": can_settings.interface, "channel": str(can_settings.channel),
            "bitrate": int(can_settings.bitrate), "options": [list(kv) for kv in can_settings.options],
            "device_node": int(can_settings.device_node_id), "host_node": int(can_settings.host_node_id),
            "period_s": period, "lease_s": float(lease_s)}


class HeartbeatKeeper:
    """The host's handle on a keeper process (see the module docstring).

    ``renew()`` every heartbeat period once ``ready()``; ``alive()`` is False once the process is
    gone (the host then beats itself); ``close()`` ends it and returns its summary line."""

    def __init__(self, can_settings, lease_s: float):
        spec = keeper_spec(can_settings, lease_s)
        if not keeper_supported(spec["interface"]):
            raise ConfigError(f"heartbeat keeper: the {spec['interface']} backend cannot be opened by a second "
                              f"process (expected one of {', '.join(MULTI_PROCESS_BACKENDS)})")
        self.lease_s = float(lease_s)
        try:
            self.process = subprocess.Popen([sys.executable, "-c", _BOOTSTRAP, json.dumps(spec)],
                                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0,
                                            close_fds=True)
        except OSError as exc:
            raise DeviceError(f"heartbeat keeper not started: {exc}") from exc
        # Never block the host's heartbeat thread: a keeper that stopped reading (SIGSTOP) fills the
        # pipe after 64 KiB of renewals, and a renewal then fails (the thread beats itself).
        os.set_blocking(self.process.stdin.fileno(), False)
        self._ready = threading.Event()
        self._lines: list[str] = []
        self._reader = threading.Thread(target=self._read, name="ppod-keeper-out", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for raw in iter(self.process.stdout.readline, b""):
            line = raw.decode(errors="replace").strip()
            if line == "ready":
                self._ready.set()
            elif line:
                self._lines.append(line)

    @property
    def pid(self) -> int:
        return self.process.pid

    def ready(self) -> bool:
        """The keeper has its bus and beats (while its lease runs)."""
        return self._ready.is_set() and self.process.poll() is None

    def alive(self) -> bool:
        return self.process.poll() is None

    def renew(self) -> bool:
        """Renew the lease; False when the keeper is gone or has stopped reading."""
        try:
            os.write(self.process.stdin.fileno(), b".")
        except (OSError, ValueError):   # BrokenPipeError: gone; BlockingIOError: not reading; ValueError: closed
            return False
        return True

    def close(self, timeout_s: float = 2.0) -> str:
        """End the keeper (end-of-file on its input; SIGKILL after ``timeout_s``); its summary line."""
        with contextlib.suppress(OSError):
            self.process.stdin.close()
        try:
            self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout_s)
        self._reader.join(timeout_s)
        return self._lines[-1] if self._lines else f"exit code {self.process.returncode}"


# ---------------------------------------------------------------------------------------- the process
def main(spec_json: str, policy: int = os.SCHED_OTHER, priority: int = 0) -> int:
    """The keeper process (see the module docstring); ``policy``/``priority``: the scheduling to beat at."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    logging.basicConfig(level=logging.INFO, format="[heartbeat keeper] %(message)s", stream=sys.stderr)
    spec = json.loads(spec_json)
    import can

    from ppod_ros.can.bus import open_bus
    from ppod_ros.can.commands import Heartbeat

    try:
        bus = open_bus(interface=spec["interface"], channel=spec["channel"], bitrate=spec["bitrate"],
                       **{**dict(spec["options"]), "can_filters": NO_FRAMES})
    except (ConfigError, DeviceError) as exc:
        log.error("no bus: %s", exc)
        return 2
    if policy != os.SCHED_OTHER:
        try:
            os.sched_setscheduler(0, policy, os.sched_param(priority))
        except OSError as exc:
            log.warning("scheduling policy %d priority %d not taken back (%s)", policy, priority, exc)
    period, lease = float(spec["period_s"]), float(spec["lease_s"])
    device, host = int(spec["device_node"]), int(spec["host_node"])
    # Drain whatever a backend delivers despite the filter (none should), so nothing queues up.
    closing = threading.Event()
    drain = threading.Thread(target=_drain, args=(bus, closing), name="drain", daemon=True)
    drain.start()
    fd = sys.stdin.fileno()
    os.write(sys.stdout.fileno(), b"ready\n")
    now = time.monotonic()
    lease_until, renewed, next_beat = now + lease, now, now
    counter = sent = covered = expired = errors = 0
    lapsed = False
    while True:
        wait = max(0.0, next_beat - time.monotonic())
        readable, _, _ = select.select([fd], [], [], wait)
        now = time.monotonic()
        if readable:
            if not os.read(fd, 4096):
                break   # end-of-file: the host closed the pipe or is gone
            lease_until, renewed = now + lease, now
            lapsed = False
        if now < next_beat:
            continue
        next_beat = max(next_beat + period, now)
        if now >= lease_until:
            if not lapsed:
                expired += 1
                lapsed = True
                log.warning("the host has not renewed its lease for %.0f ms: no more heartbeats until it "
                            "does (the device's watchdog ramps the plate down)", 1e3 * (now - renewed))
            if now - lease_until > ORPHAN_AFTER_S:
                log.warning("lease out for %.0f s: exiting", ORPHAN_AFTER_S)
                break
            continue
        counter = (counter + 1) % 256
        try:
            bus.send(Heartbeat(counter, host).encode(device))
        except can.CanError as exc:
            errors += 1
            if errors in (1, 10, 100) or errors % 1000 == 0:
                log.warning("heartbeat not sent (%d so far): %s", errors, exc)
            continue
        sent += 1
        if now - renewed > 2 * period:
            covered += 1   # a beat the host's own thread would have missed
    summary = (f"sent {sent} heartbeats, {covered} while the host's renewal was late, lease out {expired} times"
               + (f", {errors} not sent (bus errors)" if errors else ""))
    with contextlib.suppress(OSError):
        os.write(sys.stdout.fileno(), f"{summary}\n".encode())
    closing.set()
    drain.join(1.0)
    closer = threading.Thread(target=_close, args=(bus,), daemon=True)
    closer.start()
    closer.join(1.0)
    return 0


def _drain(bus, closing: threading.Event) -> None:
    while not closing.is_set():
        try:
            bus.recv(0.2)
        except Exception:   # noqa: BLE001 - the bus is going away; the main loop reports send errors
            closing.wait(0.5)


def _close(bus) -> None:
    try:
        bus.shutdown()
    except Exception as exc:   # noqa: BLE001 - on the way out: the connection may be gone already
        log.debug("bus shutdown: %s", exc)


__all__ = ["MULTI_PROCESS_BACKENDS", "HeartbeatKeeper", "keeper_spec", "keeper_supported", "main"]
