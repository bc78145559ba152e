"""The acquisition engine on the whole simulated flat-plate rig (real drivers, real transports).

Every instrument's reader runs against its simulator; a collecting subscriber checks that
blocks come from every device, that no counter is missing that the simulators did not drop
(checked against the simulators' own truth records), and that a release through the engine is
an event after which the lasers see the model move.
"""

from __future__ import annotations

import time
from collections import defaultdict
from typing import Any

import numpy as np
import pytest

from daq.acquisition.drivers import drivers_from_config
from daq.acquisition.engine import Acquisition
from daq.acquisition.records import Event, StreamBlock
from daq.config import parse_rig_config
from daq.sim.rig import start_simulated_rig

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

LASERS = ("laser_front", "laser_rear", "laser_check")


class Collector:
    def __init__(self) -> None:
        self.docs: list[tuple[str, Any]] = []

    def __call__(self, name: str, doc: Any) -> None:
        self.docs.append((name, doc))

    def blocks(self) -> dict[str, list[StreamBlock]]:
        out: dict[str, list[StreamBlock]] = defaultdict(list)
        for name, doc in self.docs:
            if name == "block":
                out[doc.device].append(doc)
        return out

    def events(self, kind: str) -> list[Event]:
        return [d for n, d in self.docs if n == "event" and d.kind == kind]


def test_engine_streams_the_whole_simulated_rig_and_records_a_release():
    # A fast fan ramp (a simulator option) keeps the test short.
    text = SIM_FLAT_PLATE.read_text() + \
        FAST_FAN
    config = parse_rig_config(text, "sim_flat_plate.toml")
    sink = Collector()
    with start_simulated_rig(config) as rig:
        acq = Acquisition(drivers_from_config(rig.config), subscribers=[sink],
                          metadata={"config": rig.config.text})
        with acq:
            fan = acq.drivers["fan"]  # operator commands go to the drivers while they stream
            fan.set_speed(300.0)
            fan.start()
            time.sleep(0.7)
            acq.arm("plc")
            release = acq.release("plc")
            time.sleep(0.8)

            def enough() -> bool:
                """Tell whether the data the checks below count has been delivered."""
                blocks = sink.blocks()
                after = [sum(int(np.count_nonzero(b.host_time_ns
                                                  > release.host_time_ns + 50_000_000))
                             for b in blocks[name]) for name in LASERS]
                return (len(blocks["fan"]) >= 10 and len(blocks["barometer"]) >= 1
                        and min(after) > 1000)

            deadline = time.monotonic() + 10.0
            while not enough():
                assert time.monotonic() < deadline, "too little data after the release in 10 s"
                time.sleep(0.05)
        summary = sink.docs[-1][1]
        truth = {name: rig.simulators[name].truth() for name in LASERS}
        scanner_sim = rig.simulators["scanner"]
        scan_sent = scanner_sim.truth.sent_counters(0, scanner_sim.scan_id)
        scan_dropped = scanner_sim.truth.dropped_counters(0, scanner_sim.scan_id)

    assert [n for n, _ in sink.docs][0] == "start" and sink.docs[-1][0] == "stop"
    assert summary["overflows"] == summary["faults"] == summary["events_dropped"] == 0
    assert summary["errors"] == [] and summary["threads_alive"] == []
    blocks = sink.blocks()
    assert set(blocks) == {inst.name for inst in config.instruments}  # every device delivered

    for device, device_blocks in blocks.items():
        assert [b.seq for b in device_blocks] == list(range(len(device_blocks))), device
        counter = np.concatenate([b.counter for b in device_blocks])
        assert [b.gaps for b in device_blocks if b.gaps] == [], device
        assert np.all(np.diff(counter) == 1), device  # continuous: no gap at all

    # ... and the simulators confirm it: every sample they put on the wire in that span came.
    scan = np.concatenate([b.counter for b in blocks["scanner"]])
    assert scan_dropped.size == 0
    span = scan_sent[(scan_sent >= scan[0]) & (scan_sent <= scan[-1])]
    assert np.array_equal(scan, span)
    for name in LASERS:
        got = np.concatenate([b.counter for b in blocks[name]])
        sent = truth[name].counter[truth[name].sent]  # no wrap in a few s (2**18 samples)
        assert np.array_equal(got, sent[(sent >= got[0]) & (sent <= got[-1])]), name

    # The release is an event with its host time; the lasers see the model move after it.
    (event,) = sink.events("release")
    assert event is release and event.device == "plc"
    assert [e.kind for e in sink.events("arm")] == ["arm"]
    for name in LASERS:
        t = np.concatenate([b.host_time_ns for b in blocks[name]])
        d = np.concatenate([b.values["distance"] for b in blocks[name]])
        before = d[t < event.data["requested_ns"]]
        after = d[t > event.host_time_ns + 50_000_000]
        assert before.size > 1000 and after.size > 1000, name
        # Held: noise of ~1 um. Released from h = 8 mm, alpha = 0.04 rad: millimetres.
        assert np.ptp(before) < 1e-4 and np.ptp(after) > 1e-3, name

    # The fan command went through while the drive was polled at 10 Hz.
    speed = np.concatenate([b.values["speed"] for b in blocks["fan"]])
    assert speed[0] < 1.0 and abs(speed[-1] - 300.0) < 1.0
    assert len(blocks["fan"]) >= 10 and len(blocks["barometer"]) >= 1
