"""Mode shapes from plain CSV tables (one per mode, as a finite-element program exports them).

A mode table is a CSV file (``docs/guides/bridge.md``)::

    # frequency = 0.1046        (Hz, still air; required)
    # damping = 0.003           (ratio; default 0.003, recorded as a default)
    # generalised_mass = 9.1e6  (kg per unit modal coordinate squared; default 1, recorded)
    # name = V1S                (optional label)
    x,h,alpha,p
    0.0,0.0,0.0,0.0
    20.0,0.0785,0.0,0.0
    ...

The ``# key = value`` lines before the header carry the mode's data; the header names ``x`` (m
along the span, first) and any of ``h`` (m, down), ``alpha`` (rad, nose-up), ``p`` (m,
downwind); a component not given is zero. A pitch exported in degrees is named ``alpha_deg`` and
converted: a unit is read from the file, never guessed. Every table of one bridge must have the
same deck nodes ``x``. :func:`bridge_from_mode_tables` adds the deck data (``B``, ``rho``,
``static``, ``name``: a template, the bridge model file without ``nodes_x`` and ``modes``) and
returns the validated :class:`~ident.bridge.model.BridgeModel`, whose ``defaults`` and
``warnings`` name each mode by its table's file.

Not responsible for: the bridge model's validation (:mod:`ident.bridge.model`).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.bridge.model import BridgeModel

__all__ = ["bridge_from_mode_tables", "read_mode_table"]

_META_KEYS = ("frequency", "damping", "generalised_mass", "name")
_COLUMNS = ("x", "h", "alpha", "alpha_deg", "p")


def read_mode_table(path: str | os.PathLike[str]) -> tuple[npt.NDArray[np.float64],
                                                           dict[str, Any]]:
    """Read one mode table; return its nodes ``x`` and the mode's entry of the bridge JSON.

    Raises
    ------
    ValueError
        One line naming the file (and line) and what is wrong: a missing ``frequency``, an
        unknown key or column, a value that is not a number, a row of the wrong
        length, no rows.
    """
    source = os.fspath(path)
    meta: dict[str, Any] = {}
    header: list[str] | None = None
    rows: list[list[float]] = []
    try:
        with open(source, newline="", encoding="utf-8") as handle:
            for number, line in enumerate(handle, start=1):
                text = line.strip()
                if not text:
                    continue
                if text.startswith("#"):
                    if header is None and "=" in text:
                        key, _, value = (part.strip() for part in text[1:].partition("="))
                        meta[_meta_key(source, number, key)] = value
                    continue
                cells = [c.strip() for c in next(csv.reader([text]))]
                if header is None:
                    header = [c.lower() for c in cells]
                    _check_header(source, number, header)
                    continue
                if len(cells) != len(header):
                    raise ValueError(f"{source}, line {number}: {len(cells)} values for "
                                     f"{len(header)} columns")
                rows.append([_float(source, number, c) for c in cells])
    except FileNotFoundError:
        raise ValueError(f"{source}: no such file") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{source}: not a text (UTF-8) CSV file: {exc.reason}") from None
    if header is None or not rows:
        raise ValueError(f"{source}: no table (a header x,h,alpha,p and one row per deck node)")
    if "frequency" not in meta:
        raise ValueError(f"{source}: no '# frequency = ...' line above the header")
    data = np.array(rows)
    columns = dict(zip(header, data.T, strict=True))
    entry: dict[str, Any] = {}
    for key in ("frequency", "damping", "generalised_mass"):
        if key in meta:
            entry[key] = _float(source, None, meta[key], key)
    if "name" in meta:
        entry["name"] = meta["name"]
    for name in ("h", "p"):
        if name in columns:
            entry[name] = columns[name].tolist()
    if "alpha" in columns:
        entry["alpha"] = columns["alpha"].tolist()
    elif "alpha_deg" in columns:
        entry["alpha"] = np.deg2rad(columns["alpha_deg"]).tolist()
    return columns["x"], entry


def _meta_key(source: str, number: int, key: str) -> str:
    if key not in _META_KEYS:
        raise ValueError(f"{source}, line {number}: unknown key {key!r}; allowed: "
                         f"{', '.join(_META_KEYS)}")
    return key


def _check_header(source: str, number: int, header: list[str]) -> None:
    if not header or header[0] != "x":
        raise ValueError(f"{source}, line {number}: the first column must be x (m along the "
                         f"span), got {header[0] if header else 'nothing'!r}")
    unknown = [c for c in header if c not in _COLUMNS]
    if unknown:
        raise ValueError(f"{source}, line {number}: unknown column(s) {unknown}; allowed: "
                         f"{', '.join(_COLUMNS)}")
    repeated = sorted({c for c in header if header.count(c) > 1})
    if repeated or ("alpha" in header and "alpha_deg" in header):
        raise ValueError(f"{source}, line {number}: a column appears twice "
                         f"({repeated or ['alpha', 'alpha_deg']})")
    if len(header) < 2:
        raise ValueError(f"{source}, line {number}: no shape column (h, alpha or p)")


def _float(source: str, number: int | None, text: str, key: str | None = None) -> float:
    try:
        value = float(text)
    except ValueError:
        where = f"{source}, line {number}" if number is not None else f"{source}: {key}"
        raise ValueError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(value):
        where = f"{source}, line {number}" if number is not None else f"{source}: {key}"
        raise ValueError(f"{where}: {text!r} is not finite")
    return value


def bridge_from_mode_tables(template: Mapping[str, Any],
                            paths: Sequence[str | os.PathLike[str]],
                            source: str = "") -> BridgeModel:
    """Build a bridge from a template (``B``, ``rho``, ``name``, ``static``) and mode tables.

    Parameters
    ----------
    template : mapping
        The bridge model file's keys except ``nodes_x`` and ``modes``.
    paths : sequence of path-like
        One mode table per mode, in the order of the modes.
    source : str
        The template's file, named in a default taken for the deck data (``rho``).

    Raises
    ------
    ValueError
        A bad table (:func:`read_mode_table`), tables with different nodes, a template that
        already has modes, or any problem of the bridge (:meth:`BridgeModel.from_dict`).
    """
    if not paths:
        raise ValueError("no mode tables given")
    given = sorted({"nodes_x", "modes"} & set(template))
    if given:
        raise ValueError(f"the template already has {given}: give the mode tables or the "
                         "modes, not both")
    x0: npt.NDArray[np.float64] | None = None
    modes = []
    for path in paths:
        x, entry = read_mode_table(path)
        if x0 is None:
            x0, first = x, os.fspath(path)
        elif x.shape != x0.shape or not np.allclose(x, x0, rtol=0.0,
                                                    atol=1e-9 * max(1.0, np.abs(x0).max())):
            raise ValueError(f"{os.fspath(path)}: its deck nodes x differ from those of {first} "
                             "(every mode table must list the same nodes)")
        modes.append(entry)
    assert x0 is not None
    return BridgeModel.from_dict({**template, "nodes_x": x0.tolist(), "modes": modes},
                                 source=source, mode_sources=[os.fspath(p) for p in paths])
