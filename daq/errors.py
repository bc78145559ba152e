"""Every exception daq raises, in one place: the error boundary of the acquisition side.

One error channel: every failure of a device, a transport, a configuration, a recording or the
console's acquisition surfaces as one of these, each also a builtin (``ValueError``,
``ConnectionError``, ``TimeoutError``, ``OSError``, ``RuntimeError``) so that generic callers can
catch it too. Messages name the device, the key or the bytes. No other module of daq defines an
exception class (``tests/test_architecture.py`` checks it).

The tree::

    DaqError(Exception)
    ├── ConfigError(ValueError)          bad or unknown key, value out of its range
    ├── TransportError(ConnectionError)  a link cannot be opened, or failed in use
    │   └── TransportTimeout(TimeoutError)
    ├── ProtocolError                    bytes that do not follow the device's protocol
    ├── DeviceError                      the device reported an error
    │   └── ModbusDeviceError            ... as a Modbus exception response (code, function)
    ├── DriverUnavailableError(RuntimeError)  a driver's vendor library or runtime is missing
    ├── SafetyError(ValueError)          a command refused by a safety limit or interlock
    ├── SyncError(ValueError)            a synchronisation step with no answer yet
    ├── CalzError(RuntimeError)          a CALZ during a run failed after the scan stopped
    ├── RecorderError                    the run file writer
    │   ├── StorageError(OSError)        the file cannot be created or written (errno set)
    │   │   └── InsufficientSpaceError   too little free space
    │   └── RecorderStateError(RuntimeError)  a call out of the writer's order
    ├── RecordingError(RuntimeError)     a console recording request that cannot be served now
    ├── ReplayError(ValueError)          a run file that cannot be replayed
    ├── RingStalledError(RuntimeError)   the shared ring's lock not released in time
    ├── AcquisitionProcessError(RuntimeError)  the console's acquisition process is gone
    ├── RemoteError(RuntimeError)        an error of that process that could not be sent as is
    ├── DeviceCheckError(RuntimeError)   the check before a run found devices wrong (all named)
    ├── PluginError(RuntimeError)        an installed driver plugin that cannot be used (named)
    └── OperatorError(RuntimeError)      an operator's answer a step waits for cannot come
"""

from __future__ import annotations

__all__ = [
    "AcquisitionProcessError",
    "CalzError",
    "ConfigError",
    "DaqError",
    "DeviceCheckError",
    "PluginError",
    "DeviceError",
    "DriverUnavailableError",
    "InsufficientSpaceError",
    "ModbusDeviceError",
    "NotARunFileError",
    "OperatorError",
    "ProtocolError",
    "RecorderError",
    "RecorderStateError",
    "RecoveryError",
    "RecordingError",
    "RemoteError",
    "ReplayError",
    "RingStalledError",
    "SafetyError",
    "StorageError",
    "SyncError",
    "TransportError",
    "TransportTimeout",
    "UsageError",
]


class DaqError(Exception):
    """Base class of every acquisition error."""


# -- configuration, transports, devices -----------------------------------------------------------
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


class ModbusDeviceError(DeviceError):
    """The device answered with a Modbus exception response.

    Attributes
    ----------
    code : int
        The Modbus exception code (2 = illegal data address, ...; see
        :data:`daq.transports.modbus.EXCEPTION_CODES`).
    function_code : int
        The function code of the request that was refused (1, 2, 3, 5, 6).
    """

    def __init__(self, message: str, *, code: int, function_code: int) -> None:
        super().__init__(message)
        self.code = code
        self.function_code = function_code


class DriverUnavailableError(DaqError, RuntimeError):
    """A driver's vendor library or runtime is not installed (the message names what to install).

    E.g. the NI-DAQmx driver without the ``nidaqmx`` package, or with the package but without
    the NI-DAQmx C library it loads.
    """


class SafetyError(DaqError, ValueError):
    """A command was refused because it would break a safety limit of the rig config."""


# -- synchronisation and the engine ---------------------------------------------------------------
class SyncError(DaqError, ValueError):
    """A synchronisation step cannot give an answer (e.g. a clock map with no data yet)."""


class CalzError(DaqError, RuntimeError):
    """A zero calibration during a run failed after the scan was interrupted.

    The message says at which step (``pause``, ``stop``, ``calz``, ``restart``) and whether the
    scan runs again; the device's own error is the ``__cause__``.
    """


# -- recording ------------------------------------------------------------------------------------
class RecorderError(DaqError):
    """Base class of the errors of the run recorder."""


class StorageError(RecorderError, OSError):
    """The run file cannot be created or written (permissions, no such directory, disk full).

    ``errno`` is set (``EACCES``, ``ENOENT``, ``ENOSPC``, ...) and ``filename`` is the file.
    """


class InsufficientSpaceError(StorageError):
    """The file system of the run file has less free space than the configured minimum."""


class RecorderStateError(RecorderError, RuntimeError):
    """A method was called out of the order open -> declare -> start -> append -> close."""


# -- the console ----------------------------------------------------------------------------------
class RecordingError(DaqError, RuntimeError):
    """A recording request that cannot be carried out now.

    Already recording, not recording, the acquisition not running, or the dispatcher not
    answering in time. File problems (an existing file, a missing or read-only directory, a
    full disk) are :class:`StorageError` instead.
    """


class RecoveryError(RecorderError, ValueError):
    """A run file that ``windrig recover`` cannot or must not recover (named in the message)."""


class NotARunFileError(RecoveryError):
    """The path is not a windrig run file: a directory, not HDF5, or another HDF5 layout."""


class UsageError(DaqError, ValueError):
    """A command-line value, or a file it names, that the command cannot take (exit 2)."""


class ReplayError(DaqError, ValueError):
    """A run file cannot be replayed: missing, not HDF5, truncated, or not a windrig run."""


class RingStalledError(DaqError, RuntimeError):
    """The shared ring's lock was not released in time: its writer died holding it, or is stuck."""


class AcquisitionProcessError(DaqError, RuntimeError):
    """The acquisition process did not start, did not answer, or is gone."""


class RemoteError(DaqError, RuntimeError):
    """An exception raised in the acquisition process that could not be sent as it was.

    Its message is the original's type name and message.
    """


class DeviceCheckError(DaqError, RuntimeError):
    """The device check before a run (``windrig check``) found devices wrong.

    Its message names every failing device with its reason, one per line.
    """


class PluginError(DaqError, RuntimeError):
    """An installed driver plugin (entry point of ``windrig.drivers``) that cannot be used.

    It does not import, its object is not a ``DriverEntry``, it names another driver, or two
    distributions contribute the same driver name. The message names the distribution and the
    entry point, in one line.
    """


class OperatorError(DaqError, RuntimeError):
    """An operator's answer a step waits for cannot come (a prompt's input ended)."""
