"""How well a recorded run's synchronised view lines up with the simulator's truth.

Responsibility: :func:`measure_alignment` compares ``/entry/sync`` of a run recorded from a
simulated rig with the virtual tunnel's own record of every free decay
(:meth:`~simulators.virtual_tunnel.VirtualTunnel.decay_truth`) and estimates, per channel, the
time by which the recorded signal lags the truth. h and alpha come from the lasers, lift and
moment from the scanner, so their delays measure each device's clock mapping end to end (clock
offset and drift, transport latency, resampling), and their spread is the misalignment between
the devices that E2RFC would see as a phase error between motion and force. :func:`write_alignment`
stores the result as attributes of ``/entry/sync``.

Estimator: on the rows of every release (the free decays, where the signals move), the recorded
channel ``y`` is regressed on the truth ``x(t)``, its time derivative ``x'(t)`` and a constant:
``y = g x - g tau x' + c`` to first order in the delay ``tau``, which is ``-b / g`` of the fit.
The first order is ample: at 4 Hz, 1 ms of delay is a 2.5 % phase, its second-order term
``(w tau)^2 / 2`` 3e-4. The standard error of ``tau`` follows from the fit's residual; with
seconds of decay and 2 % noise it is microseconds, far below the 0.2 ms being checked.

Not responsible for: recording (:mod:`daq.pipeline`), the truth (:mod:`simulators`). Real rigs
have no truth: this runs only for simulated ones.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["ClockTruthTracker", "measure_alignment", "write_alignment"]

FloatArray = npt.NDArray[np.float64]

#: Which device each sync channel comes from.
CHANNEL_SOURCES = {"h": "lasers", "alpha": "lasers", "lift": "scanner", "moment": "scanner"}
#: Rows skipped after each release, s: the first instants depend on the release mechanism.
SKIP_AFTER_RELEASE_S = 0.05
#: Step of the central difference that gives the truth's derivative, s.
_DERIVATIVE_STEP_S = 1e-4


def measure_alignment(path: str | Path, truth: Callable[[FloatArray], Mapping[str, FloatArray]],
                      true_time_of_run_start: float) -> dict[str, Any]:
    """Delay of each synchronised channel against the simulator's truth.

    Parameters
    ----------
    path : str or Path
        A closed run file.
    truth : callable
        True times (s, tunnel clock) -> dict of ``h``, ``alpha``, ``lift``, ``moment`` (NaN
        outside the decays), e.g. ``VirtualTunnel.decay_truth``.
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
    import h5py

    with h5py.File(path, "r") as f:
        sync = {k: f["entry/sync"][k][:] for k in ("time", *CHANNEL_SOURCES)}
        releases = f["entry/releases"][:]
    keep = np.zeros(sync["time"].size, dtype=bool)
    for row in releases:
        start, stop = int(row["start_index"]), int(row["stop_index"])
        t = sync["time"][start:stop]
        keep[start:stop] = t >= float(row["release_time"]) + SKIP_AFTER_RELEASE_S
    t_true = sync["time"][keep] + float(true_time_of_run_start)
    x = truth(t_true)
    x_plus = truth(t_true + _DERIVATIVE_STEP_S)
    x_minus = truth(t_true - _DERIVATIVE_STEP_S)
    delay: dict[str, float] = {}
    delay_std: dict[str, float] = {}
    rows = 0
    for name in CHANNEL_SOURCES:
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


