"""The operator console's main window: traces, pressure distribution, spectra, wind, status.

Responsibility: one :class:`ConsoleWindow` (no module-level state) that owns a ``QTimer`` and, at
each tick, polls its :class:`~daq.console.source.DataSource` and redraws from a snapshot: scrolling
h and alpha traces (peak downsampling, clipped to the view), lift and moment, the pressure
coefficients of the latest row against the tap's perimeter position and on the section outline, the
amplitude spectra of h and alpha over the visible window, wind speed and air density, and a status
line. Over a live source (a :class:`~daq.console.source.HealthSource`) it adds the fan state and a
device health panel (samples/s, gaps, overflows, errors, clock fit and last fault per device) with a
red alarm line when a device has faulted or stalled, and the operator controls
(:class:`~daq.console.controls.ControlPanel`: fan, arm/release, CALZ, markers); all are polled by
the same timer. Data is never pushed into the window from other threads
(docs/reference/architecture.md, "Design rules").

Not responsible for: reading files or instruments (the sources), the numbers themselves
(:mod:`daq.console.display`), or the command line (:mod:`daq.console.app`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from daq.console.controls import ControlPanel
from daq.console.display import amplitude_spectrum, perimeter_positions, pressure_coefficients
from daq.console.live_ident import DecaySource, LiveIdentifier
from daq.console.qt_guard import guard_bool_refcounts
from daq.console.releases_panel import DerivativesPanel, ReleasesPanel
from daq.console.source import DataSource, DeviceHealth, HealthSource
from daq.errors import ReplayError

__all__ = ["TRACE_BINS", "ConsoleWindow", "peak_decimate"]

#: Redraw period, ms: 30 frames/s at most, so that ticks late by a few ms (the cores busy with
#: the acquisition) or finding no new rows still leave the 20 frames/s the operator needs
#: (measured with 511 taps live: 40 ms gave 18.8-21.6 frames/s, 33 ms 22.4).
FRAME_MS = 33
#: Trace colours (pen specs), by channel.
_PENS = {"h": "c", "alpha": "y", "lift": "m", "moment": "g", "p": "r"}
#: Displayed unit and scale factor from SI, by channel.
_DISPLAY = {"h": ("mm", 1e3), "alpha": ("deg", 180.0 / math.pi), "lift": ("N/m", 1.0),
            "moment": ("N m/m", 1.0), "p": ("mm", 1e3)}
#: The traces drawn, top to bottom; a rig with three degrees of freedom adds the sway p.
_TRACES = ("h", "alpha", "lift", "moment")
#: The columns drawn over the whole window (the pressures are drawn for the latest row only).
_TRACE_COLUMNS = ("time", "h", "alpha", "lift", "moment", "U", "rho")
#: The traces are drawn as the minimum and maximum of this many bins (about the plot's width in
#: pixels: no peak is lost, and 10 000 rows of a 20 s window cost 2000 points).
TRACE_BINS = 1000
#: Columns of the health panel.
HEALTH_COLUMNS = ("device", "samples/s", "gaps", "overflow", "errors", "clock fit", "last fault")
#: The health panel is refreshed every this many frames.
_HEALTH_EVERY = 5
#: The timer redraws the spectra and the pressure views when the data moved on by this much,
#: s of run time (~7 per second at real time): they change slowly and cost as much as the four
#: traces.
_SLOW_PERIOD_S = 0.15
#: Tap colours on the outline: Cp on [-2, 2] in this many steps. The brushes are made once:
#: pyqtgraph caches a rendered symbol per brush *object*, so new brushes at every frame would
#: re-render every tap's symbol (~60 ms per frame with 511 taps).
_CP_LEVELS = 64


def peak_decimate(t: npt.NDArray[Any], y: npt.NDArray[Any],
                  bins: int) -> tuple[npt.NDArray[Any], npt.NDArray[Any]]:
    """Reduce a trace to the minimum and maximum of each of ``bins`` equal runs of samples.

    Parameters
    ----------
    t, y : ndarray, shape (n,)
        Time (s) and values; NaN (a gap) in ``y`` stays a gap: a bin with a NaN gives NaN.
    bins : int
        Number of bins (>= 1); traces of at most ``2 bins`` samples are returned as they are.

    Returns
    -------
    t, y : ndarray, shape (2 bins,) or (n,)
        Each bin's minimum then maximum, in time order within the bin, at the bin's first and
        last sample times.
    """
    n = t.size
    if n <= 2 * bins:
        return t, y
    per = n // bins
    used = per * bins
    start = n - used  # the newest samples are kept whole; the oldest few are dropped
    yb = y[start:].reshape(bins, per)
    tb = t[start:].reshape(bins, per)
    with np.errstate(invalid="ignore"):
        lo, hi = yb.min(axis=1), yb.max(axis=1)  # NaN propagates: a gap stays visible
    arg_lo, arg_hi = np.argmin(np.nan_to_num(yb, nan=np.inf), axis=1), \
        np.argmax(np.nan_to_num(yb, nan=-np.inf), axis=1)
    first = arg_lo <= arg_hi  # the minimum comes first in time
    out_y = np.empty(2 * bins)
    out_y[0::2] = np.where(first, lo, hi)
    out_y[1::2] = np.where(first, hi, lo)
    out_t = np.empty(2 * bins)
    out_t[0::2] = tb[:, 0]
    out_t[1::2] = tb[:, -1]
    return out_t, out_y


class _RangeKeeper:
    """Sets a plot's y range from the data drawn, at redraw time, with hysteresis.

    pyqtgraph's auto-range runs at paint time and its range change asks for a second paint of
    every plot at every frame; here the range follows the data (grows at once, shrinks when
    the data fill less than a third of it) and is set before the paint.
    """

    def __init__(self, plot: pg.PlotWidget) -> None:
        plot.enableAutoRange(y=False)
        self._plot = plot
        self._range: tuple[float, float] | None = None

    def fit(self, *arrays: npt.NDArray[Any]) -> None:
        """Make the y range hold the finite values of ``arrays`` (nothing when there are none)."""
        lows = [float(np.nanmin(a)) for a in arrays if a.size and np.isfinite(a).any()]
        highs = [float(np.nanmax(a)) for a in arrays if a.size and np.isfinite(a).any()]
        if not lows:
            return
        lo, hi = min(lows), max(highs)
        span = hi - lo if hi > lo else max(abs(hi) * 0.1, 1e-9)
        lo, hi = lo - 0.05 * span, hi + 0.05 * span
        now = self._range
        if now is None or lo < now[0] or hi > now[1] or now[1] - now[0] > 3.0 * (hi - lo):
            self._plot.setYRange(lo, hi, padding=0.0)
            self._range = (lo, hi)


def _plot_widget(plots: list[pg.PlotWidget]) -> pg.PlotWidget:
    """Return a plot whose axes show the values as given (no automatic SI prefix), in ``plots``."""
    plot = pg.PlotWidget()
    plots.append(plot)
    for side in ("left", "bottom"):
        plot.getAxis(side).enableAutoSIPrefix(False)
    return plot


class ConsoleWindow(QtWidgets.QMainWindow):
    """The operator console window over one data source.

    Parameters
    ----------
    source : DataSource
        An opened source (replay or live); the window polls it and closes it when closed.
    window_s : float
        Length of the scrolling time window, s (> 0).
    frame_ms : int
        Redraw period, ms.
    confirm : callable, optional
        ``confirm(title, question) -> bool`` for the control panel's dangerous actions
        (default: a message box); a seam for tests.
    identify : bool
        Fit each release of the source (one with ``decays()``) and, from two wind speeds on,
        the E2RFC model (:mod:`daq.console.live_ident`, in a worker process).
    parent : QWidget, optional
        Qt parent.

    Attributes
    ----------
    curves : dict of str to pyqtgraph.PlotDataItem
        The ``h`` (mm), ``alpha`` (deg), ``lift`` (N/m) and ``moment`` (N m/m) traces (and the
        sway ``p`` (mm) of a rig with three degrees of freedom) against time (``xData``: s
        from run start), as set by the last redraw; each is drawn shifted so that its latest
        sample is at 0 of the fixed time axis (s before the latest sample).
    cp_curve : pyqtgraph.PlotDataItem
        Cp of the latest row against perimeter position (m).
    spectrum_curves : dict of str to pyqtgraph.PlotDataItem
        Amplitude spectra of ``h`` (mm) and ``alpha`` (deg) against frequency (Hz).
    health_table : QTableWidget or None
        The device health panel (columns :data:`HEALTH_COLUMNS`), for a live source only.
    alarm_label : QLabel or None
        The alarm line above it: empty when all is well, red text naming the devices in alarm.
    controls : ControlPanel or None
        The operator controls (:mod:`daq.console.controls`), over a live source (one with an ``acq``
        engine) only; re-evaluated at every tick.
    identifier : LiveIdentifier or None
        Fits the releases (None when the source has no ``decays()`` or ``identify`` is off).
    tabs : QTabWidget
        The ``spectra`` and ``flutter derivatives`` views.
    releases_panel : ReleasesPanel
        The releases table and the E2RFC status line (under the traces; hidden without an
        identifier).
    derivatives_panel : DerivativesPanel
        The model's flutter derivatives against the table values.
    flutter_label : QLabel
        The predicted flutter speed in the top bar ("U_F = --" until there is a model).
    """

    def __init__(self, source: DataSource, *, window_s: float = 20.0, frame_ms: int = FRAME_MS,
                 confirm: Callable[[str, str], bool] | None = None, identify: bool = True,
                 parent: QtWidgets.QWidget | None = None) -> None:
        guard_bool_refcounts()  # PySide6 6.12.0 + Python 3.11: see daq.console.qt_guard
        super().__init__(parent)
        if not (isinstance(window_s, (int, float)) and 0 < window_s < math.inf):
            raise ValueError(f"window_s = {window_s!r} must be a number of seconds > 0")
        self._source = source
        self._window_s = float(window_s)
        self._drawn_rows = -1
        #: Time (s) of the row whose pressures the Cp view shows; NaN before the first one.
        self.cp_time = math.nan
        info = source.info
        taps = info.config.taps
        self._perimeter = perimeter_positions(taps)
        self.setWindowTitle(f"windrig console: {info.label} ({info.config.name})")

        central = QtWidgets.QWidget()
        grid = QtWidgets.QGridLayout(central)
        self.setCentralWidget(central)
        self._wind_label = QtWidgets.QLabel("U = -- m/s")
        self._rho_label = QtWidgets.QLabel("rho = -- kg/m^3")
        for label in (self._wind_label, self._rho_label):
            label.setStyleSheet("font-size: 16pt; font-weight: bold")
        top = QtWidgets.QHBoxLayout()
        top.setSpacing(40)
        top.addWidget(self._wind_label)
        top.addWidget(self._rho_label)
        self._health_source = source if isinstance(source, HealthSource) else None
        self._fan_label: QtWidgets.QLabel | None = None
        if self._health_source is not None:
            self._fan_label = QtWidgets.QLabel("fan: -- rpm")
            self._fan_label.setStyleSheet("font-size: 16pt; font-weight: bold")
            top.addWidget(self._fan_label)
        self.flutter_label = QtWidgets.QLabel("U_F = --")
        self.flutter_label.setStyleSheet("font-size: 16pt; font-weight: bold")
        self.flutter_label.setToolTip("flutter speed predicted by the E2RFC model of this "
                                      "session's releases")
        top.addWidget(self.flutter_label)
        top.addStretch(1)
        grid.addLayout(top, 0, 0, 1, 2)

        self.curves: dict[str, pg.PlotDataItem] = {}
        self._y_ranges: dict[str, _RangeKeeper] = {}
        self._plots: list[pg.PlotWidget] = []
        first: pg.PlotWidget | None = None
        traces = _TRACES + (("p",) if info.config.section.n_dof == 3 else ())
        self._trace_columns = (*_TRACE_COLUMNS, *traces[len(_TRACES):])
        for row, name in enumerate(traces, start=1):
            unit, _ = _DISPLAY[name]
            plot = _plot_widget(self._plots)
            plot.setLabel("left", f"{name} ({unit})")
            plot.showGrid(x=True, y=True, alpha=0.3)
            if first is None:
                first = plot
            else:
                plot.setXLink(first)
            if row == len(traces):
                plot.setLabel("bottom", "time before the latest sample (s)")
            else:  # one time axis with numbers is enough (the grid lines stay)
                plot.getAxis("bottom").setStyle(showValues=False)
            # A fixed x range: the traces move, not the axis (see redraw).
            plot.enableAutoRange(x=False)
            plot.setXRange(-self._window_s, 0.0, padding=0.0)
            self._y_ranges[name] = _RangeKeeper(plot)
            # Decimated here (peak_decimate), not by pyqtgraph: its automatic downsampling
            # depends on the view's transform, which is only known at paint time, and its
            # recomputation then asks for a second paint of every trace at every frame.
            curve = plot.plot(pen=_PENS[name])
            self.curves[name] = curve
            grid.addWidget(plot, row, 0)

        cp_plot = _plot_widget(self._plots)
        cp_plot.setLabel("left", "Cp")
        cp_plot.setLabel("bottom", "perimeter position (m)")
        cp_plot.getViewBox().invertY(True)  # suction (Cp < 0) up, as aerodynamicists plot it
        cp_plot.showGrid(x=True, y=True, alpha=0.3)
        self.cp_curve = cp_plot.plot(pen="w", symbol="o", symbolSize=5, symbolBrush="w")
        cp_plot.enableAutoRange(x=False)
        cp_plot.setXRange(float(np.min(self._perimeter)), float(np.max(self._perimeter)))
        self._y_ranges["Cp"] = _RangeKeeper(cp_plot)
        grid.addWidget(cp_plot, 1, 1)

        outline = _plot_widget(self._plots)
        outline.setLabel("left", "-z (m)")
        outline.setLabel("bottom", "x (m)")
        outline.setAspectLocked(True)
        outline.plot(np.append(taps.x, taps.x[0]), -np.append(taps.z, taps.z[0]), pen="w")
        self._tap_scatter = pg.ScatterPlotItem(taps.x, -taps.z, size=8)
        outline.addItem(self._tap_scatter)
        self._colormap = pg.colormap.get("CET-D1")
        self._palette = [pg.mkBrush(q) for q in self._colormap.map(
            np.linspace(0.0, 1.0, _CP_LEVELS), mode="qcolor")] + [pg.mkBrush(120, 120, 120)]
        self._tap_levels_shown: npt.NDArray[np.intp] | None = None
        self._slow_drawn_at = -math.inf  # run time of the last redraw of the slow views, s
        grid.addWidget(outline, 2, 1)

        spectrum = _plot_widget(self._plots)
        spectrum.setLabel("left", "amplitude (mm, deg)")
        spectrum.setLabel("bottom", "frequency (Hz)")
        spectrum.addLegend()
        spectrum.showGrid(x=True, y=True, alpha=0.3)
        self.spectrum_curves = {name: spectrum.plot(pen=_PENS[name], name=name)
                                for name in ("h", "alpha")}
        spectrum.enableAutoRange(x=False)
        spectrum.setXRange(0.0, min(20.0, 0.5 * source.info.rate_hz))
        self._y_ranges["spectrum"] = _RangeKeeper(spectrum)
        self.releases_panel = ReleasesPanel()
        self.derivatives_panel = DerivativesPanel()
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(spectrum, "spectra")
        self.tabs.addTab(self.derivatives_panel, "flutter derivatives")
        self.identifier: LiveIdentifier | None = None
        self._decay_source: DecaySource | None = None
        if identify and callable(getattr(source, "decays", None)):
            self._decay_source = cast(DecaySource, source)
            self.identifier = LiveIdentifier(info.config.section, info.rate_hz)
        self.health_table: QtWidgets.QTableWidget | None = None
        self.alarm_label: QtWidgets.QLabel | None = None
        self._frames = 0
        grid.addWidget(self.releases_panel, len(traces) + 1, 0)
        self.releases_panel.setVisible(self.identifier is not None)
        if self._health_source is None:
            grid.addWidget(self.tabs, 3, 1, 3, 1)
        else:
            grid.addWidget(self.tabs, 3, 1)
            grid.addWidget(self._health_panel(), 4, 1, 2, 1)
        self.controls: ControlPanel | None = None
        if self._health_source is not None and hasattr(source, "acq"):
            self.controls = ControlPanel(source, confirm=confirm)
            grid.addWidget(self.controls, len(traces) + 2, 0, 1, 2)
        grid.setColumnStretch(0, 3)
        grid.setColumnStretch(1, 2)

        self._status = QtWidgets.QLabel(source.status())
        self.statusBar().addWidget(self._status, 1)

        self._timer = QtCore.QTimer(self)
        self._timer.setInterval(int(frame_ms))
        self._timer.timeout.connect(self.tick)
        self._timer.start()

    # -- public ----------------------------------------------------------------------------------
    @property
    def source(self) -> DataSource:
        """The data source the window polls."""
        return self._source

    @property
    def window_s(self) -> float:
        """Length of the scrolling time window, s."""
        return self._window_s

    @property
    def status_text(self) -> str:
        """The status line as shown."""
        return str(self._status.text())

    def tick(self) -> None:
        """Poll the source and redraw when it has new rows (the timer's slot)."""
        try:
            self._source.poll()
        except ReplayError:
            self._timer.stop()
        if self._source.total_rows != self._drawn_rows:
            self._drawn_rows = self._source.total_rows
            # The scalars of the whole window, the (wide) pressures of the latest row only.
            snap = self._source.snapshot(columns=self._trace_columns)
            t_end = float(snap["time"][-1]) if snap["time"].size else math.nan
            slow = not t_end < self._slow_drawn_at + _SLOW_PERIOD_S  # NaN: draw
            latest = self._source.snapshot(1, columns=("time", "pressure")) if slow else None
            self.redraw(snap, latest, slow_views=slow)
        self._status.setText(self._source.status())
        if self._health_source is not None and self._frames % _HEALTH_EVERY == 0:
            self.show_health(self._health_source.health(), self._health_source.fan_speed_rpm)
        if self.controls is not None:
            self.controls.refresh()
        if (self.identifier is not None and self._decay_source is not None
                and self.identifier.update(self._decay_source)):
            self.show_releases()
        self._frames += 1

    def show_releases(self) -> None:
        """Redraw the releases table, the derivatives and the flutter speed from the fits."""
        ident = self.identifier
        if ident is None:
            return
        self.releases_panel.show_rows(ident)
        self.derivatives_panel.show_fit(ident)
        fit = ident.campaign
        if fit is None or fit.flutter_speed is None:
            self.flutter_label.setText("U_F = --" if fit is None else "U_F: none found")
        else:
            std = "" if fit.flutter_std is None else f" +- {fit.flutter_std:.2f}"
            spread = fit.structures
            # The range only when the data leave the structure open: the std alone would
            # claim more than they hold.
            also = ("" if spread is None or len(spread.labels) == 1
                    else f" ({spread.range_text()})")
            self.flutter_label.setText(f"U_F = {fit.flutter_speed:.2f}{std} m/s{also}")

    def show_health(self, health: list[DeviceHealth], fan_rpm: float) -> None:
        """Fill the health panel, the alarm line and the fan state (live sources only)."""
        table, alarm = self.health_table, self.alarm_label
        if table is None or alarm is None:
            return
        if self._fan_label is not None:
            self._fan_label.setText("fan: -- rpm" if math.isnan(fan_rpm)
                                    else f"fan: {fan_rpm:.0f} rpm")
        table.setRowCount(len(health))
        red = pg.mkColor(255, 90, 90)
        for row, dev in enumerate(health):
            fit = dev.clock_fit
            clock = ("" if fit is None else f"{fit.get('drift_ppm', math.nan):+.1f} ppm "
                     f"{fit.get('residual_s', math.nan) * 1e6:.0f} us")
            cells = (dev.device, f"{dev.rate_hz:.1f}", str(dev.gaps), str(dev.overflow_samples),
                     str(dev.faults), clock, dev.alarm or dev.last_fault or "")
            for col, text in enumerate(cells):
                item = table.item(row, col)
                if item is None:
                    item = QtWidgets.QTableWidgetItem()
                    table.setItem(row, col, item)
                item.setText(text)
                if dev.alarm is not None:
                    item.setForeground(red)
                else:
                    item.setData(QtCore.Qt.ItemDataRole.ForegroundRole, None)
        alarms = [f"{d.device}: {d.alarm}" for d in health if d.alarm is not None]
        alarm.setText("ALARM  " + "; ".join(alarms) if alarms else "all devices OK")
        alarm.setStyleSheet("color: white; background: #c00000; font-weight: bold; padding: 2px"
                            if alarms else "color: #60d060; padding: 2px")

    def redraw(self, snap: dict[str, npt.NDArray[Any]],
               latest: dict[str, npt.NDArray[Any]] | None = None, *,
               slow_views: bool = True) -> None:
        """Draw one snapshot.

        Parameters
        ----------
        snap : dict of str to ndarray
            The window's rows of the scalar columns of :func:`daq.console.source.sync_columns`
            (``pressure`` may be absent).
        latest : dict of str to ndarray, optional
            ``time`` and ``pressure`` of the row the pressure views show (the latest); default
            the last row of ``snap``.
        slow_views : bool
            Redraw the spectra and the pressure views too (the timer does when the data
            moved on by ``_SLOW_PERIOD_S``); the traces and labels are always redrawn.
        """
        t = snap["time"]
        if t.size == 0:
            return
        t_end = float(t[-1])
        visible = t >= t_end - self._window_s
        tv = t[visible]
        for name, curve in self.curves.items():
            _, scale = _DISPLAY[name]
            values = snap[name][visible] * scale
            self._y_ranges[name].fit(values)
            curve.setData(*peak_decimate(tv, values, TRACE_BINS), connect="finite")
            # The curve keeps the run's times (``xData``) and is shifted so that the latest
            # sample sits at 0 of the fixed axis: a scrolling x range would make every time
            # axis and grid regenerate its ticks at every frame (~30 % of a frame's CPU).
            curve.setPos(-t_end, 0.0)
        U, rho = float(snap["U"][-1]), float(snap["rho"][-1])
        self._wind_label.setText(f"U = {U:.2f} m/s")
        self._rho_label.setText(f"rho = {rho:.3f} kg/m^3")
        if not slow_views:
            self._prepare_paint()
            return
        self._slow_drawn_at = t_end
        amplitudes = []
        for name, curve in self.spectrum_curves.items():
            _, scale = _DISPLAY[name]
            freq, amp = amplitude_spectrum(tv, snap[name][visible] * scale)
            amplitudes.append(amp)
            curve.setData(freq, amp)
        self._y_ranges["spectrum"].fit(*amplitudes)
        if latest is None:
            latest = {"time": t[-1:], "pressure": snap["pressure"][-1:]}
        cp = pressure_coefficients(latest["pressure"][-1], U, rho)
        self.cp_time = float(latest["time"][-1])
        if np.isfinite(cp).any():
            self._y_ranges["Cp"].fit(cp)
            self.cp_curve.setData(self._perimeter, cp, connect="finite")
        else:  # wind off: no Cp (an all-NaN curve makes pyqtgraph warn at every frame)
            self.cp_curve.setData([], [])
        levels = self._tap_levels(cp)
        if self._tap_levels_shown is None or not np.array_equal(levels, self._tap_levels_shown):
            self._tap_scatter.setBrush(self._tap_brushes(cp))
            self._tap_levels_shown = levels
        self._prepare_paint()

    def _prepare_paint(self) -> None:
        """Bring the plots' view transforms up to date now, before Qt paints them.

        pyqtgraph updates a view's transform lazily in the paint itself, and the axes it moves
        then ask for a second paint: every plot would be painted twice per frame.
        """
        for plot in self._plots:
            plot.scene().prepareForPaint()

    # -- Qt --------------------------------------------------------------------------------------
    def closeEvent(self, event: Any) -> None:  # noqa: N802 - Qt's name
        """Stop the timer, wait for a running control action, and close the source."""
        self._timer.stop()
        if self.controls is not None:
            self.controls.shutdown()
        if self.identifier is not None:
            self.identifier.close()
        self._source.close()
        super().closeEvent(event)

    # -- internals -------------------------------------------------------------------------------
    def _health_panel(self) -> QtWidgets.QWidget:
        """Build the (empty) device health panel: the alarm line over the table."""
        panel = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(panel)
        layout.setContentsMargins(0, 0, 0, 0)
        self.alarm_label = QtWidgets.QLabel("devices: starting")
        layout.addWidget(self.alarm_label)
        table = QtWidgets.QTableWidget(0, len(HEALTH_COLUMNS))
        table.setHorizontalHeaderLabels(list(HEALTH_COLUMNS))
        table.verticalHeader().setVisible(False)
        table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        table.verticalHeader().setDefaultSectionSize(17)
        font = table.font()
        font.setPointSizeF(max(font.pointSizeF() - 1.0, 7.0))
        table.setFont(font)
        table.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        header = table.horizontalHeader()
        header.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        layout.addWidget(table)
        self.health_table = table
        return panel

    @staticmethod
    def _tap_levels(cp: npt.NDArray[np.float64]) -> npt.NDArray[np.intp]:
        """Return each tap's colour: Cp on [-2, 2] in ``_CP_LEVELS`` steps (that index: NaN)."""
        scaled = np.clip((np.asarray(cp, dtype=float) + 2.0) / 4.0, 0.0, 1.0)
        levels = np.rint(np.nan_to_num(scaled) * (_CP_LEVELS - 1)).astype(np.intp)
        levels[~np.isfinite(scaled)] = _CP_LEVELS
        return levels

    def _tap_brushes(self, cp: npt.NDArray[np.float64]) -> list[Any]:
        """Return each tap's brush, by Cp on [-2, 2] (grey where Cp is not defined)."""
        return [self._palette[i] for i in self._tap_levels(cp).tolist()]
