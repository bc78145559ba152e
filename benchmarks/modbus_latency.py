"""Modbus round-trip latency and poll rates of the fan drive and PLC drivers (not a test).

The drivers talk to their simulators (pymodbus TCP servers on 127.0.0.1, each in its own thread and
asyncio loop) through :class:`daq.transports.modbus.ModbusBus`, so the figures are pymodbus client +
loopback TCP + pymodbus server + simulator logic, on this machine. A real drive adds its own
response time (typically a few ms on Modbus TCP), which these figures do not include.

Printed: round-trip latency of single requests (FC03 read of one register, FC06 write, FC01 read
of one coil) as median / 95th / 99th percentile / max in ms; polls per second of
``AbbAcs580.read()`` (one FC03 request: Status Word and Actual 1 are adjacent) and of
``ModbusPlc.read()`` (three requests); and the release-confirmation overhead of
``ModbusPlc.release()``: confirmed delay minus the simulated armature delay.

Run: ``.venv/bin/python benchmarks/modbus_latency.py [--requests 2000] [--seconds 2]``.
``--quick`` (CI): 200 requests, 0.5 s of polls, 3 releases; ``--results DIR`` writes the tables
(``benchmarks/result_files.py``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core figures

import argparse  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from daq.instruments.abb_acs580.driver import AbbAcs580
from daq.instruments.abb_acs580.settings import AbbAcs580Settings
from daq.instruments.modbus_plc.driver import POLL_S, ModbusPlc
from daq.instruments.modbus_plc.settings import ModbusPlcSettings
from daq.transports.modbus import ModbusBus  # noqa: E402
from ident import SectionModel, TapLayout
from ident.model import flat_plate
from simulators.devices.abb_acs580 import SimAbbAcs580  # noqa: E402
from simulators.devices.modbus_plc import SimModbusPlc  # noqa: E402
from simulators.virtual_tunnel import VirtualTunnel  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

FAN = {"max_rpm": 1500.0, "ramp_rpm_per_s": 3000.0,
       "registers": {"control_word": 0, "reference_1": 1, "status_word": 3, "actual_1": 4}}
PLC = {"coils": {"release": 0, "arm": 1, "trigger": 2}, "discrete_inputs": {"released": 0},
       "holding_registers": {"trigger_count": 10}}
#: Defaults: (full run, --quick) per option.
DEFAULTS = {"requests": (2000, 200), "seconds": (2.0, 0.5), "releases": (20, 3)}


def latencies(call: Callable[[], object], n: int) -> np.ndarray:
    for _ in range(min(50, n)):  # warm-up
        call()
    out = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        call()
        out[i] = time.perf_counter() - t0
    return out


def rate(call: Callable[[], object], seconds: float) -> float:
    count, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        call()
        count += 1
    return count / (time.perf_counter() - t0)


def row(name: str, seconds: np.ndarray, table: list[list[object]] | None = None) -> str:
    """Return the printed line of one request's latencies (and add its row to ``table``)."""
    ms = 1e3 * np.percentile(seconds, [50, 95, 99, 100])
    if table is not None:
        table.append([name, seconds.size, *ms])
    return f"{name:<34s} {ms[0]:8.3f} {ms[1]:8.3f} {ms[2]:8.3f} {ms[3]:8.3f}"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name, kind, what in (("requests", int, "requests per latency row"),
                             ("seconds", float, "s of polling per poll rate"),
                             ("releases", int, "releases for the confirmation overhead")):
        full, quick = DEFAULTS[name]
        parser.add_argument(f"--{name}", type=kind, default=None,
                            help=f"{what} (default {full:g}; --quick: {quick:g})")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    result_files.resolve_defaults(args, DEFAULTS)
    if args.requests < 1 or not args.seconds > 0 or args.releases < 1:
        parser.error("--requests and --releases must be >= 1, --seconds > 0")
    logging.basicConfig(level=logging.ERROR)

    section = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    tunnel = VirtualTunnel(section, flat_plate.jones_model(), TapLayout.rectangle(0.3, 0.01, 16),
                           wind_per_rpm=0.01, decay_duration_s=2.0)
    sim_fan = SimAbbAcs580(tunnel, **FAN["registers"], max_rpm=FAN["max_rpm"],
                           ramp_rpm_per_s=FAN["ramp_rpm_per_s"], rng=1)
    sim_plc = SimModbusPlc(tunnel, **PLC["coils"], **PLC["discrete_inputs"],
                           **PLC["holding_registers"], rng=2)
    trips: list[list[object]] = []
    with sim_fan, sim_plc:
        fan_bus = ModbusBus(sim_fan.url)
        plc_bus = ModbusBus(sim_plc.url)
        fan = AbbAcs580(fan_bus, AbbAcs580Settings.from_table(FAN), limit_rpm=1000.0)
        plc = ModbusPlc(plc_bus, ModbusPlcSettings.from_table(PLC))
        with fan, plc:
            n = args.requests
            print(f"Modbus TCP on 127.0.0.1, pymodbus sync client and server, {n} requests each")
            print(f"{'round trip, ms':<34s} {'median':>8s} {'p95':>8s} {'p99':>8s} {'max':>8s}")
            print(row("FC03 read 1 holding register", latencies(
                lambda: fan_bus.read_holding_registers(3, 1), n), trips))
            print(row("FC03 read SW + ACT1 (2 registers)", latencies(
                lambda: fan_bus.read_holding_registers(3, 2), n), trips))
            print(row("FC06 write Reference 1", latencies(lambda: fan.set_speed(500.0), n),
                      trips))
            print(row("FC01 read 1 coil", latencies(lambda: plc_bus.read_coils(1, 1), n), trips))
            print(row("FC02 read 1 discrete input", latencies(
                lambda: plc_bus.read_discrete_inputs(0, 1), n), trips))
            print()
            print(f"polls/s over {args.seconds:g} s:")
            fan_rate = rate(fan.read, args.seconds)
            print(f"  AbbAcs580.read()  (1 request)   {fan_rate:9.0f}")
            plc_rate = rate(plc.read, args.seconds)
            print(f"  ModbusPlc.read()  (3 requests)  {plc_rate:9.0f}")
            overhead = []
            for i in range(args.releases):
                plc.arm()
                timing = plc.release()
                overhead.append(timing.delay_s - sim_plc.release_delays[i])
            ms = 1e3 * np.array(overhead)
            print()
            print(f"release confirmation over {args.releases} releases (RELEASED polled every "
                  "2 ms): confirmed delay - simulated armature delay, ms: "
                  f"median {np.median(ms):.2f}, min {ms.min():.2f}, max {ms.max():.2f}")

    lat = ("median latency (ms)", "p95 latency (ms)", "p99 latency (ms)", "max latency (ms)")
    poll = "poll rate (polls/s)"
    over = ("median overhead (ms)", "min overhead (ms)", "max overhead (ms)")
    tables = [
        result_files.Table(
            "Round-trip latency of single Modbus TCP requests to the simulators on loopback "
            "(pymodbus client and server).",
            ["request", "requests", *lat], trips, formats=dict.fromkeys(lat, ".3f")),
        result_files.Table(
            f"Polls per second of the drivers' read() over {args.seconds:g} s each.",
            ["poll", "requests per poll", poll],
            [["AbbAcs580.read()", 1, fan_rate], ["ModbusPlc.read()", 3, plc_rate]],
            formats={poll: ".0f"}),
        result_files.Table(
            "Release confirmation overhead of ModbusPlc.release(): confirmed delay minus the "
            "simulated armature delay.",
            ["releases", *over],
            [[args.releases, float(np.median(ms)), float(ms.min()), float(ms.max())]],
            formats=dict.fromkeys(over, ".2f")),
    ]
    notes = ["The figures are pymodbus client, loopback TCP, pymodbus server and simulator "
             "logic on this host; a real drive adds its own response time.",
             f"ModbusPlc.release() polls RELEASED every {POLL_S * 1e3:g} ms, which bounds the "
             "confirmation overhead's resolution."]
    if ms.min() < 0:
        notes.append(f"{int((ms < 0).sum())} of {ms.size} overheads are negative (down to "
                     f"{ms.min():.2f} ms): the simulated PLC starts the armature timer at the "
                     "release and computes the decay before it acknowledges the write, so the "
                     "driver's command time (the acknowledgement) is late by that computation.")
    result_files.write(
        "modbus_latency", "Modbus round-trip latency and poll rates", tables,
        results=args.results, quick=args.quick,
        parameters={"requests": args.requests, "seconds": args.seconds,
                    "releases": args.releases},
        notes=notes)
    if args.results is not None:
        print(f"results: {args.results / 'modbus_latency.json'} and .md")


if __name__ == "__main__":
    main()
