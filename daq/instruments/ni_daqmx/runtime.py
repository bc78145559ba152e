"""The nidaqmx API the driver talks to: the real package, imported lazily, or a stand-in.

Responsibility: :func:`load_api` returns the parts of the ``nidaqmx`` package the driver uses
as one :class:`NiApi` (``Task``, ``constants``, ``errors``, ``stream_readers``, ``system``), after
checking that the NI-DAQmx runtime behind it is there: the package is imported only when a rig
config names an NI-DAQmx instrument (``windrig[nidaqmx]`` is an optional extra), and a missing
package, or a package whose C library is missing, is one
:class:`~daq.errors.DriverUnavailableError` line that says what to install. A URL with
``standin=127.0.0.1:PORT`` gets the stand-in registered with :func:`register_standin` (the
simulated rig registers the one in :mod:`simulators.nidaqmx_standin`; daq does not import
simulators).

Not responsible for: tasks and reading (:mod:`daq.instruments.ni_daqmx.task_group`).
"""

from __future__ import annotations

import importlib
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from daq.errors import ConfigError, DriverUnavailableError
from daq.instruments.ni_daqmx.address import TaskAddress

__all__ = ["INSTALL_PACKAGE", "INSTALL_RUNTIME", "NiApi", "load_api", "register_standin"]

#: What to do without the Python package.
INSTALL_PACKAGE: Final = ("NI-DAQmx: the Python package 'nidaqmx' is not installed; install it "
                          "with: pip install 'windrig[nidaqmx]'")
#: What to do without the C library (the package is there).
INSTALL_RUNTIME: Final = ("NI-DAQmx: the 'nidaqmx' package is installed but the NI-DAQmx "
                          "runtime (its C library) is not; install the NI-DAQmx driver from NI "
                          "(on Linux: python -m nidaqmx installdriver)")

_MODULES: Final = ("constants", "errors", "stream_readers", "system")


@dataclass(frozen=True)
class NiApi:
    """The parts of the nidaqmx API the driver uses (the package's names, one object).

    Attributes
    ----------
    name : str
        ``"nidaqmx"`` or the stand-in's name (in messages and the device's identity).
    Task : type
        ``nidaqmx.Task``.
    constants, errors, stream_readers, system : module-like
        ``nidaqmx.constants`` (AcquisitionType, OverwriteMode, ReadRelativeTo,
        TerminalConfiguration, Edge, LineGrouping), ``nidaqmx.errors`` (DaqError with
        ``error_code``), ``nidaqmx.stream_readers`` (AnalogMultiChannelReader) and
        ``nidaqmx.system`` (``System.local().driver_version``).
    driver_version : str
        The NI-DAQmx runtime's version, ``major.minor.update``.
    """

    name: str
    Task: Any
    constants: Any
    errors: Any
    stream_readers: Any
    system: Any
    driver_version: str


_lock = threading.Lock()
_standin: Callable[[str, int], Any] | None = None


def register_standin(factory: Callable[[str, int], Any]) -> None:
    """Register the stand-in API: ``factory(host, port)`` returns a module-like object.

    The object has the attributes of :class:`NiApi` but ``driver_version``: ``Task``,
    ``constants``, ``errors``, ``stream_readers``, ``system`` and a ``name``.
    """
    global _standin
    with _lock:
        _standin = factory


def _import_nidaqmx() -> Any:
    """Import the real package and the submodules the driver uses (lazily: an optional extra)."""
    try:
        package = importlib.import_module("nidaqmx")
        parts = {name: importlib.import_module(f"nidaqmx.{name}") for name in _MODULES}
    except ImportError as exc:
        if exc.name is not None and exc.name.split(".")[0] == "nidaqmx":
            raise DriverUnavailableError(INSTALL_PACKAGE) from exc
        raise  # the package is there but something it imports is not: its own message says what
    return type("nidaqmx_api", (), {"name": "nidaqmx", "Task": package.Task, **parts})


def load_api(address: TaskAddress) -> NiApi:
    """Return the API of ``address`` (real or stand-in), its runtime checked.

    Raises
    ------
    DriverUnavailableError
        The ``nidaqmx`` package is not installed, or its NI-DAQmx C library is not (one line
        saying what to install).
    ConfigError
        A stand-in URL but no stand-in registered (a simulated rig's URL used outside it).
    """
    if address.standin is not None:
        with _lock:
            factory = _standin
        if factory is None:
            raise ConfigError(f"url {address.url!r} names a simulated NI device (standin=) but "
                              "no simulated rig is running in this process")
        module = factory(*address.standin)
    else:
        module = _import_nidaqmx()
    errors = module.errors
    # DaqNotFoundError: the package could not load its C library (no NI-DAQmx installed);
    # DaqNotSupportedError: NI-DAQmx does not exist for this platform. Both from
    # nidaqmx.errors (nidaqmx >= 0.8); older versions raise them from nidaqmx._lib, as
    # subclasses of nidaqmx.errors.Error, which is why that base is the fallback.
    missing = tuple(getattr(errors, name) for name in ("DaqNotFoundError", "DaqNotSupportedError")
                    if hasattr(errors, name)) or (errors.Error,)
    try:
        version = module.system.System.local().driver_version
    except missing as exc:
        if isinstance(exc, errors.DaqError):
            raise  # a DAQmx error of a present runtime: not a missing one
        raise DriverUnavailableError(f"{INSTALL_RUNTIME} ({_first_line(exc)})") from exc
    text = ".".join(str(getattr(version, f"{part}_version", "?"))
                    for part in ("major", "minor", "update"))
    return NiApi(name=str(module.name), Task=module.Task, constants=module.constants,
                 errors=errors, stream_readers=module.stream_readers, system=module.system,
                 driver_version=text)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
