"""How well a recorded run's synchronised view lines up with the simulator's truth.

Responsibility: :class:`ClockTruthTracker` compares the host times the recorder gave every
block of the sync view with the simulators' true clocks (per device, and the spread between
devices at one instant); :func:`measure_alignment` compares ``/entry/sync`` of a run recorded from a
simulated rig with the virtual tunnel's own record of every free decay
(:meth:`~simulators.virtual_tunnel.VirtualTunnel.decay_truth`) and estimates, per channel, the
time by which the recorded signal lags the truth. h and alpha come from the lasers, lift and
moment from the scanner, so their delays measure each device's clock mapping end to end (clock
offset and drift, transport latency, resampling), and their spread is the misalignment between
the devices that E2RFC would see as a phase error between motion and force.
:func:`write_alignment` stores both as attributes of ``/entry/sync``; :func:`check_run` does all
of it for one run file.

Estimator: on the rows of every release (the free decays, where the signals move), the recorded
channel ``y`` is regressed on the truth ``x(t)``, its time derivative ``x'(t)`` and a constant:
``y = g x - g tau x' + c`` to first order in the delay ``tau``, which is ``-b / g`` of the fit.
The first order is ample: at 4 Hz, 1 ms of delay is a 2.5 % phase, its second-order term
``(w tau)^2 / 2`` 3e-4. The standard error of ``tau`` follows from the fit's residual: for h
and alpha (lasers) a few microseconds over seconds of decay; for lift and moment, integrated
from 62 taps with 1 Pa noise each, ~0.25 ms at half the flutter speed.

Not responsible for: recording (:mod:`daq.recording.writer`), the truth (:mod:`simulators`). Real
rigs have no truth: this runs only for simulated ones.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from daq.recording.layout import per_device_attr

__all__ = ["ClockTruthTracker", "check_run", "measure_alignment", "release_rows",
           "write_alignment"]

FloatArray = npt.NDArray[np.float64]

#: Which device each sync channel comes from.
CHANNEL_SOURCES = {"h": "lasers", "alpha": "lasers", "lift": "scanner", "moment": "scanner"}
#: The channels a 3-DOF rig's file adds (checked when the file has them).
SWAY_SOURCES = {"p": "lasers", "drag": "scanner"}
#: Rows skipped after each release, s: the first instants depend on the release mechanism.
SKIP_AFTER_RELEASE_S = 0.05
#: Step of the central difference that gives the truth's derivative, s.
_DERIVATIVE_STEP_S = 1e-4


def check_run(path: str | Path, tracker: ClockTruthTracker, *,
              true_time_of: Callable[[str, FloatArray], FloatArray],
              decay_truth: Callable[[FloatArray], Mapping[str, FloatArray]],
              origin_s: float) -> dict[str, Any]:
    """Check a closed run file against a simulated rig's truth and store the result in it.

    Parameters
    ----------
    path : str or Path
        The run file (closed).
    tracker : ClockTruthTracker
        The tracker the run's writer fed.
    true_time_of : callable
        ``(device name, device times) -> true host times`` (``time.monotonic`` s).
    decay_truth : callable
        True times (tunnel clock, s) -> the tunnel's decays.
    origin_s : float
        The tunnel's true time 0 on the ``time.monotonic`` clock, s.

    Returns
    -------
    dict
        ``clocks`` (:meth:`ClockTruthTracker.result`) and ``signals``
        (:func:`measure_alignment`).
    """
    clocks = tracker.result({name: functools.partial(true_time_of, name)
                             for name in tracker.devices})
    with h5py.File(path, "r") as f:
        t0_s = int(f["entry/sync"].attrs["t0_host_ns"]) * 1e-9
    signals = measure_alignment(path, decay_truth, t0_s - float(origin_s))
    write_alignment(path, clocks=clocks, signals=signals)
    return {"clocks": clocks, "signals": signals}


def measure_alignment(path: str | Path, truth: Callable[[FloatArray], Mapping[str, FloatArray]],
                      true_time_of_run_start: float) -> dict[str, Any]:
    """Delay of each synchronised channel against the simulator's truth.

    Parameters
    ----------
    path : str or Path
        A closed run file.
    truth : callable
        True times (s, tunnel clock) -> dict of ``h``, ``alpha``, ``lift``, ``moment`` (and a
        3-DOF tunnel's ``p``, ``drag``, checked when the file has them; NaN outside the
        decays), e.g. ``VirtualTunnel.decay_truth``.
    true_time_of_run_start : float
        The tunnel's true time at the run's time 0, s (``/entry/sync`` times are from the run
        start on the host clock).

    Returns
    -------
    dict
        ``delay_s`` and ``delay_std_s`` per channel (positive: the record lags the truth),
        ``misalignment_s`` (largest difference of delays between channels), ``max_abs_delay_s``
        and ``rows`` used; empty dicts and NaN when the run holds no usable decay.
    """
    with h5py.File(path, "r") as f:
        names = [*CHANNEL_SOURCES, *(k for k in SWAY_SOURCES if k in f["entry/sync"])]
        sync = {k: f["entry/sync"][k][:] for k in ("time", *names)}
        releases = f["entry/releases"][:]
    keep = release_rows(sync["time"], releases)
    t_true = sync["time"][keep] + float(true_time_of_run_start)
    x = truth(t_true)
    x_plus = truth(t_true + _DERIVATIVE_STEP_S)
    x_minus = truth(t_true - _DERIVATIVE_STEP_S)
    delay: dict[str, float] = {}
    delay_std: dict[str, float] = {}
    rows = 0
    for name in names:
        if name not in x:
            continue
        y = sync[name][keep]
        dx = (x_plus[name] - x_minus[name]) / (2 * _DERIVATIVE_STEP_S)
        ok = np.isfinite(y) & np.isfinite(x[name]) & np.isfinite(dx)
        if np.count_nonzero(ok) < 100:
            continue
        rows = max(rows, int(np.count_nonzero(ok)))
        X = np.column_stack([x[name][ok], dx[ok], np.ones(np.count_nonzero(ok))])
        coef, *_ = np.linalg.lstsq(X, y[ok], rcond=None)
        g, b = float(coef[0]), float(coef[1])
        resid = y[ok] - X @ coef
        dof = max(int(np.count_nonzero(ok)) - 3, 1)
        cov = np.linalg.inv(X.T @ X) * float(resid @ resid) / dof
        delay[name] = -b / g
        # tau = -b/g: first-order error propagation, g known to far better than b.
        delay_std[name] = math.sqrt(max(float(cov[1, 1]), 0.0)) / abs(g)
    values = list(delay.values())
    return {
        "delay_s": delay,
        "delay_std_s": delay_std,
        "misalignment_s": (max(values) - min(values)) if len(values) >= 2 else math.nan,
        "max_abs_delay_s": max(abs(v) for v in values) if values else math.nan,
        "rows": rows,
    }


def release_rows(time: FloatArray, releases: npt.NDArray[Any]) -> npt.NDArray[np.bool_]:
    """Return which rows of the sync view hold a free decay, its first instants left out.

    Parameters
    ----------
    time : ndarray
        ``/entry/sync/time``, s.
    releases : ndarray
        ``/entry/releases`` (``start_index``, ``stop_index``, ``release_time``).

    Returns
    -------
    ndarray of bool
        True on the rows of every release from ``SKIP_AFTER_RELEASE_S`` after its instant.
    """
    keep = np.zeros(time.size, dtype=bool)
    for row in releases:
        start, stop = int(row["start_index"]), int(row["stop_index"])
        keep[start:stop] = time[start:stop] >= float(row["release_time"]) + SKIP_AFTER_RELEASE_S
    return keep


def write_alignment(path: str | Path, *, clocks: Mapping[str, Any],
                    signals: Mapping[str, Any]) -> None:
    """Store the truth checks as attributes of ``/entry/sync`` (of a closed file).

    Attributes: from :meth:`ClockTruthTracker.result`, ``truth_clock_error_mean_s__<device>``,
    ``truth_clock_error_max_s__<device>``, ``truth_misalignment_s`` and
    ``truth_misalignment_max_s`` (between devices, mean and largest, after the settling time
    ``truth_settle_s``); from :func:`measure_alignment`,
    ``truth_delay_s__<channel>`` and ``truth_delay_std_s__<channel>``.
    """
    with h5py.File(path, "r+") as f:
        attrs = f["entry/sync"].attrs
        for name, value in clocks.get("clock_error_mean_s", {}).items():
            attrs[per_device_attr("truth_clock_error_mean_s", name)] = float(value)
            attrs[per_device_attr("truth_clock_error_max_s", name)] = float(
                clocks["clock_error_max_s"][name])
        if "misalignment_s" in clocks:
            attrs["truth_misalignment_s"] = float(clocks["misalignment_s"])
            attrs["truth_misalignment_max_s"] = float(clocks["misalignment_max_s"])
            attrs["truth_settle_s"] = float(clocks["settle_s"])
        for name, value in signals.get("delay_s", {}).items():
            attrs[per_device_attr("truth_delay_s", name)] = float(value)
            attrs[per_device_attr("truth_delay_std_s", name)] = float(
                signals["delay_std_s"][name])


class ClockTruthTracker:
    """Error of the host times the sync view used, against the simulator's true clocks.

    The recorder calls :meth:`observe` with every block it puts into the sync view: the host
    times it mapped the samples to (run seconds) and their device times. The first and last
    sample of each block are kept (a clock error changes slowly within a 20-50 ms block), a few
    hundred points per second of run: this runs on simulated rigs only. :meth:`result` compares
    them with the truth, ``truth[name](device time) -> true host time`` (``time.monotonic``
    seconds), asked only then (a rig in another process answers after the run).

    Parameters
    ----------
    settle_s : float
        Run time before which errors are not counted, s: the clock maps need a few envelope
        windows and their first anchors before they mean anything.
    """

    def __init__(self, *, settle_s: float = 2.0) -> None:
        self.settle_s = float(settle_s)
        self._points: dict[str, list[tuple[float, float, float, float]]] = {}
        self._t0_s = math.nan

    def observe(self, name: str, t_run: FloatArray, t_device: FloatArray, t0_s: float) -> None:
        """Record one block: mapped run times and device times of its samples, s."""
        if t_run.size == 0:
            return
        self._t0_s = float(t0_s)
        self._points.setdefault(name, []).append(
            (float(t_run[0]), float(t_run[-1]), float(t_device[0]), float(t_device[-1])))

    @property
    def devices(self) -> list[str]:
        """Devices observed so far."""
        return sorted(self._points)

    def errors(self, truth: Mapping[str, Callable[[FloatArray], FloatArray]]
               ) -> dict[str, tuple[FloatArray, FloatArray]]:
        """Clock error of each device over the run after ``settle_s``.

        Parameters
        ----------
        truth : mapping of str to callable
            As :meth:`result`; devices without one, or with fewer than two blocks, are left out.

        Returns
        -------
        dict of str to (ndarray, ndarray)
            Device name -> (mapped run times of the blocks' first and last samples, s; their
            mapped minus true times, s), in the order observed.
        """
        series: dict[str, tuple[FloatArray, FloatArray]] = {}
        for name, points in self._points.items():
            arr = np.array([p for p in points if p[0] >= self.settle_s]).reshape(-1, 4)
            if name not in truth or arr.shape[0] < 2:
                continue
            t_run = arr[:, :2].ravel()
            true = np.asarray(truth[name](arr[:, 2:].ravel()), dtype=np.float64) - self._t0_s
            series[name] = (t_run, t_run - true)
        return series

    def result(self, truth: Mapping[str, Callable[[FloatArray], FloatArray]]) -> dict[str, Any]:
        """Headline figures after ``settle_s``: per device mean and max error, misalignment.

        Parameters
        ----------
        truth : mapping of str to callable
            Device name -> (device time, s -> true host time, s); devices without one are
            left out.

        Returns
        -------
        dict
            ``clock_error_mean_s`` and ``clock_error_max_s`` per device (mapped minus true
            time); ``misalignment_s``, the spread of the devices' errors at one instant (the
            largest minus the smallest: how far apart two devices' samples of one instant
            land in the sync view) averaged over the run, and ``misalignment_max_s``, its
            largest value (NaN with fewer than two devices); ``settle_s``.
        """
        series = self.errors(truth)
        mean = {name: float(np.mean(err)) for name, (_, err) in series.items()}
        worst = {name: float(np.max(np.abs(err))) for name, (_, err) in series.items()}
        misalignment = worst_misalignment = math.nan
        names = sorted(series)
        if len(names) >= 2:
            lo = max(float(series[n][0][0]) for n in names)
            hi = min(float(series[n][0][-1]) for n in names)
            grid = np.unique(np.concatenate([series[n][0] for n in names]))
            grid = grid[(grid >= lo) & (grid <= hi)]
            if grid.size:
                errs = np.array([np.interp(grid, *series[n]) for n in names])
                spread = errs.max(axis=0) - errs.min(axis=0)
                # Time-weighted mean: the grid is the union of block edges, not uniform.
                misalignment = float(np.average(spread, weights=_cell_widths(grid)))
                worst_misalignment = float(np.max(spread))
        return {"clock_error_mean_s": mean, "clock_error_max_s": worst,
                "misalignment_s": misalignment, "misalignment_max_s": worst_misalignment,
                "settle_s": self.settle_s}


def _cell_widths(t: FloatArray) -> FloatArray:
    """Width of the time cell around each point of an increasing grid (trapezoid weights)."""
    if t.size < 2:
        return np.ones_like(t)
    edges = np.concatenate(([t[0]], 0.5 * (t[1:] + t[:-1]), [t[-1]]))
    widths = np.diff(edges)
    return widths if np.any(widths > 0) else np.ones_like(t)
