"""Checks of TOML tables: unknown and missing keys, numbers in their range.

Responsibility: :func:`check_keys` and :func:`number`, the two checks every table of a rig config
runs, the rig's own tables (:mod:`daq.config`) and each driver's settings (the ``from_table``
of every settings class in :mod:`daq.instruments.build`). Each raises a
:class:`~daq.errors.ConfigError` whose message names the table, the key and what is allowed.

Not responsible for: what the tables hold (the rig config and the drivers' settings classes).
It sits below both, so that a driver's settings can be checked without importing the rig
config, which imports the driver registry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from daq.errors import ConfigError

__all__ = ["check_keys", "number"]


def check_keys(table: Mapping[str, Any], where: str, required: set[str],
               optional: set[str] = frozenset()) -> None:  # type: ignore[assignment]
    """Raise ConfigError naming unknown keys and missing required keys of a table."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table, got {type(table).__name__}")
    unknown = sorted(set(table) - required - set(optional))
    missing = sorted(required - set(table))
    if unknown:
        allowed = sorted(required | set(optional))
        raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed keys: {allowed}")
    if missing:
        raise ConfigError(f"{where}: missing required key(s) {missing}")


def number(table: Mapping[str, Any], key: str, where: str, *, lo: float = -math.inf,
           hi: float = math.inf, lo_open: bool = False, default: float | None = None) -> float:
    """Read a finite number in ``[lo, hi]`` (``(lo, hi]`` if ``lo_open``) or raise ConfigError."""
    if key not in table:
        if default is None:
            raise ConfigError(f"{where}: missing required key {key!r}")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where} {key} must be a number, got {value!r}")
    x = float(value)
    ok = math.isfinite(x) and (lo < x if lo_open else lo <= x) and x <= hi
    if not ok:
        left = "(" if lo_open else "["
        raise ConfigError(f"{where} {key} = {x!r} is outside the allowed range {left}{lo}, {hi}]")
    return x
