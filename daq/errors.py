"""Exceptions raised by the acquisition side (drivers, transports, configuration).

One error channel: every failure of a device, a transport or a configuration surfaces as one of
these, each also a builtin (``ValueError``, ``ConnectionError``, ``TimeoutError``) so that generic
callers can catch it too (STYLE.md, "Errors"). Messages name the device, the key or the bytes.
"""

from __future__ import annotations

__all__ = [
    "ConfigError",
    "DaqError",
    "DeviceError",
    "ProtocolError",
    "SafetyError",
    "TransportError",
    "TransportTimeout",
]


class DaqError(Exception):
    """Base class of every acquisition error."""


class ConfigError(DaqError, ValueError):
    """A rig configuration is invalid: unknown or missing key, or a value out of its range."""


class TransportError(DaqError, ConnectionError):
    """A transport could not be opened, or failed while in use (disconnect, reset)."""


class TransportTimeout(TransportError, TimeoutError):
    """A read did not complete within its timeout."""


class ProtocolError(DaqError):
    """Bytes that do not follow the device's protocol (malformed frame, unexpected reply)."""


class DeviceError(DaqError):
    """The device reported an error (a code and its decoded text are in the message)."""


class SafetyError(DaqError, ValueError):
    """A command was refused because it would break a safety limit of the rig config."""
