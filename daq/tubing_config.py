"""The rig config's pneumatic tubing: ``[[taps.tubing]]`` tables, one per group of taps.

Each table gives a group of taps (``taps = "all"`` or a list of 0-based tap indices in the
layout's order; default ``"all"``) and the tubing between them and the scanner, either as a
tube (Bergh and Tijdeman's model, :class:`ident.physics.tubing.Tube`)::

    [[taps.tubing]]
    taps = "all"
    length = 1.0        # m
    diameter = 1.0e-3   # m, inner
    volume = 300e-9     # m^3, the transducer's internal volume
    sigma = 0.0         # optional: relative volume increase by diaphragm deflection
    k = 1.4             # optional: the volume's polytropic constant (default adiabatic)

or as a measured response, ``table = "file.csv"`` (columns ``frequency,gain,phase_deg``: Hz,
ratio, degrees; a relative path is taken from the config file's folder). A tap may be in one
group only; taps in none have no tubing. Every error is a
:class:`~daq.errors.ConfigError` naming the table and key (``[[taps.tubing]] #0 length``).

The groups are recorded in each run file (``/entry/metadata/tubing``, :func:`tubing_metadata`)
so that an offline reader corrects the pressures the same way without the CSV files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from daq.errors import ConfigError
from daq.validation import check_keys, number
from ident.physics.tubing import TableResponse, Tube, TubingGroup, tubing_set

__all__ = ["parse_tubing", "split_tubing", "tubing_metadata"]

_TUBE_KEYS = {"length", "diameter", "volume"}


def split_tubing(taps_table: Any, source: str) -> tuple[Any, list[Mapping[str, Any]]]:
    """Return the ``[taps]`` table without its ``tubing`` array, and that array (or ``[]``)."""
    if not isinstance(taps_table, Mapping) or "tubing" not in taps_table:
        return taps_table, []
    tubing = taps_table["tubing"]
    if not isinstance(tubing, list) or not all(isinstance(t, Mapping) for t in tubing):
        raise ConfigError(f"{source} [taps] tubing must be an array of tables ([[taps.tubing]])")
    rest = {key: value for key, value in taps_table.items() if key != "tubing"}
    return rest, list(tubing)


def parse_tubing(tables: Sequence[Mapping[str, Any]], n_taps: int, source: str,
                 base: Path | None = None) -> tuple[TubingGroup, ...]:
    """Validate the ``[[taps.tubing]]`` tables into tubing groups.

    Parameters
    ----------
    tables : sequence of mapping
        The tables, in order.
    n_taps : int
        Taps of the layout (indices must lie in ``0 .. n_taps - 1``).
    source : str
        The config's name, for messages.
    base : Path, optional
        Folder a relative ``table`` path is taken from (the config file's).

    Raises
    ------
    ConfigError
        Naming the table (``[[taps.tubing]] #i``) and the key.
    """
    groups: list[TubingGroup] = []
    owner: dict[int, int] = {}
    for index, table in enumerate(tables):
        where = f"{source} [[taps.tubing]] #{index}"
        if "table" in table:
            check_keys(table, where, {"table"}, {"taps"})
        else:
            check_keys(table, where, _TUBE_KEYS, {"taps", "sigma", "k"})
        taps = _taps(table.get("taps", "all"), n_taps, where)
        for tap in range(n_taps) if taps is None else taps:
            if tap in owner:
                raise ConfigError(f"{where} taps: tap {tap} is already in [[taps.tubing]] "
                                  f"#{owner[tap]}; a tap has one tube")
            owner[tap] = index
        model: Tube | TableResponse
        if "table" in table:
            model = _table(table["table"], where, base)
        else:
            k = number(table, "k", where, lo=1.0, hi=1.67) if "k" in table else None
            model = Tube(
                length=number(table, "length", where, lo=0.0, hi=50.0, lo_open=True),
                diameter=number(table, "diameter", where, lo=0.0, hi=0.05, lo_open=True),
                volume=number(table, "volume", where, lo=0.0, hi=1e-3),
                sigma=number(table, "sigma", where, lo=0.0, hi=100.0, default=0.0),
                k=k,
            )
        groups.append(TubingGroup(taps=taps, model=model))
    return tuple(groups)


def tubing_metadata(groups: Sequence[TubingGroup], n_taps: int) -> dict[str, Any]:
    """Return the groups as run-file metadata: ``{"group_0": {...}, ...}``."""
    described = tubing_set(groups, n_taps).describe()
    return {f"group_{i}": dict(item) for i, item in enumerate(described)}


def _taps(value: Any, n_taps: int, where: str) -> tuple[int, ...] | None:
    if value == "all":
        return None
    if not isinstance(value, list) or not value or not all(
            isinstance(t, int) and not isinstance(t, bool) for t in value):
        raise ConfigError(f"{where} taps must be \"all\" or a non-empty list of tap indices, "
                          f"got {value!r}")
    bad = [t for t in value if not 0 <= t < n_taps]
    if bad:
        raise ConfigError(f"{where} taps: {bad} outside the layout's taps 0..{n_taps - 1}")
    if len(set(value)) != len(value):
        raise ConfigError(f"{where} taps: a tap is listed twice in {value!r}")
    return tuple(value)


def _table(value: Any, where: str, base: Path | None) -> TableResponse:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{where} table must be the path of a CSV file, got {value!r}")
    path = Path(value)
    if not path.is_absolute() and base is not None:
        path = base / path
    try:
        return TableResponse.from_csv(path)
    except OSError as exc:
        raise ConfigError(f"{where} table: cannot read {path}: {exc.strerror or exc}") from exc
    except ValueError as exc:
        raise ConfigError(f"{where} table: {exc}") from exc
