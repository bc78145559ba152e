"""The operator's keys on the terminal during a recording: releases by hand, without a PLC.

Responsibility: :class:`OperatorKeys` reads lines from a text stream (the terminal's standard
input) in a daemon thread while an engine runs and turns each into one of the engine's
commands, so that each is an event of the run:

- Enter, or ``r`` then Enter: the model was let go by hand
  (:meth:`~daq.acquisition.engine.Acquisition.manual_release`; the run writer finds the
  release instant in the lasers' signals before the key);
- ``h``: the model is caught and held still again
  (:meth:`~daq.acquisition.engine.Acquisition.manual_hold`; ends the decay);
- ``q``: end the recording now (sets the ``until`` event the recorder waits on).

Anything else is answered with the list of keys. Lines, not single key strokes: a terminal
delivers a line on Enter without raw mode, and a script or a test can drive it through a pipe.

Not responsible for: finding the release (:mod:`daq.recording.releases`) or the recording
itself (:func:`daq.recording.run.record_run`, whose ``actions`` start the keys).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any, TextIO

__all__ = ["KEYS_HELP", "OperatorKeys"]

log = logging.getLogger(__name__)

#: The one line that tells the operator the keys.
KEYS_HELP = ("manual releases: let the model go by hand, then press Enter (or r Enter); "
             "h Enter once it is caught and held still; q Enter ends the recording")


class OperatorKeys:
    """Turn an operator's lines into manual-release commands of a running engine.

    Parameters
    ----------
    stream : text stream
        Where the lines come from (``sys.stdin``).
    say : callable
        Receives one line of feedback per key.
    until : threading.Event, optional
        Set by ``q`` (the recorder ends the run).
    hand : callable, optional
        ``hand("release")`` / ``hand("hold")`` before the command: a simulated rig's operator,
        who lets the model go through the virtual tunnel (there is no hand on a real rig).
    """

    def __init__(self, stream: TextIO, *, say: Callable[[str], None],
                 until: threading.Event | None = None,
                 hand: Callable[[str], Any] | None = None) -> None:
        self.stream = stream
        self.say = say
        self.until = until
        self.hand = hand
        #: Commands given so far, by kind (``"release"``, ``"hold"``).
        self.counts = {"release": 0, "hold": 0}
        self._thread: threading.Thread | None = None

    def start(self, acq: Any) -> None:
        """Read lines in a daemon thread until the stream ends or the engine stops.

        A daemon: a terminal's ``readline`` cannot be interrupted, and the run must end
        without waiting for one more line.
        """
        self._thread = threading.Thread(target=self._run, args=(acq,), daemon=True,
                                        name="windrig-operator-keys")
        self._thread.start()

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the stream to end (or the engine to stop); True once the reading ended."""
        if self._thread is None:
            return True
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def _run(self, acq: Any) -> None:
        while True:
            line = self.stream.readline()
            if not line:  # end of the stream: no more keys
                return
            if not acq.running:
                return
            try:
                self.key(acq, line.strip().lower())
            except RuntimeError as exc:  # the engine stopped between the check and the command
                log.info("operator key after the recording: %s", exc)
                return

    def key(self, acq: Any, key: str) -> None:
        """Act on one key (the stripped, lower-case line)."""
        if key in ("", "r"):
            if self.hand is not None:
                self.hand("release")
            acq.manual_release()
            self.counts["release"] += 1
            self.say(f"release {self.counts['release']}: recorded (the instant is found in the "
                     "lasers' signals); h Enter once the model is held again")
        elif key == "h":
            if self.hand is not None:
                self.hand("hold")
            acq.manual_hold()
            self.counts["hold"] += 1
            self.say("model held: the decay ends here")
        elif key == "q":
            if self.until is not None:
                self.until.set()
            self.say("ending the recording")
        else:
            self.say(f"unknown key {key!r}: {KEYS_HELP}")
