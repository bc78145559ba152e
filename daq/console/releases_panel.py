"""The console's releases views: the releases table and the flutter derivatives.

Responsibility: two widgets that show what a :class:`~daq.console.live_ident.LiveIdentifier` holds.
:class:`ReleasesPanel` is the table (one row per release: time, wind speed, length, frequency
and damping ratio of the heave- and pitch-dominated modes, status) over a line saying what the
E2RFC part is doing (waiting for a second wind speed, identifying, the predicted flutter speed).
:class:`DerivativesPanel` plots the identified model's flutter derivatives ``H1*..A4*``
against ``1/K`` with the indirect method's table values from the same decays as points. Both
are redrawn by the window when the identifier reports a change; they hold no state of their own.

Not responsible for: the fits (:mod:`daq.console.live_ident`) or the window
(:mod:`daq.console.window`).
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from daq.console.live_ident import LiveIdentifier, ReleaseRow
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES

__all__ = ["RELEASE_COLUMNS", "DerivativesPanel", "ReleasesPanel"]

#: Columns of the releases table.
RELEASE_COLUMNS = ("#", "t (s)", "U (m/s)", "length (s)", "f_h (Hz)", "zeta_h", "f_a (Hz)",
                   "zeta_a", "status")
#: The derivatives of the heave column of Q, measured by the table at K_h (the others at K_a).
_HEAVE_COLUMN = {"H1", "H4", "A1", "A4"}


def _cells(row: ReleaseRow) -> tuple[str, ...]:
    """Return the table cells of one release (blank where not known yet)."""
    def num(value: float, fmt: str) -> str:
        return "" if not math.isfinite(value) else format(value, fmt)

    modal = row.modal
    modes = ("", "", "", "") if modal is None else (
        num(modal.f_h, ".3f"), num(modal.zeta_h, ".2%"), num(modal.f_a, ".3f"),
        num(modal.zeta_a, ".2%"))
    return (str(row.number), f"{row.release_s:.1f}", num(row.U, ".2f"), num(row.length_s, ".1f"),
            *modes, row.status)


class ReleasesPanel(QtWidgets.QGroupBox):
    """The releases table and the E2RFC status line, titled ``releases (n)``.

    Attributes
    ----------
    table : QTableWidget
        One row per release (columns :data:`RELEASE_COLUMNS`), newest last.
    model_label : QLabel
        The identifier's ``campaign_status``: why there is no model yet, or the predicted
        flutter speed.
    """

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("releases", parent)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        self.table = QtWidgets.QTableWidget(0, len(RELEASE_COLUMNS))
        self.table.setHorizontalHeaderLabels(list(RELEASE_COLUMNS))
        self.table.verticalHeader().setVisible(False)
        self.table.verticalHeader().setDefaultSectionSize(17)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        # about six rows: the traces above keep the height (the table scrolls to the newest)
        self.table.setMaximumHeight(150)
        self.table.setMinimumHeight(40)  # a small window (800 x 600) keeps its size
        layout.addWidget(self.table, 1)
        self.model_label = QtWidgets.QLabel("")
        self.model_label.setWordWrap(True)
        layout.addWidget(self.model_label)

    def show_rows(self, ident: LiveIdentifier) -> None:
        """Fill the table and the status line from the identifier."""
        table = self.table
        table.setRowCount(len(ident.rows))
        grey = pg.mkColor(150, 150, 150)
        for r, row in enumerate(ident.rows):
            for c, text in enumerate(_cells(row)):
                item = table.item(r, c)
                if item is None:
                    item = QtWidgets.QTableWidgetItem()
                    table.setItem(r, c, item)
                item.setText(text)
                if row.usable:
                    item.setData(QtCore.Qt.ItemDataRole.ForegroundRole, None)
                else:  # listed, but not part of the model
                    item.setForeground(grey)
        if ident.rows:
            table.scrollToBottom()
        self.setTitle(f"releases ({len(ident.rows)})")
        self.model_label.setText(ident.campaign_status)

    def cell(self, row: int, column: str) -> str:
        """Return the text of one cell (``column`` one of :data:`RELEASE_COLUMNS`)."""
        item = self.table.item(row, RELEASE_COLUMNS.index(column))
        return "" if item is None else str(item.text())


class DerivativesPanel(pg.GraphicsLayoutWidget):
    """Flutter derivatives of the identified model (lines) and the table values (points).

    Attributes
    ----------
    curves, points : dict of str to pyqtgraph item
        Per derivative name (``"H1"`` ... ``"A4"``): the model's curve and the table's points,
        both against ``1/K = U / (B omega)``.
    """

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.curves: dict[str, pg.PlotDataItem] = {}
        self.points: dict[str, pg.ScatterPlotItem] = {}
        for i, name in enumerate(FLUTTER_DERIVATIVE_NAMES):
            plot = self.addPlot(row=i // 4, col=i % 4, title=f"{name}*")
            plot.showGrid(x=True, y=True, alpha=0.3)
            for side in ("left", "bottom"):
                plot.getAxis(side).enableAutoSIPrefix(False)
            if i // 4 == 1:
                plot.setLabel("bottom", "1/K")
            self.curves[name] = plot.plot(pen=pg.mkPen("r", width=1.5))
            points = pg.ScatterPlotItem(size=7, brush=pg.mkBrush("c"), pen=None)
            plot.addItem(points)
            self.points[name] = points

    def show_fit(self, ident: LiveIdentifier) -> None:
        """Draw the identifier's latest model and table (clears both when there is none)."""
        fit = ident.campaign
        for name in FLUTTER_DERIVATIVE_NAMES:
            if fit is None:
                self.curves[name].setData([], [])
                self.points[name].setData([], [])
                continue
            self.curves[name].setData(1.0 / fit.K, fit.derivatives[name])
            table = fit.table
            if table is None:
                self.points[name].setData([], [])
                continue
            K = table.K_h if name in _HEAVE_COLUMN else table.K_a
            values = np.asarray(table.derivatives[name], dtype=float)
            ok = np.isfinite(values) & (K > 0)
            self.points[name].setData(1.0 / K[ok], values[ok])
