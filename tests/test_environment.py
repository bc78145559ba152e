"""Smoke tests of the environment: the Qt binding works offscreen; the CLI is installed."""

from __future__ import annotations

from importlib.metadata import entry_points

import numpy as np
import pyqtgraph as pg
import pytest
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

pytestmark = pytest.mark.realtime


def test_pyqtgraph_plots_offscreen(qapp: QApplication, qtbot: QtBot) -> None:
    widget = pg.PlotWidget()
    qtbot.addWidget(widget)  # pytest-qt closes and deletes it after the test
    x = np.linspace(0.0, 1.0, 100)
    curve = widget.plot(x, np.sin(2.0 * np.pi * x))
    widget.resize(320, 240)
    with qtbot.waitExposed(widget):
        widget.show()
    qapp.processEvents()

    x_data, y_data = curve.getData()
    assert len(x_data) == len(y_data) == 100
    assert widget.width() > 0
    assert widget.height() > 0


def test_console_script_windrig_is_installed() -> None:
    scripts = {ep.name: ep for ep in entry_points(group="console_scripts")}
    assert "windrig" in scripts, "not installed: run `pip install -e .` (make does it)"
    assert scripts["windrig"].value == "daq.cli:main"
