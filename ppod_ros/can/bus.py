"""The bus factory: one function opens the configured CAN backend by name.

The same configuration runs in the lab and in tests (STYLE.md rule 5):

=============  ==================================================================================
``virtual``    python-can's in-process bus; ``channel`` names it (tests, the simulator's inside)
``remote``     the localhost bridge client (python-can-remote): ``channel`` is ``ws://HOST:PORT/``,
               served by the simulated device process (``python -m ppod_sim``)
``socketcan``  Linux SocketCAN (``can0``, ``vcan0``); the bit rate is set by ``ip link``
other          any python-can interface (``pcan``, ``kvaser``, ``vector``, ``slcan``, ...) with
               ``channel`` and ``bitrate`` passed through
=============  ==================================================================================

Backend-specific keywords come from ``can.options`` in the device description and are passed to
``can.Bus`` unchanged, e.g. ``{tty_baudrate: 115200}`` for slcan, ``{fd: true, data_bitrate: 2000000}``
for pcan, ``{accept_virtual: true}`` for kvaser. Whatever a backend raises while opening (python-can
errors, OS errors, and the odd ``NameError`` of a vendor library that is not installed) becomes one
:class:`DeviceError` line naming the backend, the channel and the cause.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any
from urllib.parse import urlparse

import can

from ppod_ros.device.config import CanSettings
from ppod_ros.errors import ConfigError, DeviceError


def _virtual(channel: str, bitrate: int, extra: dict[str, Any]) -> can.BusABC:
    return can.Bus(interface="virtual", channel=channel, **{"receive_own_messages": False, **extra})


def _remote(channel: str, bitrate: int, extra: dict[str, Any]) -> can.BusABC:
    url = urlparse(channel)
    if url.scheme not in ("ws", "wss") or not url.hostname or url.port is None:
        raise ConfigError(f"can.channel: the remote backend needs a ws://HOST:PORT/ address, got {channel!r}")
    return can.Bus(interface="remote", channel=channel, **extra)


def _socketcan(channel: str, bitrate: int, extra: dict[str, Any]) -> can.BusABC:
    return can.Bus(interface="socketcan", channel=channel, **extra)


def _passthrough(name: str) -> Callable[[str, int, dict[str, Any]], can.BusABC]:
    def open_(channel: str, bitrate: int, extra: dict[str, Any]) -> can.BusABC:
        return can.Bus(interface=name, channel=channel, bitrate=bitrate, **extra)

    return open_


BACKENDS: dict[str, Callable[[str, int, dict[str, Any]], can.BusABC]] = {
    "virtual": _virtual,
    "remote": _remote,
    "socketcan": _socketcan,
}


def backend_names() -> list[str]:
    """Every backend name :func:`open_bus` accepts."""
    return sorted(set(BACKENDS) | set(can.VALID_INTERFACES))


def open_bus(
    settings: CanSettings | None = None,
    *,
    interface: str | None = None,
    channel: str | None = None,
    bitrate: int | None = None,
    **extra: Any,
) -> can.BusABC:
    """Open the CAN bus named by ``settings`` (or the keyword overrides).

    Raises
    ------
    ConfigError
        Unknown backend name or malformed channel.
    DeviceError
        The backend exists but the bus could not be opened (no server, no interface, ...).
    """
    if settings is not None and settings.options:
        extra = {**dict(settings.options), **extra}  # keyword overrides win over the file's options
    interface = interface or (settings.interface if settings else None)
    channel = channel if channel is not None else (settings.channel if settings else None)
    bitrate = bitrate or (settings.bitrate if settings else 1_000_000)
    if not interface or channel is None:
        raise ConfigError("can.interface, can.channel: both are needed to open a bus")
    if interface in BACKENDS:
        opener = BACKENDS[interface]
    elif interface in can.VALID_INTERFACES:
        opener = _passthrough(interface)
    else:
        raise ConfigError(
            f"can.interface: unknown backend {interface!r}; expected one of {', '.join(backend_names())}"
        )
    try:
        return opener(str(channel), int(bitrate), extra)
    except ConfigError:
        raise
    except TypeError as exc:  # a keyword the backend does not take: the configuration is wrong
        raise ConfigError(f"can.options: the {interface} backend rejects {sorted(extra)}: {exc}") from exc
    except Exception as exc:  # noqa: BLE001 - vendor backends raise anything (kvaser: NameError); one line
        cause = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DeviceError(f"cannot open the {interface} bus on {channel!r}: {type(exc).__name__}: {cause}") from exc


def open_bus_waiting(settings: CanSettings, wait_s: float, retry_s: float = 0.2, **overrides: Any) -> can.BusABC:
    """:func:`open_bus`, retrying for up to ``wait_s`` while the bus cannot be opened yet.

    For a device that is still coming up (the simulator's bridge while its process starts, a USB
    adapter being enumerated). Configuration errors are not retried.
    """
    deadline = time.monotonic() + wait_s
    while True:
        try:
            return open_bus(settings, **overrides)
        except DeviceError:
            if time.monotonic() + retry_s > deadline:
                raise
            time.sleep(retry_s)


__all__ = ["BACKENDS", "backend_names", "open_bus", "open_bus_waiting"]
