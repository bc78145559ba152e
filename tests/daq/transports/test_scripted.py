"""The scripted transports themselves (:mod:`daq.transports.scripted`).

The scripted-exchange harness must catch wrong, missing and extra bytes.
"""

from __future__ import annotations

import pytest

from daq.errors import TransportTimeout
from daq.transports.scripted import ScriptedTransport, expected_exchange


def test_a_complete_exchange_passes():
    """Writes matching the script release the replies, in order."""
    with expected_exchange([(b"", b"HELLO\r\n"), (b"SEND\r\n", b"1013.2\r\n")]) as t:
        assert t.read_until(b"\r\n", 1.0) == b"HELLO\r\n"
        t.write(b"SE")
        with pytest.raises(TransportTimeout):
            t.read(1, 0.1)  # no reply before the command is complete
        t.write(b"ND\r\n")
        assert t.read_until(b"\r\n", 1.0) == b"1013.2\r\n"


def test_wrong_bytes_fail_immediately_with_hex():
    """A byte that differs from the script fails at once and shows both sides."""
    t = ScriptedTransport([(b"SCAN\r\n", b"")])
    t.open()
    with pytest.raises(AssertionError, match=r"expected b'SCAN\\r\\n' \(53 43 41 4e 0d 0a\)"):
        t.write(b"STOP\r\n")


def test_unplayed_script_or_unread_reply_fails_on_exit():
    """Leaving an exchange undone, or a reply unread, is a failure."""
    with pytest.raises(AssertionError, match="1 of 2 exchanges done"):
        with expected_exchange([(b"A", b""), (b"B", b"")]) as t:
            t.write(b"A")
    with pytest.raises(AssertionError, match="reply bytes never read"):
        with expected_exchange([(b"A", b"ok")]) as t:
            t.write(b"A")
