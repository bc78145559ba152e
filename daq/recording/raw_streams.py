"""One device's raw stream in a run file being written: declared, then its rows appended.

Responsibility: :class:`RawStream`, the group ``/entry/instrument/<device>`` of a run file that a
:class:`~daq.recording.recorder.RunRecorder` is writing: the checks of its declaration (channel
names, units, rate, value type, extra columns) before the group is created in the layout of
:func:`daq.recording.layout.create_stream`, the checks of each block of samples and of each gap
before they are appended, and the open datasets and row counts in between.

Not responsible for: the file's life cycle, SWMR and the translation of HDF5 failures
(:mod:`daq.recording.swmr_file`; the recorder wraps every append in it), nor for which device
streams what (:mod:`daq.recording.devices`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from daq.recording.layout import (
    EXTRA_DTYPES,
    GAP_DTYPE,
    VALUE_DTYPES,
    append_rows,
    check_name,
    column_of,
    create_stream,
    integer_column,
)

__all__ = ["RawStream"]


class RawStream:
    """Open datasets and row count of one device's raw stream.

    Parameters
    ----------
    device : str
        The device's name (the group's).
    datasets : dict of str to h5py.Dataset
        Its datasets, by name (:func:`daq.recording.layout.create_stream`'s).
    n_channels : int
        Columns of ``value``.
    dtype : numpy.dtype
        Storage type of ``value``.
    extra : dict of str to numpy.dtype
        The extra per-sample columns declared, and their types.
    """

    def __init__(self, device: str, datasets: dict[str, h5py.Dataset], n_channels: int,
                 dtype: np.dtype[Any], extra: dict[str, np.dtype[Any]]) -> None:
        # Held open on purpose: closing a dataset flushes and drops its chunk cache, so opening
        # it again per block (group["value"]) re-reads and re-compresses its partial chunk each
        # time and leaves the old copy as dead space (measured: a 3x larger file, 5x slower).
        self.device = device
        self.datasets = datasets
        self.n_channels = n_channels
        self.dtype = dtype
        self.extra = extra
        self.rows = 0
        self.gaps = 0

    @classmethod
    def declare(cls, instrument: h5py.Group, device: str, channels: Sequence[str],
                units: str | Sequence[str], rate_hz: float, value_dtype: str | np.dtype[Any],
                extra: Mapping[str, str | np.dtype[Any]] | None, *,
                make_column: Callable[..., h5py.Dataset]) -> RawStream:
        """Check a stream's declaration and create its group in ``instrument``.

        The arguments are :meth:`daq.recording.recorder.RunRecorder.add_stream`'s (the device's
        name already checked); ``make_column`` creates a dataset as
        :func:`daq.recording.layout.create_column` does.
        """
        channels = list(channels)
        if not channels or not all(isinstance(c, str) and c for c in channels):
            raise ValueError(f"{device}: channels must be a non-empty list of names, "
                             f"got {channels!r}")
        if len(set(channels)) != len(channels):
            raise ValueError(f"{device}: channel names repeat: {channels!r}")
        unit_list = [units] * len(channels) if isinstance(units, str) else list(units)
        if len(unit_list) != len(channels) or not all(isinstance(u, str) for u in unit_list):
            raise ValueError(f"{device}: units must be one str or one per channel "
                             f"({len(channels)}), got {units!r}")
        if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float)) \
                or not 0 < rate_hz < math.inf:
            raise ValueError(f"{device}: rate_hz = {rate_hz!r} must be a number > 0 Hz")
        dtype = np.dtype(value_dtype)
        if dtype not in VALUE_DTYPES:
            raise ValueError(f"{device}: value_dtype = {value_dtype!r}; allowed: float32, float64")
        extra_types: dict[str, np.dtype[Any]] = {}
        for name, kind in (extra or {}).items():
            check_name(name, f"{device}: extra column")
            if name in ("host_time_ns", "device_time", "counter", "value", "gaps"):
                raise ValueError(f"{device}: extra column {name!r} clashes with a standard one")
            extra_types[name] = np.dtype(kind)
            if extra_types[name] not in EXTRA_DTYPES:
                raise ValueError(f"{device}: extra column {name!r} has dtype {kind!r}; allowed: "
                                 f"{[str(t) for t in EXTRA_DTYPES]}")
        ds = create_stream(instrument, device, channels, unit_list, rate_hz, dtype, extra_types,
                           make_column=make_column)
        return cls(device, ds, len(channels), dtype, extra_types)

    def check_block(self, host_time_ns: npt.ArrayLike, device_time: npt.ArrayLike | None,
             counter: npt.ArrayLike, values: npt.ArrayLike,
             extra: Mapping[str, npt.ArrayLike] | None) -> dict[str, npt.NDArray[Any]] | None:
        """Check a block of samples; return its columns by dataset, or None if it has no rows.

        The arguments are :meth:`daq.recording.recorder.RunRecorder.append_raw`'s. The columns
        come in the order :meth:`append` writes them: ``value`` and the extra columns first, the
        time stamps and counters last.
        """
        device = self.device
        t_host = integer_column(host_time_ns, f"{device} host_time_ns")
        n = t_host.shape[0]
        t_dev = (np.full(n, np.nan) if device_time is None
                 else column_of(device_time, n, np.float64, f"{device} device_time"))
        count = integer_column(counter, f"{device} counter")
        if count.shape != (n,):
            raise ValueError(f"{device}: counter has {count.shape[0]} rows, host_time_ns {n}")
        block = np.asarray(values, dtype=self.dtype)
        if block.ndim == 1 and self.n_channels == 1:
            block = block[:, None]
        if block.shape != (n, self.n_channels):
            raise ValueError(f"{device}: values have shape {block.shape}, expected "
                             f"({n}, {self.n_channels}) (rows, channels)")
        given = dict(extra or {})
        if set(given) != set(self.extra):
            raise ValueError(f"{device}: extra columns {sorted(given)} differ from the declared "
                             f"{sorted(self.extra)}")
        columns = {name: column_of(given[name], n, kind, f"{device} {name}")
                   for name, kind in self.extra.items()}
        if n == 0:
            return None
        return {"value": block, **columns, "device_time": t_dev, "host_time_ns": t_host,
                "counter": count}

    def append(self, rows: Mapping[str, npt.NDArray[Any]]) -> None:
        """Append the columns :meth:`check_block` returned, in their order."""
        start = self.rows
        for name, array in rows.items():
            append_rows(self.datasets[name], start, array)
        self.rows = start + rows["counter"].shape[0]

    def check_gap(self, after_counter: int, length: int) -> npt.NDArray[Any]:
        """Check a gap (:meth:`~daq.recording.recorder.RunRecorder.add_gap`); return its row."""
        if not (length == -1 or length >= 1):
            raise ValueError(f"{self.device}: gap length = {length!r} must be >= 1, or -1 "
                             "(unknown)")
        return np.array([(int(after_counter), int(length))], dtype=GAP_DTYPE)

    def append_gap(self, row: npt.NDArray[Any]) -> None:
        """Append a row of :meth:`check_gap` to the ``gaps`` table."""
        append_rows(self.datasets["gaps"], self.gaps, row)
        self.gaps += 1
