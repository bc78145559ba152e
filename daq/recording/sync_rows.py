"""The synchronised view of a run file being written: declared, its rows and clock fits checked.

Responsibility: :class:`SyncRows`, the group ``/entry/sync`` of a run file that a
:class:`~daq.recording.recorder.RunRecorder` is writing: the checks of its declaration (unique
tap names, the pressure type) before the group is created in the layout of
:func:`daq.recording.layout.create_sync`, the checks of each block of rows (every column as
long as ``time``, the pressure one column per tap, a 3-DOF rig's ``p`` and ``drag`` exactly
when the view has them) before they are appended, and :func:`clock_attrs`, the clock fits
stored as its attributes.

Not responsible for: computing the rows (:mod:`daq.recording.sync_view`, from the resampled
streams), the file's life cycle and SWMR (:mod:`daq.recording.swmr_file`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from daq.recording.layout import VALUE_DTYPES, append_rows, column_of, create_sync, per_device_attr

__all__ = ["SyncRows", "clock_attrs"]


class SyncRows:
    """Open columns and row count of ``/entry/sync``.

    Parameters
    ----------
    group : h5py.Group
        ``/entry/sync``.
    datasets : dict of str to h5py.Dataset
        Its columns, by name (:func:`daq.recording.layout.create_sync`'s).
    n_taps : int
        Columns of ``pressure``.
    sway : bool
        A 3-DOF rig's view: it has the ``p`` and ``drag`` columns.
    """

    def __init__(self, group: h5py.Group, datasets: dict[str, h5py.Dataset], n_taps: int,
                 sway: bool) -> None:
        self.group = group
        self.datasets = datasets
        self.n_taps = n_taps
        self.sway = sway
        self.rows = 0

    @classmethod
    def declare(cls, entry: h5py.Group, tap_names: Sequence[str],
                pressure_dtype: str | np.dtype[Any], *, make_column: Callable[..., h5py.Dataset],
                sway: bool) -> SyncRows:
        """Check the view's declaration and create ``/entry/sync`` in ``entry``.

        The arguments are :meth:`daq.recording.recorder.RunRecorder.add_sync`'s;
        ``make_column`` creates a dataset as :func:`daq.recording.layout.create_column` does.
        """
        taps = list(tap_names)
        if not all(isinstance(t, str) for t in taps) or len(set(taps)) != len(taps):
            raise ValueError(f"tap_names must be unique str, got {taps!r}")
        p_dtype = np.dtype(pressure_dtype)
        if p_dtype not in VALUE_DTYPES:
            raise ValueError(f"pressure_dtype = {pressure_dtype!r}; allowed: float32, float64")
        sync, ds = create_sync(entry, taps, p_dtype, make_column=make_column, sway=sway)
        return cls(sync, ds, len(taps), sway)

    def check_block(self, time: npt.ArrayLike, *, h: npt.ArrayLike, alpha: npt.ArrayLike,
             lift: npt.ArrayLike, moment: npt.ArrayLike, pressure: npt.ArrayLike,
             U: npt.ArrayLike, rho: npt.ArrayLike, p: npt.ArrayLike | None,
             drag: npt.ArrayLike | None) -> dict[str, npt.NDArray[Any]] | None:
        """Check a block of rows; return its columns by name, or None if it has no rows.

        The arguments are :meth:`daq.recording.recorder.RunRecorder.append_sync`'s. The columns
        come in the order :meth:`append` writes them: ``pressure`` first, ``time`` last.
        """
        if (p is not None or drag is not None) != self.sway or (p is None) != (drag is None):
            raise ValueError("p and drag go together, and exactly into a 3-DOF run (sway="
                             f"{self.sway}); got p {'given' if p is not None else 'None'}, "
                             f"drag {'given' if drag is not None else 'None'}")
        t = column_of(time, None, np.float64, "sync time")
        n = t.shape[0]
        cols = {"h": h, "alpha": alpha, "lift": lift, "moment": moment, "U": U, "rho": rho}
        if p is not None and drag is not None:  # a sway view's (checked above)
            cols.update(p=p, drag=drag)
        arrays = {name: column_of(v, n, np.float64, f"sync {name}") for name, v in cols.items()}
        taps = np.asarray(pressure, dtype=self.datasets["pressure"].dtype)
        if taps.shape != (n, self.n_taps):
            raise ValueError(f"sync pressure has shape {taps.shape}, expected ({n}, "
                             f"{self.n_taps}) (rows, taps)")
        if n == 0:
            return None
        return {"pressure": taps, **arrays, "time": t}

    def append(self, rows: Mapping[str, npt.NDArray[Any]]) -> None:
        """Append the columns :meth:`check_block` returned, in their order."""
        start = self.rows
        for name, array in rows.items():
            append_rows(self.datasets[name], start, array)
        self.rows = start + rows["time"].shape[0]


def clock_attrs(streams: Collection[str], *, clock_offset_s: Mapping[str, float] | None,
                clock_drift_ppm: Mapping[str, float] | None,
                residual_misalignment_s: float | None) -> dict[str, float]:
    """Check the clock fits of a run; return them as attributes of ``/entry/sync``.

    The arguments are :meth:`daq.recording.recorder.RunRecorder.set_sync_attrs`'s; ``streams``
    are the devices declared (the only ones a fit may name).
    """
    attrs: dict[str, float] = {}
    for label, mapping in (("clock_offset_s", clock_offset_s),
                           ("clock_drift_ppm", clock_drift_ppm)):
        for device, value in (mapping or {}).items():
            if device not in streams:
                raise ValueError(f"{label}: no stream {device!r} declared; have "
                                 f"{sorted(streams)}")
            attrs[per_device_attr(label, device)] = _finite(value, f"{label} of {device}")
    if residual_misalignment_s is not None:
        attrs["residual_misalignment_s"] = _finite(residual_misalignment_s,
                                                 "residual_misalignment_s")
    return attrs


def _finite(value: Any, what: str) -> float:
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{what} = {value!r} must be finite")
    return x
