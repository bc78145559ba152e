"""Clocks that a test sets by hand."""

from __future__ import annotations


class ManualClock:
    """A monotonic clock the test sets by hand, s: ``clock.now = 105.0``, then ``clock()``."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now
