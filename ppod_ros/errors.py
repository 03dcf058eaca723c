"""The PPOD stack's exception tree.

Every error the core raises on purpose derives from :class:`PpodError`, so callers (nodes, the CLI)
can translate them into a service response, a diagnostic or a one-line message without catching
unrelated exceptions. Raise with ``from`` when wrapping a lower-level error.
"""

from __future__ import annotations


class PpodError(Exception):
    """Base class of all errors raised by the PPOD stack."""


class ConfigError(PpodError, ValueError):
    """Invalid configuration or input data; the message names the offending key or argument."""


class LimitError(PpodError):
    """A request would exceed a configured device limit; nothing was sent.

    Attributes
    ----------
    limit : str
        Dotted name of the limit in the device configuration, e.g. ``"limits.coil_current_a"``.
    limit_value : float
        The configured value of that limit (SI units of the limit).
    requested : float
        What the request would have needed, same units.
    """

    def __init__(self, message: str, *, limit: str, limit_value: float, requested: float):
        super().__init__(message)
        self.limit = limit
        self.limit_value = float(limit_value)
        self.requested = float(requested)


class DeviceError(PpodError):
    """The device (real or simulated) or its bus misbehaved: fault, timeout, lost heartbeat."""


class ProtocolError(DeviceError):
    """A CAN frame could not be encoded or decoded: wrong id, length or out-of-range value."""


class SolverError(PpodError):
    """A numerical solver could not produce a trustworthy result (bad settings, breakdown)."""


__all__ = ["PpodError", "ConfigError", "LimitError", "DeviceError", "ProtocolError", "SolverError"]