def write_alignment(path: str | Path, *, clocks: Mapping[str, Any],
                    signals: Mapping[str, Any]) -> None:
    """Store the truth checks as attributes of ``/entry/sync`` (of a closed file).

    Attributes: from :meth:`ClockTruthTracker.result`, ``truth_clock_error_mean_s.<device>``,
    ``truth_clock_error_max_s.<device>`` and ``truth_misalignment_s`` (between devices, after
    the settling time ``truth_settle_s``); from :func:`measure_alignment`,
    ``truth_delay_s.<channel>`` and ``truth_delay_std_s.<channel>``.
    """
    import h5py

    with h5py.File(path, "r+") as f:
        attrs = f["entry/sync"].attrs
        for name, value in clocks.get("clock_error_mean_s", {}).items():
            attrs[f"truth_clock_error_mean_s.{name}"] = float(value)
            attrs[f"truth_clock_error_max_s.{name}"] = float(clocks["clock_error_max_s"][name])
        if "misalignment_s" in clocks:
            attrs["truth_misalignment_s"] = float(clocks["misalignment_s"])
            attrs["truth_settle_s"] = float(clocks["settle_s"])
        for name, value in signals.get("delay_s", {}).items():
            attrs[f"truth_delay_s.{name}"] = float(value)
            attrs[f"truth_delay_std_s.{name}"] = float(signals["delay_std_s"][name])


class ClockTruthTracker:
    """Per-sample error of the host times the sync view used, against the simulator's truth.

    The recorder calls :meth:`observe` with every block it puts into the sync view: the host
    times it mapped the samples to (run seconds) and their device times. ``truth[name]`` gives
    the true host time (``time.monotonic`` seconds) of a device time. The error of a sample is
    ``mapped - true``; its spread between devices at the same instant is the misalignment the
    sync view carries. One point per block is kept (the block's mean error and its time), so
    memory grows by ~100 points per second of run (a few MB per hour): this runs on simulated
    rigs only.

    Parameters
    ----------
    truth : mapping of str to callable
        Device name -> (device time, s -> true host time, s).
    settle_s : float
        Run time before which errors are not counted in the headline figures, s: the clock maps
        need a few envelope windows before their drift estimate means anything.
    """

    def __init__(self, truth: Mapping[str, Callable[[FloatArray], FloatArray]], *,
                 settle_s: float = 2.0) -> None:
        self.truth = dict(truth)
        self.settle_s = float(settle_s)
        self._points: dict[str, list[tuple[float, float, float]]] = {n: [] for n in self.truth}

    def observe(self, name: str, t_run: FloatArray, t_device: FloatArray, t0_s: float) -> None:
        """Record one block: mapped run times and device times of its samples, s."""
        fn = self.truth.get(name)
        if fn is None or t_run.size == 0:
            return
        err = t_run - (np.asarray(fn(t_device), dtype=np.float64) - t0_s)
        self._points[name].append((float(t_run[0]), float(np.mean(err)),
                                   float(np.max(np.abs(err)))))

    def result(self) -> dict[str, Any]:
        """Headline figures after ``settle_s``: per device mean and max error, misalignment.

        Returns
        -------
        dict
            ``clock_error_mean_s`` and ``clock_error_max_s`` per device, ``misalignment_s``
            (largest difference, at one instant, between two devices' errors; NaN with fewer
            than two devices), ``settle_s``.
        """
        mean: dict[str, float] = {}
        worst: dict[str, float] = {}
        series: dict[str, tuple[FloatArray, FloatArray]] = {}
        for name, points in self._points.items():
            arr = np.array([p for p in points if p[0] >= self.settle_s]).reshape(-1, 3)
            if arr.shape[0] < 2:
                continue
            mean[name] = float(np.mean(arr[:, 1]))
            worst[name] = float(np.max(arr[:, 2]))
            series[name] = (arr[:, 0], arr[:, 1])
        misalignment = math.nan
        names = sorted(series)
        if len(names) >= 2:
            grid = np.unique(np.concatenate([series[n][0] for n in names]))
            lo = max(float(series[n][0][0]) for n in names)
            hi = min(float(series[n][0][-1]) for n in names)
            grid = grid[(grid >= lo) & (grid <= hi)]
            if grid.size:
                errs = np.array([np.interp(grid, *series[n]) for n in names])
                misalignment = float(np.max(errs.max(axis=0) - errs.min(axis=0)))
        return {"clock_error_mean_s": mean, "clock_error_max_s": worst,
                "misalignment_s": misalignment, "settle_s": self.settle_s}
