"""PTB330 driver against its simulator over real transports (pyserial socket:// and a pty).

The driver (daq/) and the simulator (simulators/) encode and decode the wire format with separate
code; agreement here cross-checks both against the manual facts of docs/reference/wire_formats.md,
"Barometer". Faults are the barometer's of docs/reference/wire_formats.md, "Faults": garbled or
partial line, no reply, unit change.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from daq.errors import ProtocolError, TransportTimeout
from daq.instruments.vaisala_ptb330.decoder import Ptb330Line, Ptb330LineDecoder
from daq.instruments.vaisala_ptb330.driver import SERIAL_DEFAULTS, VaisalaPtb330
from daq.instruments.vaisala_ptb330.settings import Ptb330Settings
from daq.transports.byte_transport import open_transport
from ident import TapLayout
from ident.model import flat_plate
from simulators.devices.vaisala_ptb330 import SimVaisalaPtb330
from simulators.virtual_tunnel import AirState, VirtualTunnel

from support.sections import FLAT_PLATE

pytestmark = pytest.mark.realtime

TAPS = TapLayout.rectangle(0.3, 0.01, 16)
TRANSPORTS = ["socket", "pty"]


def tunnel():
    air = AirState(pressure_pa=98_500.0, temperature_k=296.4)
    return VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TAPS, wind_per_rpm=0.01, air=air)


def connect(url, **settings):
    # The simulator answers within milliseconds; 0.1 s keeps fault tests short.
    settings.setdefault("timeout_s", 0.1)
    return VaisalaPtb330(open_transport(url, **SERIAL_DEFAULTS), Ptb330Settings(**settings))


def assert_matches_truth(reading, truth):
    """Check a reading against the simulator's measured value, up to the printed rounding.

    Pressure: resolution_pa of the line; temperature: printed with 2 decimals (0.005 K, or
    0.005 'F = 0.0028 K).
    """
    assert reading.ok, reading.status
    assert abs(reading.pressure_pa - truth.pressure_pa) <= reading.resolution_pa * (1 + 1e-9)
    assert reading.temperature_k == pytest.approx(truth.temperature_k, abs=0.0051 * 5 / 9 + 0.0051)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_polled_readings_are_the_simulated_air(transport):
    vt = tunnel()
    with SimVaisalaPtb330(vt, rng=1) as sim, connect(sim.start(transport)) as drv:
        readings = [drv.measure() for _ in range(3)]
        stats = sim.stats
    intact = [t for t in sim.truth if not t.fault]
    assert stats["lines"] == stats["intact"] == 4  # the open check plus three reads
    for reading, truth in zip(readings, intact[1:], strict=True):
        assert_matches_truth(reading, truth)
        # noise 2 Pa, 0.02 K, drift < 0.01 Pa over the test: rho within 2e-4 relative
        assert reading.density_kg_m3 == pytest.approx(vt.air.density, rel=2e-4)
    assert [r.counter for r in readings] == [1, 2, 3]
    assert np.all(np.diff([r.host_time_ns for r in readings]) > 0)


def test_garbled_partial_and_missing_replies_are_retried_and_silence_raises():
    """Each simulated line fault costs one retry; a unit that stays silent raises TransportTimeout.

    Every reading is the simulator's next intact line, and the driver's error counts equal the
    faults the simulator injected; after the bounded attempts fail, the driver recovers.
    """
    with SimVaisalaPtb330(tunnel(), rng=2) as sim, connect(sim.start("pty")) as drv:
        readings = []
        for fault in ("garbled", "partial", "no_reply"):
            sim.inject(fault)
            readings.append(drv.measure())
        stats = sim.stats
        truth = list(sim.truth)
        assert (stats["garbled"], stats["partial"], stats["no_reply"]) == (1, 1, 1)
        assert drv.stats["protocol_errors"] == 2 and drv.stats["timeouts"] == 1
        assert drv.stats["reads"] == stats["intact"] == 4
        faults = [t.fault for t in truth]
        assert faults == ["", "garbled", "", "partial", "", "no_reply", ""]
        for reading, good in zip(readings, [truth[2], truth[4], truth[6]], strict=True):
            assert_matches_truth(reading, good)

        sim.inject("no_reply", count=3)
        start = time.monotonic()
        with pytest.raises(TransportTimeout, match="after 3 attempts"):
            drv.measure()
        # 3 timeouts of 0.1 s + backoffs 0.05 + 0.1 s; 0.5 s slack for a loaded machine
        assert time.monotonic() - start < 3 * 0.1 + 0.15 + 0.5
        after = drv.measure()
        assert after.counter == readings[-1].counter + 2  # the failed poll is a gap of 1
        assert_matches_truth(after, sim.truth[-1])


def test_unit_changes_are_followed_and_an_unknown_unit_never_gives_a_number():
    """The fault 'unit_change' (from the display) and UNIT over the line (PTB330 Table 13)."""
    with SimVaisalaPtb330(tunnel(), rng=4) as sim:
        url = sim.start("pty")
        raw = open_transport(url, **SERIAL_DEFAULTS)
        raw.open()
        try:
            raw.write(b"UNIT P kPa\r")
            assert raw.read_until(b"P     : kPa\r\n", 1.0).endswith(b"kPa\r\n")
        finally:
            raw.close()
        with connect(url) as drv:
            assert drv.measure().pressure_unit == "kPa"
            for unit, t_unit in [("Pa", "'F"), ("mbar", "K"), ("mmHg", "'C"), ("inHg", "'F"),
                                 ("psi", "'C"), ("torr", "K"), ("bar", "'C")]:
                sim.inject("unit_change", unit=unit, temperature_unit=t_unit)
                reading = drv.measure()
                assert reading.pressure_unit == unit
                assert_matches_truth(reading, sim.truth[-1])
            sim.inject("unit_change", unit="mmH2O")
            with pytest.raises(ProtocolError, match="unknown pressure unit 'mmH2O'"):
                drv.measure()
            sim.inject("unit_change", unit="hPa")
            assert_matches_truth(drv.measure(), sim.truth[-1])
    assert sim.stats["unit_changes"] == 9


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_run_mode_stream_loses_no_line_the_simulator_did_not_drop(transport):
    """RUN mode, 10 s of device time (INTV 1 s, sped up 40x), seeded random faults.

    The decoder yields exactly the simulator's intact lines, in order, and flags damaged ones.
    """
    sim = SimVaisalaPtb330(tunnel(), time_scale=40.0, rng=6,
                           faults={"garbled": 0.15, "partial": 0.15, "no_reply": 0.1})
    with sim:
        raw = open_transport(sim.start(transport), **SERIAL_DEFAULTS)
        raw.open()
        decoder = Ptb330LineDecoder()
        items = []
        try:
            raw.write(b"RESET\r")
            assert raw.read_until(b"\r\n", 1.0) == b"PTB330 / 1.01\r\n"  # STOP-mode banner
            raw.write(b'FORM "P=" 6.3 P " " U6 "T=" 3.2 TP1 " " U3 #r #n\r')
            assert raw.read_until(b"\r\n", 1.0) == b"OK\r\n"
            raw.write(b"INTV 1 S\r")
            assert raw.read_until(b"\r\n", 1.0) == b"Output interval: 1 s\r\n"
            raw.write(b"R\r")  # start RUN output now (PTU300/DMT152 'R')
            # 10 lines (10 s of device time: 0.25 s when the host is idle), counted as the
            # simulator puts them out: a loaded host stalls its thread (it then resumes without
            # a burst) or delays the S below, so a fixed 0.25 s read gives fewer or more.
            deadline = time.monotonic() + 10.0
            while len(sim.truth) < 10:
                assert time.monotonic() < deadline, f"only {len(sim.truth)} lines in 10 s"
                try:
                    items += decoder.feed(raw.read(256, 0.05))
                except TransportTimeout:
                    pass
            raw.write(b"S\r")  # the one command RUN mode obeys
            # Then every line it wrote: until 0.1 s of silence that began once it had stopped
            # (its thread, stalled on a loaded host, may take S and write its last line late).
            deadline = time.monotonic() + 10.0
            while True:
                assert time.monotonic() < deadline, "RUN output not stopped within 10 s"
                stopped = not sim.running
                try:
                    items += decoder.feed(raw.read(256, 0.1))
                except TransportTimeout:
                    if stopped:
                        break
        finally:
            raw.close()
        assert not sim.running
        stats = sim.stats
    truth = list(sim.truth)
    # The 10 lines waited for, and those that came while S was on its way; never more than
    # one per 25 ms of the simulator's cadence (a line late by a stall may shorten the next
    # interval, never add a line: one interval of slack).
    assert len(truth) >= 10
    t_line = np.array([t.t_true for t in truth])
    assert (len(truth) - 2) * 0.025 - 1e-3 <= t_line[-1] - t_line[0], np.diff(t_line)
    intact = [t for t in truth if not t.fault]
    lines = [item for item in items if isinstance(item, Ptb330Line)]
    assert len(lines) == decoder.lines_ok == len(intact) == stats["intact"]
    # each decoded value is its truth line up to the printed rounding (0.0005 hPa)
    np.testing.assert_allclose([x.pressure_pa for x in lines], [t.pressure_pa for t in intact],
                               atol=0.05 + 1e-9)
    # Every damaged line is flagged; consecutive damaged lines may merge into one bad line
    # (a partial line runs into the next), and a final partial line stays pending.
    damaged = stats["garbled"] + stats["partial"]
    assert damaged >= 2 and stats["no_reply"] >= 1  # the seed does exercise every fault
    assert 1 <= decoder.lines_bad <= damaged


def test_driver_takes_over_a_streaming_unit_and_an_addressed_polled_unit():
    """open() stops RUN output (S); in POLL mode it needs the address (OPEN aa ... CLOSE)."""
    with SimVaisalaPtb330(tunnel(), mode="RUN", time_scale=20.0, rng=7) as sim:
        with connect(sim.start("pty")) as drv:
            assert not sim.running
            assert drv.measure().ok
    with SimVaisalaPtb330(tunnel(), mode="POLLED", address=7, rng=8) as sim:
        url = sim.start("pty")
        with pytest.raises(ProtocolError, match="pressure = "):
            connect(url).open()  # FORM ignored in POLL mode: factory lines come back
        with connect(url, address=7) as drv:
            assert_matches_truth(drv.measure(), sim.truth[-1])
        assert sim.form.startswith('"P="')
