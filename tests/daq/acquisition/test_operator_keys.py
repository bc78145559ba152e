"""The operator's keys during a recording (daq.acquisition.operator_keys), on a real engine.

An :class:`~daq.acquisition.engine.Acquisition` runs with one polled barometer-like device
(the engine needs a device; the keys need none, as on a rig without a PLC); the keys come from
a text stream as a terminal gives them, line by line. Each becomes the engine's event (a
subscriber collects them); ``q`` sets the recorder's ``until``.
"""

from __future__ import annotations

import io
import threading
from typing import Any

import pytest

from daq.acquisition.engine import Acquisition
from daq.acquisition.operator_keys import KEYS_HELP, OperatorKeys
from daq.instruments.reading import PollSequence, Reading

pytestmark = pytest.mark.realtime


class Barometer:
    """A polled device that only answers reads (the reading contract's poll sequence)."""

    def __init__(self) -> None:
        self.polls = PollSequence()

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def read(self) -> Reading:
        return self.polls.reading(self.polls.next(), {"pressure": 101325.0},
                                  {"pressure": "float64"})


def _engine(**kw: Any) -> Acquisition:
    return Acquisition({"barometer": ("barometer", Barometer())}, read_timeout_s=0.05,
                       join_timeout_s=1.0, **kw)


def test_each_key_becomes_the_engines_event():
    seen: list[Any] = []
    arrived = threading.Event()

    def collect(name: str, doc: Any) -> None:
        if name == "event" and doc.kind.startswith("manual_"):
            seen.append(doc)
            if len(seen) == 3:
                arrived.set()

    acq = _engine(subscribers=[collect])
    acq.start()
    said: list[str] = []
    until = threading.Event()
    keys = OperatorKeys(io.StringIO("\nh\nR\nx\nq\n"), say=said.append, until=until)
    try:
        keys.start(acq)
        assert keys.join(5.0)
        assert arrived.wait(5.0)  # the dispatcher delivered them
    finally:
        acq.stop()
    assert [e.kind for e in seen] == ["manual_release", "manual_hold", "manual_release"]
    assert keys.counts == {"release": 2, "hold": 1}
    assert until.is_set()
    assert said[0].startswith("release 1: recorded") and said[1].startswith("model held")
    assert said[3] == f"unknown key 'x': {KEYS_HELP}" and said[4] == "ending the recording"


def test_keys_after_the_engine_stopped_are_ignored():
    acq = _engine()
    acq.start()
    acq.stop()
    keys = OperatorKeys(io.StringIO("\n"), say=lambda line: None)
    keys.start(acq)
    assert keys.join(5.0) and keys.counts == {"release": 0, "hold": 0}
