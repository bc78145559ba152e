"""Registry of instrument drivers, keyed by the ``driver`` name used in rig configs.

Every driver, built in or from another distribution, is found the same way: as an entry point
of the group :data:`GROUP` (``windrig.drivers``) whose name is the driver's name and whose
object is its :class:`~daq.instruments.entry.DriverEntry`. windrig's own seven drivers are
entry points of the ``windrig`` distribution (``pyproject.toml``), so this module imports no
driver package: a driver is imported lazily, by name, when a rig config asks for it, and a
driver that is never named is never imported. :func:`register` adds an entry built in code
(a test's driver); it takes precedence over nothing: a name both registered and installed is
refused.

A broken plugin is one :class:`~daq.errors.PluginError` line naming its distribution and entry
point: an import that fails, an object that is not a ``DriverEntry``, an entry that names
another driver or a role windrig does not have, two distributions giving the same name, and a
driver's own code (its ``validate``, ``link`` or ``factory``, :func:`call_driver_code`) raising
anything but windrig's own exceptions.

The rig config asks the registry to validate an instrument table (:func:`validate_settings`),
:func:`daq.instruments.build.build_driver` asks it for the factory, and ``windrig drivers``
lists every driver (:func:`available_drivers`).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from daq.errors import ConfigError, DaqError, PluginError
from daq.instruments.entry import ROLES, DriverEntry

__all__ = ["GROUP", "DriverInfo", "available_drivers", "call_driver_code", "driver_entry",
           "driver_origin", "register", "scanner_layout", "unregister", "validate_settings"]

#: The entry-point group through which distributions contribute drivers.
GROUP = "windrig.drivers"

#: Entries built in code (:func:`register`).
_REGISTERED: dict[str, DriverEntry] = {}
#: Entries loaded from entry points, by name (each loaded once per process).
_LOADED: dict[str, DriverEntry] = {}
#: Where each loaded entry comes from (distribution and entry point), for messages.
_ORIGINS: dict[str, str] = {}
_LOCK = threading.RLock()  # the device check builds drivers on several threads at once


@dataclass(frozen=True)
class DriverInfo:
    """One driver as ``windrig drivers`` lists it.

    Attributes
    ----------
    name : str
        The ``driver`` value in rig configs.
    role : str
        The role it fills ("" when it could not be loaded).
    distribution : str
        The distribution that contributes it, ``name version`` (``"(registered in code)"`` for
        :func:`register`).
    entry_point : str
        ``module:attribute`` of its entry (``""`` for one registered in code).
    error : str
        Why it cannot be used ("" when it can).
    """

    name: str
    role: str
    distribution: str
    entry_point: str
    error: str = ""

    def to_dict(self) -> dict[str, str]:
        """Return the fields as JSON-ready values."""
        return {"name": self.name, "role": self.role, "distribution": self.distribution,
                "entry_point": self.entry_point, "error": self.error}


def register(entry: DriverEntry) -> None:
    """Register a driver built in code (a test's); installed drivers need no registration.

    Raises
    ------
    RuntimeError
        The name is registered already with another entry, or an installed distribution
        contributes a driver of that name.
    """
    _check_entry(entry, f"driver {entry.name!r} registered in code")
    with _LOCK:
        if entry.name in _REGISTERED and _REGISTERED[entry.name] != entry:
            raise RuntimeError(f"driver {entry.name!r} registered twice")
        installed = _installed(entry.name)
        if installed:
            raise RuntimeError(f"driver {entry.name!r} is installed already "
                               f"({_where(installed[0])}): choose another name")
        _REGISTERED[entry.name] = entry


def unregister(name: str) -> None:
    """Remove a driver registered in code (no error if there is none)."""
    with _LOCK:
        _REGISTERED.pop(name, None)


def driver_entry(name: str) -> DriverEntry:
    """Return the driver called ``name``, loading its plugin on first use.

    Raises
    ------
    ConfigError
        No driver of that name (the message lists the known ones).
    PluginError
        The driver's distribution is broken (one line naming it and the entry point).
    """
    with _LOCK:
        if name in _REGISTERED:
            return _REGISTERED[name]
        if name in _LOADED:
            return _LOADED[name]
        found = _installed(name)
        if not found:
            known = sorted({ep.name for ep in _all_installed()} | set(_REGISTERED))
            raise ConfigError(f"unknown driver {name!r}; known drivers: {known} (an installed "
                              f"distribution adds drivers through the entry-point group "
                              f"{GROUP!r}: windrig drivers lists them)")
        _LOADED[name] = _load(found)
        _ORIGINS[name] = _where(found[0])
        return _LOADED[name]


def driver_origin(name: str) -> str:
    """Say where the loaded driver ``name`` comes from: its distribution and entry point.

    ``"registered in code"`` for :func:`register`; ``"not loaded"`` for a name not loaded yet.
    """
    with _LOCK:
        if name in _REGISTERED:
            return "registered in code"
        return _ORIGINS.get(name, "not loaded")


def call_driver_code(entry: DriverEntry, what: str, func: Any, *args: Any, **kwargs: Any) -> Any:
    """Call a driver's own code (``validate``, ``link``, ``factory``, ``describe``) for windrig.

    A driver raises windrig's exceptions (:mod:`daq.errors`: a ``ConfigError`` for a bad table);
    those pass unchanged. Anything else (a plugin's ``KeyError``, ``AttributeError``) is a bug
    of that driver, and without this it would reach the user as a traceback from the rig
    config's loading, or as a bare message naming neither the driver nor its plugin. It becomes
    one :class:`~daq.errors.PluginError` line naming the driver, its distribution, the call and
    the exception (chained: ``windrig --debug`` shows the driver's traceback).

    Parameters
    ----------
    entry : DriverEntry
        The driver whose code is called.
    what : str
        The call and what it was for, for the message (``"validate of rig.toml [barometer]"``).
    func : callable
        The driver's code; called with ``args`` and ``kwargs``.
    """
    try:
        return func(*args, **kwargs)
    except DaqError:
        raise
    except Exception as exc:
        text = " ".join(str(exc).split())
        raise PluginError(
            f"driver {entry.name!r} ({driver_origin(entry.name)}): its {what} raised "
            f"{type(exc).__name__}{': ' + text if text else ''} (a driver raises the exceptions "
            "of daq.errors, a ConfigError for a bad setting: this is a bug of the driver)",
        ) from exc


def validate_settings(driver: str, role: str, settings: Mapping[str, Any], where: str) -> Any:
    """Validate an instrument table's driver-specific settings; return the settings object."""
    try:
        entry = driver_entry(driver)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from exc
    if entry.role != role:
        raise ConfigError(f"{where}: driver {driver!r} is a {entry.role} driver, not a {role}")
    return call_driver_code(entry, f"validate of {where}", entry.validate, settings, where)


class _NoLink:
    """Stands for a transport where a driver is built only to ``describe()`` itself."""

    def __getattr__(self, name: str) -> Any:
        raise RuntimeError(f"a driver's constructor and describe() do no I/O, but .{name} of "
                           "its transport was used")


def scanner_layout(driver: str, settings: Mapping[str, Any], where: str) -> tuple[int, int]:
    """Return a configured scanner's (channels per module, modules), from its ``describe()``.

    A scanner driver says how wide it is (``pressure`` has the channels of every module,
    ``module_status`` one row per module, docs/guides/drivers.md); the rig config's tap wiring asks
    it here rather than assume any count. The driver is built on a link that refuses any use
    (construction and ``describe()`` do no I/O) and thrown away.
    """
    entry = driver_entry(driver)
    validated = call_driver_code(entry, f"validate of {where}", entry.validate, settings, where)
    built = call_driver_code(entry, f"factory (built without I/O for {where})", entry.factory,
                             _NoLink(), validated)
    described = call_driver_code(entry, f"describe() (for {where})", built.describe)
    try:
        channels = int(tuple(described["pressure"]["shape"])[0])
        modules = int(tuple(described["module_status"]["shape"])[0])
    except (KeyError, IndexError, TypeError) as exc:
        raise ConfigError(f"{where}: scanner driver {driver!r} does not describe 'pressure' "
                          "and 'module_status' as vectors (docs/guides/drivers.md)") from exc
    if modules < 1 or channels % modules:
        raise ConfigError(f"{where}: scanner driver {driver!r} describes {channels} pressure "
                          f"channels for {modules} module(s)")
    return channels // modules, modules


def available_drivers() -> list[DriverInfo]:
    """List every driver: installed (loaded, to learn its role) and registered in code.

    A plugin that cannot be loaded is listed with its error rather than raised: the list is
    where a user looks for what is broken.
    """
    by_name: dict[str, list[EntryPoint]] = {}
    for ep in _all_installed():
        by_name.setdefault(ep.name, []).append(ep)
    out: list[DriverInfo] = []
    for name, eps in sorted(by_name.items()):
        try:
            entry = driver_entry(name)
            error = ""
        except PluginError as exc:
            entry, error = None, str(exc)
        out.append(DriverInfo(name=name, role=entry.role if entry else "",
                              distribution=", ".join(_distribution(ep) for ep in eps),
                              entry_point=", ".join(ep.value for ep in eps), error=error))
    with _LOCK:
        registered = sorted(_REGISTERED.items())
    out += [DriverInfo(name=name, role=entry.role, distribution="(registered in code)",
                       entry_point="") for name, entry in registered]
    return sorted(out, key=lambda info: info.name)


# -- entry points --------------------------------------------------------------------------------
def _all_installed() -> list[EntryPoint]:
    # Read afresh each time: a distribution installed while the process runs (a test's) is seen,
    # and the scan of installed metadata is a few ms, paid once per driver name loaded.
    return list(entry_points(group=GROUP))


def _installed(name: str) -> list[EntryPoint]:
    return [ep for ep in _all_installed() if ep.name == name]


def _distribution(ep: EntryPoint) -> str:
    dist = ep.dist
    return "(unknown distribution)" if dist is None else f"{dist.name} {dist.version}"


def _where(ep: EntryPoint) -> str:
    return f"distribution {_distribution(ep)}, entry point {ep.name} = {ep.value}"


def _load(found: list[EntryPoint]) -> DriverEntry:
    """Load the one entry point of a driver name; every way it can be broken is a PluginError."""
    if len(found) > 1:
        raise PluginError(f"driver {found[0].name!r} is contributed by more than one "
                          f"distribution ({'; '.join(_where(ep) for ep in found)}): uninstall "
                          "one of them")
    ep = found[0]
    try:
        obj = ep.load()
    except Exception as exc:  # any import failure of a plugin is its own, reported in one line
        text = " ".join(str(exc).split())
        raise PluginError(f"driver plugin {ep.name!r} cannot be imported ({_where(ep)}): "
                          f"{type(exc).__name__}: {text}") from exc
    if not isinstance(obj, DriverEntry):
        raise PluginError(f"driver plugin {ep.name!r} is a {type(obj).__name__}, not a "
                          f"daq.instruments.entry.DriverEntry ({_where(ep)})")
    if obj.name != ep.name:
        raise PluginError(f"driver plugin {ep.name!r} holds the entry of driver {obj.name!r} "
                          f"({_where(ep)}): the entry point's name must be the driver's")
    try:
        _check_entry(obj, f"driver plugin {ep.name!r}")
    except RuntimeError as exc:
        raise PluginError(f"{exc} ({_where(ep)})") from exc
    return obj


def _check_entry(entry: DriverEntry, what: str) -> None:
    if entry.role not in ROLES:
        raise RuntimeError(f"{what} fills role {entry.role!r}; windrig's roles are {list(ROLES)}")
    if not (callable(entry.factory) and callable(entry.validate)):
        raise RuntimeError(f"{what}: its factory and validate must be callables")
