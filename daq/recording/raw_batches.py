"""The raw rows of every device, buffered between the writer's appends.

Responsibility: :class:`RawBatches` keeps each device's raw rows (host times, device times,
counters, values and extra columns) as they arrive, block by block, and appends them to the
recorder in one batch per device when asked (:meth:`RawBatches.write`). Appending per block
costs ~0.1 ms per dataset in h5py: a few hundred blocks per second times ~8 datasets would
take longer than the run. Batching bounds it.

Not responsible for: when to write (:class:`daq.recording.writer.RunWriter`, every
``write_interval_s``) or the file (:mod:`daq.recording.recorder`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from daq.acquisition.records import StreamBlock
from daq.recording.recorder_protocol import Recorder

__all__ = ["RawBatches"]


class RawBatches:
    """Raw rows per device, waiting for the next append."""

    def __init__(self) -> None:
        self._raw: dict[str, list[tuple[Any, Any, Any, Any, dict[str, Any]]]] = {}

    def add(self, device: str, block: StreamBlock, values: Any,
            extra: Mapping[str, Any]) -> None:
        """Keep a block's rows: its times and counters, ``values`` (n, ch), ``extra``."""
        n = len(block)
        t_dev = (np.full(n, np.nan) if block.device_time is None
                 else np.asarray(block.device_time, dtype=np.float64))
        self._raw.setdefault(device, []).append(
            (np.asarray(block.host_time_ns, dtype=np.int64), t_dev,
             np.asarray(block.counter, dtype=np.int64), np.asarray(values),
             {k: np.asarray(v) for k, v in extra.items()}))

    def write(self, rec: Recorder) -> None:
        """Append every device's rows kept so far, one batch per device; forget them."""
        for name, parts in self._raw.items():
            if not parts:
                continue
            host = np.concatenate([p[0] for p in parts])
            t_dev = np.concatenate([p[1] for p in parts])
            counter = np.concatenate([p[2] for p in parts])
            values = np.concatenate([p[3] for p in parts])
            extra = {k: np.concatenate([p[4][k] for p in parts]) for k in parts[0][4]}
            rec.append_raw(name, host, t_dev, counter, values, extra=extra)
            parts.clear()
