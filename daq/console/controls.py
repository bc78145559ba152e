"""The operator control panel of the live console: fan, arm/release, CALZ, markers, recording.

Responsibility: one :class:`ControlPanel` widget over a live source (``source.acq`` is the
:class:`~daq.acquisition.engine.Acquisition` engine or its proxy in the acquisition process,
``source.fan_speed_rpm`` and ``source.plc_armed`` the last readings). Its
:meth:`ControlPanel.refresh` (called from the window's timer) tells the console's interlocks
(:class:`~daq.console.interlocks.Interlocks`, pure and Qt-free) what it sees, and disables the
actions they refuse, with their reason as the tooltip and in the status line (e.g.
``"release: arm first"``). Every action is one of the engine's commands (``set_fan_speed``,
``start_fan``, ``stop_fan``, ``arm``, ``release``, ``manual_release``, ``manual_hold``, ``calz``,
``mark``), so each is recorded as an event of the run. A rig without a PLC is released by hand:
the operator lets the model go, then clicks "released" (the instant is found in the lasers'
signals before the click), and clicks "held" once it is caught and held still again (a rig with
a PLC shows its arm and release buttons, one without shows these two instead). Actions
that can block (fan start, arm, release, CALZ) run one at a time on a
plain worker thread; the result comes back to the GUI thread through a Qt signal and any error
(``SafetyError``, ``DeviceError``, ...) is shown in the status line. Stopping the fan is one
register write and runs at once on the GUI thread (a stop must never queue behind a running
action). The release asks for confirmation through an injectable
``confirm(title, question) -> bool`` (a ``QMessageBox`` by default).

The recording row starts and stops a run file through the source's
:meth:`~daq.console.live_source.LiveSource.start_recording` / ``stop_recording`` (which hand the
work to the engine's dispatcher thread and wait for it, well under a second, so they run on the GUI
thread); its label shows the file and the elapsed time, or why the last recording stopped.

Not responsible for: the rules themselves (:mod:`daq.console.interlocks`), the drivers' own
safety checks (the fan limit, ARM before RELEASE, CALZ wind-off are enforced there as well),
drawing, or writing files (:mod:`daq.console.live_source`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtWidgets

from daq.console.interlocks import CALZ_WIND_WINDOW_S, ConsoleState, Interlocks

__all__ = ["ControlPanel", "ask_user", "suggest_run_name"]

log = logging.getLogger(__name__)

#: How long closing the panel waits for a running action, s.
_JOIN_S = 35.0


def suggest_run_name(now: float | None = None) -> str:
    """Suggest a run file name from the local time: ``run_YYYYmmdd_HHMMSS.h5``.

    Parameters
    ----------
    now : float, optional
        Wall-clock time, s since the epoch (``time.time()``); default now.
    """
    return time.strftime("run_%Y%m%d_%H%M%S.h5", time.localtime(now))


def ask_user(title: str, question: str) -> bool:
    """Ask a yes/no question in a modal message box (the default ``confirm``)."""
    answer = QtWidgets.QMessageBox.question(
        None, title, question,
        QtWidgets.QMessageBox.StandardButton.Yes | QtWidgets.QMessageBox.StandardButton.No,
        QtWidgets.QMessageBox.StandardButton.No)
    return bool(answer == QtWidgets.QMessageBox.StandardButton.Yes)


class ControlPanel(QtWidgets.QGroupBox):
    """Operator controls over a live source (see the module docstring).

    Parameters
    ----------
    source : LiveSource
        An opened live source: ``acq``, ``info.config``, ``fan_speed_rpm``, ``plc_armed`` and
        ``snapshot(last)``.
    confirm : callable, optional
        ``confirm(title, question) -> bool`` for dangerous actions; default :func:`ask_user`.
    record_dir : str or Path, optional
        Directory of the suggested run files, and of a relative file name typed; default the
        source's ``record_dir`` if it has one, else the current directory.
    parent : QWidget, optional
        Qt parent.

    Attributes
    ----------
    fan_spin : QDoubleSpinBox
        The fan setpoint, rpm, within [0, ``[limits] max_fan_rpm``].
    fan_actual : QLabel
        The fan's actual speed as last read from the drive, rpm.
    buttons : dict of str to QPushButton
        ``fan_apply``, ``fan_stop``, ``arm``, ``release``, ``calz``, ``mark``, ``record``,
        ``stop_record``.
    note_edit : QLineEdit
        The text of the next event marker.
    file_edit : QLineEdit
        The run file to record: a name in ``record_dir``, or a path.
    run_notes_edit : QLineEdit
        The operator notes stored with the next recording.
    record_label : QLabel
        The file being recorded and the elapsed time (or the last recording's failure).
    record_dir : Path
        Where run files are suggested.
    reasons : dict of str to str
        Why each disabled button is disabled (``"release: arm first"``); absent when enabled.
    """

    #: (action, error text or None, result): posted from the worker thread.
    finished = QtCore.Signal(str, object, object)

    def __init__(self, source: Any, *, confirm: Callable[[str, str], bool] | None = None,
                 record_dir: str | Path | None = None,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("controls", parent)
        self._source = source
        self._confirm = ask_user if confirm is None else confirm
        config = source.info.config
        self._max_rpm = float(config.limits.max_fan_rpm)
        fans = config.by_role("fan")
        plcs = config.by_role("plc")
        scanners = config.by_role("scanner")
        self._fan_name: str | None = fans[0].name if fans else None
        self._plc_name: str | None = plcs[0].name if len(plcs) == 1 else None
        self._scanner_name: str | None = scanners[0].name if scanners else None
        self._worker: threading.Thread | None = None
        self._busy: str | None = None
        #: The ARM state the panel's own commands left, with their host time (ns).
        self._own_armed: tuple[int, bool] | None = None
        self._fan_commanded = False
        self._interlocks = Interlocks()
        self.reasons: dict[str, str] = {}
        self._message = ""

        outer = QtWidgets.QVBoxLayout(self)
        layout = QtWidgets.QHBoxLayout()
        outer.addLayout(layout)
        layout.addWidget(QtWidgets.QLabel("fan (rpm)"))
        self.fan_spin = QtWidgets.QDoubleSpinBox()
        self.fan_spin.setDecimals(0)
        self.fan_spin.setRange(0.0, self._max_rpm)
        self.fan_spin.setSingleStep(50.0)
        self.fan_spin.setToolTip(f"fan speed setpoint, 0..{self._max_rpm:g} rpm "
                                 "([limits] max_fan_rpm)")
        layout.addWidget(self.fan_spin)
        self.fan_actual = QtWidgets.QLabel("actual - rpm")
        self.fan_actual.setToolTip("the fan's actual speed, read back from the drive (Actual 1)")
        layout.addWidget(self.fan_actual)
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        for key, text, slot in (("fan_apply", "apply", self._on_apply),
                                ("fan_stop", "stop fan", self.stop_fan),
                                ("arm", "arm", self.arm),
                                ("release", "release", self.release),
                                ("hand_release", "released", self.hand_release),
                                ("hand_hold", "held", self.hand_hold),
                                ("calz", "CALZ", self.calz)):
            button = QtWidgets.QPushButton(text)
            button.clicked.connect(slot)
            self.buttons[key] = button
            layout.addWidget(button)
        # Only the release buttons the rig can use are shown (a PLC's, or the hand's): all
        # four would widen the console past 800 px.
        by_plc = self._plc_name is not None
        for key in ("arm", "release"):
            self.buttons[key].setVisible(by_plc)
        for key in ("hand_release", "hand_hold"):
            self.buttons[key].setVisible(not by_plc)
        self.note_edit = QtWidgets.QLineEdit()
        self.note_edit.setPlaceholderText("event note")
        self.note_edit.returnPressed.connect(self._on_mark)
        layout.addWidget(self.note_edit, 1)
        mark = QtWidgets.QPushButton("mark")
        mark.clicked.connect(self._on_mark)
        self.buttons["mark"] = mark
        layout.addWidget(mark)
        outer.addLayout(self._recording_row(record_dir))
        # Tight rows: the recording row must not make the console taller than it was (its
        # window still fits 800 x 600).
        outer.setSpacing(0)
        margins = outer.contentsMargins()
        outer.setContentsMargins(margins.left(), 2, margins.right(), 0)
        self.status_label = QtWidgets.QLabel("")
        self.status_label.setWordWrap(True)
        outer.addWidget(self.status_label)
        self.finished.connect(self._on_finished)
        self.refresh()

    # -- state -----------------------------------------------------------------------------------
    @property
    def status_text(self) -> str:
        """The status line as shown."""
        return str(self.status_label.text())

    @property
    def busy(self) -> str | None:
        """The action running on the worker thread, if any."""
        return self._busy

    def armed(self) -> bool | None:
        """Tell whether the PLC is armed: the newer of its last reading and the panel's command."""
        reading = self._source.plc_armed
        own = self._own_armed
        if reading is None:
            return None if own is None else own[1]
        if own is None or reading[0] > own[0]:
            return reading[1]
        return own[1]

    def refresh(self) -> None:
        """Re-evaluate which actions are allowed now; disable the others with the reason.

        The rules are :class:`~daq.console.interlocks.Interlocks`'; the panel only tells them
        the state it sees and shows their answer.
        """
        acq = self._source.acq
        running = acq is not None and bool(acq.running)
        drivers = acq.drivers if running else {}
        can_record = callable(getattr(self._source, "start_recording", None))
        rec = self._source.recording if can_record else None
        state = ConsoleState(
            running=running, busy=self._busy,
            has_fan=self._fan_name is not None and self._fan_name in drivers,
            has_plc=self._plc_name is not None and self._plc_name in drivers,
            has_scanner=self._scanner_name is not None and self._scanner_name in drivers,
            fan_rpm=float(self._source.fan_speed_rpm), fan_commanded=self._fan_commanded,
            armed=self.armed() if self._plc_name is not None and self._plc_name in drivers
            else None,
            wind_m_s=self._wind, can_record=can_record,
            recording=rec is not None and rec.error is None)
        actual = float(self._source.fan_speed_rpm)
        self.fan_actual.setText("actual - rpm" if math.isnan(actual)
                                else f"actual {actual:.0f} rpm")
        reasons = self._interlocks.refusals(state, time.monotonic())
        self._show_recording(can_record, rec)
        self.reasons = reasons
        for key, button in self.buttons.items():
            why = reasons.get(key)
            button.setEnabled(why is None)
            button.setToolTip(why or "")
        self.fan_spin.setEnabled("fan_apply" not in reasons)
        self.note_edit.setEnabled("mark" not in reasons)
        self.file_edit.setEnabled("record" not in reasons)
        self.run_notes_edit.setEnabled("record" not in reasons)
        self._show()

    # -- actions ---------------------------------------------------------------------------------
    def apply_fan(self, rpm: float) -> None:
        """Set the fan speed to ``rpm`` and run the fan (on the worker thread).

        The driver refuses a speed outside [0, max_fan_rpm] (``SafetyError``, shown).
        """
        acq = self._fan_acq("fan")
        if acq is None:
            return
        name = self._fan_name

        def run() -> str:
            acq.set_fan_speed(float(rpm), name)  # through the engine: each an event of the run
            acq.start_fan(name)
            return f"fan set to {float(rpm):.0f} rpm"

        if 0.0 <= rpm <= self._max_rpm:  # the setpoint shown is the one commanded
            self.fan_spin.setValue(float(rpm))
        self._fan_commanded = True
        self._submit("fan", run)

    def stop_fan(self) -> None:
        """Stop the fan now (one register write, on the GUI thread)."""
        acq = self._fan_acq("fan")
        if acq is None:
            return
        try:
            acq.stop_fan(self._fan_name)
        except Exception as exc:  # shown, never swallowed
            self._set_message(f"fan stop failed: {type(exc).__name__}: {exc}")
        else:
            self._fan_commanded = False
            self._set_message("fan stopped")
        self.refresh()

    def arm(self) -> None:
        """Arm the PLC (magnet on, one release permitted), on the worker thread."""
        acq = self._acq("arm")
        if acq is not None:
            self._submit("arm", lambda: acq.arm(self._plc_name))

    def release(self, *, confirmed: bool = False) -> None:
        """Release the model after confirmation (on the worker thread).

        Parameters
        ----------
        confirmed : bool
            The operator has agreed already (the automatic releases of a simulated session,
            :mod:`daq.console.auto_release`): do not ask.
        """
        acq = self._acq("release")
        if acq is None:
            return
        if not confirmed and not self._confirm("release", "Release the model now?"):
            self._set_message("release: cancelled")
            return
        self._submit("release", lambda: acq.release(self._plc_name))

    def hand_release(self) -> None:
        """Say the model was let go by hand (no PLC): the engine's ``manual_release``.

        The release instant is found in the lasers' signals before the click by the run
        writer (:mod:`daq.recording.releases`); the releases table gets it from there.
        """
        acq = self._acq("hand_release")
        if acq is not None:
            self._submit("hand_release", lambda: self._by_hand("release", acq.manual_release))

    def hand_hold(self) -> None:
        """Say the model is caught and held by hand again: the engine's ``manual_hold``."""
        acq = self._acq("hand_hold")
        if acq is not None:
            self._submit("hand_hold", lambda: self._by_hand("hold", acq.manual_hold))

    def _by_hand(self, what: str, say_so: Callable[[], Any]) -> Any:
        """Say what the operator's hand did; on a simulated rig its simulated hand does it first.

        The simulated hand (``source.simulated_hand``) acts only on a simulated rig (``windrig
        gui --simulate``); on a real rig it does nothing, and a replay has none.
        """
        hand = getattr(self._source, "simulated_hand", None)
        if callable(hand):
            hand(what)
        return say_so()

    def calz(self) -> None:
        """Zero the scanner (CALZ) with the fan stopped and settled and the wind off."""
        self.refresh()
        why = self.reasons.get("calz")
        if why is not None:
            self._set_message(why)
            return
        acq = self._acq("CALZ")
        if acq is None:
            return
        name = self._scanner_name

        def run() -> str:
            # Wind off checked above (measured < CALZ_MAX_WIND, fan stopped). The engine pauses
            # the scan (the scanner takes no command while scanning); the pause is a marked gap.
            result = acq.calz(name, wind_speed_now=0.0)
            offsets = np.abs(result.offsets_before_pa)
            largest = float(np.nanmax(offsets)) if np.isfinite(offsets).any() else math.nan
            return (f"scanner zeroed; scan paused {result.pause_s:.2f} s, largest zero offset "
                    f"removed {largest:.2f} Pa")

        self._submit("calz", run)

    def mark(self, text: str) -> None:
        """Record an operator ``"note"`` event with ``text`` (immediate: no I/O)."""
        acq = self._acq("mark")
        if acq is None:
            return
        try:
            acq.mark("note", text)
        except Exception as exc:
            self._set_message(f"mark failed: {type(exc).__name__}: {exc}")
        else:
            self._set_message(f"marked: {text!r}")

    def record(self) -> None:
        """Start recording to the file typed (in ``record_dir`` unless a path), with the notes.

        Refused (reason in the status line) when the current state does not allow it; the
        source's refusals (an existing file, a missing or read-only directory, ...) are shown.
        """
        self.refresh()
        why = self.reasons.get("record")
        if why is not None:
            self._set_message(why)
            return
        path = self.record_path()
        if path is None:
            self._set_message("record: type a file name first")
            return
        try:
            started = self._source.start_recording(path, self.run_notes_edit.text())
        except Exception as exc:  # StorageError, RecordingError, ...: shown, never swallowed
            log.warning("record to %s refused: %s", path, exc)
            self._set_message(f"record failed: {type(exc).__name__}: {exc}")
        else:
            self._set_message(f"recording to {started}")
        self.refresh()

    def stop_record(self) -> None:
        """Stop the recording: the file is finished and closed; its summary is shown."""
        self.refresh()
        why = self.reasons.get("stop_record")
        if why is not None:
            self._set_message(why)
            return
        try:
            summary = self._source.stop_recording()
        except Exception as exc:  # RecordingError, StorageError: shown, never swallowed
            log.error("stop recording failed: %s", exc)
            self._set_message(f"stop recording failed: {type(exc).__name__}: {exc}")
        else:
            self._set_message(
                f"recorded {summary.get('file', '?')}: {float(summary.get('duration_s', 0.0)):.1f}"
                f" s, {summary.get('sync_rows', 0)} sync rows, "
                f"{summary.get('releases', 0)} release(s)")
            self.file_edit.setText(suggest_run_name())  # the next run gets a new name
        self.refresh()

    def record_path(self) -> Path | None:
        """Return the run file typed, resolved against ``record_dir``; None when empty."""
        text = self.file_edit.text().strip()
        if not text:
            return None
        path = Path(text).expanduser()
        return path if path.is_absolute() else self.record_dir / path

    def shutdown(self, timeout_s: float = _JOIN_S) -> None:
        """Wait for a running action to finish (before the source closes)."""
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.join(timeout_s)

    # -- internals -------------------------------------------------------------------------------
    def _recording_row(self, record_dir: str | Path | None) -> QtWidgets.QHBoxLayout:
        """Build the recording row: file name, notes, record / stop, file and elapsed time."""
        if record_dir is None:
            record_dir = getattr(self._source, "record_dir", None)
        self.record_dir = Path.cwd() if record_dir is None else Path(record_dir)
        self._reported_failure: Any = None
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("run file"))
        self.file_edit = QtWidgets.QLineEdit(suggest_run_name())
        self.file_edit.setToolTip(f"the HDF5 run file to record: a name in {self.record_dir}, "
                                  "or a path")
        row.addWidget(self.file_edit, 2)
        self.run_notes_edit = QtWidgets.QLineEdit()
        self.run_notes_edit.setPlaceholderText("run notes")
        self.run_notes_edit.setToolTip("operator notes stored with the run file")
        row.addWidget(self.run_notes_edit, 3)
        for key, text, slot in (("record", "record", self.record),
                                ("stop_record", "stop recording", self.stop_record)):
            button = QtWidgets.QPushButton(text)
            button.clicked.connect(slot)
            self.buttons[key] = button
            row.addWidget(button)
        self.record_label = QtWidgets.QLabel("not recording")
        row.addWidget(self.record_label, 2)
        return row

    def _show_recording(self, can_record: bool, rec: Any) -> None:
        """Show the recording in its label (and a recording's failure once in the status)."""
        if not can_record:
            self.record_label.setText("")
            return
        if rec is not None and rec.error is None:
            self.record_label.setText(f"recording {rec.path.name} ({_clock(rec.elapsed_s())})")
            self.record_label.setToolTip(str(rec.path))
            return
        if rec is None:
            self.record_label.setText("not recording")
            self.record_label.setToolTip("")
            return
        # The recording stopped by itself (e.g. the disk filled up): say so once in the status
        # line; the label keeps it until the next recording.
        self.record_label.setText(f"recording {rec.path.name} FAILED")
        self.record_label.setToolTip(f"{rec.path}: {rec.error}")
        if self._reported_failure is not rec:
            self._reported_failure = rec
            self._message = f"recording to {rec.path} failed: {rec.error}"

    def _on_apply(self) -> None:
        self.apply_fan(self.fan_spin.value())

    def _on_mark(self) -> None:
        text = self.note_edit.text().strip()
        if not text:
            self._set_message("mark: type a note first")
            return
        self.mark(text)
        self.note_edit.clear()

    def _acq(self, what: str) -> Any:
        acq = self._source.acq
        if acq is None or not acq.running:
            self._set_message(f"{what}: acquisition not running")
            return None
        return acq

    def _fan_acq(self, what: str) -> Any:
        """Return the engine, if it runs and the rig has a fan (else say why, return None)."""
        acq = self._acq(what)
        if acq is None:
            return None
        if self._fan_name is None or self._fan_name not in acq.drivers:
            self._set_message(f"{what}: no fan in this rig")
            return None
        return acq

    def _submit(self, action: str, job: Callable[[], Any]) -> None:
        if self._busy is not None:
            self._set_message(f"{action}: busy ({self._busy})")
            return
        self._busy = action
        self._set_message(f"{action}: running ...")

        def run() -> None:
            try:
                result = job()
            except Exception as exc:  # posted to the GUI thread, shown there
                error: str | None = f"{type(exc).__name__}: {exc}"
                result = None
            else:
                error = None
            try:
                self.finished.emit(action, error, result)
            except RuntimeError:  # the panel is gone (closed while the action ran)
                pass

        self._worker = threading.Thread(target=run, name=f"console-{action}", daemon=True)
        self._worker.start()
        self.refresh()

    def _on_finished(self, action: str, error: object, result: object) -> None:
        self._busy = None
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.join(1.0)  # it has emitted: it ends now
        now = time.monotonic_ns()
        if error is not None:
            if action == "fan":
                self._fan_commanded = False
            self._set_message(f"{action} failed: {error}")
        else:
            if action == "arm":
                self._own_armed = (now, True)
            elif action == "release":
                self._own_armed = (now, False)
            text = result if isinstance(result, str) else getattr(result, "text", "")
            self._set_message(f"{action}: done" + (f" ({text})" if text else ""))
        if action == "release" and error is not None:
            self._own_armed = None  # unknown: trust the next PLC reading
        self.refresh()

    @property
    def message(self) -> str:
        """The last action's message (the status line without the reasons)."""
        return self._message

    def show_message(self, text: str) -> None:
        """Show ``text`` in the panel's status line (before the reasons)."""
        self._set_message(text)

    def _set_message(self, text: str) -> None:
        self._message = text
        self._show()

    def _show(self) -> None:
        parts = [self._message] if self._message else []
        # "stop recording: not recording" is the idle state, which the recording label shows
        # already: the status line keeps to the other reasons (and stays one line shorter).
        parts += [why for key, why in self.reasons.items() if key != "stop_record"]
        self.status_label.setText("  |  ".join(dict.fromkeys(parts)))

    def _wind(self) -> float:
        """Return the median measured wind speed over the last ``CALZ_WIND_WINDOW_S``, m/s."""
        rows = max(1, int(CALZ_WIND_WINDOW_S * float(self._source.info.rate_hz)))
        try:
            wind = self._source.snapshot(rows, columns=("U",))["U"]
        except RuntimeError:
            return math.nan
        wind = wind[np.isfinite(wind)]
        return float(np.median(wind)) if wind.size else math.nan


def _clock(seconds: float) -> str:
    """Format a duration as ``h:mm:ss`` (the recording's elapsed time)."""
    minutes, secs = divmod(max(int(seconds), 0), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"
