"""A simulated NI DAQ device: the virtual tunnel's signals as voltages, on a real sample clock.

Responsibility: :class:`SimNiDaqmx` is the device behind the stand-in of the nidaqmx API
(:mod:`simulators.nidaqmx_standin`), served on 127.0.0.1. Its analog inputs carry what the
simulated rig wires to them: a laser's analog output (the laser's distance to the model, from
the tunnel's heave, pitch or sway, through the inverse of the rig config's scale), a Pitot
transducer (the tunnel's dynamic pressure), or a constant; its digital line and counter see the
tunnel's trigger pulses (the line is high for ``pulse_width_s`` after each; the counter counts
them). Samples are taken at ``index / rate`` on the device's own clock (offset, drift) from the
analog task's start; the host buffer keeps the last ``buffer`` samples (older ones are
overwritten: a read of them is error -200279). Faults: ``stall`` (the device's answers are held
back for a while, as a busy host or a stalled USB link: the buffer overflows meanwhile) and
``device_lost`` (the connections drop and the device is absent for a while: -201003; it comes
back with its sample clock at 0 for the next task).

Not responsible for: the API (the stand-in), rig configs (``daq.sim.rig`` translates them into
the ``channels`` given here). Samples are computed when read (the tunnel's state at their true
times), which is what the device's buffer holds; the noise is seeded.
"""

from __future__ import annotations

import json
import logging
import math
import socket
import threading
from collections.abc import Mapping
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from simulators.clock import DeviceClock
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["SOURCE_KINDS", "SimNiDaqmx"]

log = logging.getLogger(__name__)

#: What an analog input may carry: ``laser`` (``x``, ``z``, ``axis``, ``standoff_mm``, ``gain``,
#: ``offset``, ``unit_m``: the laser reads ``standoff + h + x alpha`` (vertical) and its output is
#: ``(distance / unit_m - offset) / gain`` V), ``pitot`` (``gain``, ``offset``, ``unit_pa``: the
#: dynamic pressure through the inverse scale), ``constant`` (``volts``).
SOURCE_KINDS: Final = ("laser", "pitot", "constant")

#: NI-DAQmx error codes the device answers with (see the stand-in).
_OVERWRITTEN, _LOST, _RESERVED, _INVALID = -200279, -201003, -50103, -200077
FloatArray = npt.NDArray[np.float64]


class SimNiDaqmx:
    """A simulated multifunction DAQ device (see the module docstring).

    Parameters
    ----------
    tunnel : VirtualTunnel
        The physical truth.
    device : str
        The device's name (``Dev1``).
    channels : mapping
        Analog input name (``ai0``) -> its source: ``{"kind": ..., ...}`` (:data:`SOURCE_KINDS`).
        Inputs not named read 0 V plus noise.
    lines : sequence of str
        Digital lines wired to the trigger (``port0/line0``).
    counters : sequence of str
        Counters whose input is the trigger (``ctr0``).
    n_ai : int
        Analog inputs the device has (``ai0`` .. ``ai{n_ai-1}``).
    noise_v : float
        Standard deviation of the voltage noise, V (about one LSB of a 16-bit ADC at +-10 V).
    pulse_width_s : float
        How long the trigger line stays high after a pulse, s.
    clock : DeviceClock
        The device's sample clock against true time.
    rng : numpy.random.Generator or int, optional
        Noise source or its seed.
    """

    def __init__(self, tunnel: VirtualTunnel, *, device: str = "Dev1",
                 channels: Mapping[str, Mapping[str, Any]] | None = None,
                 lines: tuple[str, ...] = ("port0/line0",), counters: tuple[str, ...] = ("ctr0",),
                 n_ai: int = 16, noise_v: float = 3e-4, pulse_width_s: float = 1e-3,
                 clock: DeviceClock | None = None,
                 rng: np.random.Generator | int | None = None) -> None:
        self.tunnel = tunnel
        self.device = str(device)
        self.n_ai = int(n_ai)
        self.channels = {str(k): dict(v) for k, v in (channels or {}).items()}
        for name, source in self.channels.items():
            if source.get("kind") not in SOURCE_KINDS:
                raise ValueError(f"{name}: kind must be one of {SOURCE_KINDS}, got {source!r}")
            if not (name.startswith("ai") and name[2:].isdigit() and int(name[2:]) < self.n_ai):
                raise ValueError(f"{name} is not one of ai0..ai{self.n_ai - 1}")
            if source["kind"] == "laser" and source.get("axis") == "sway" \
                    and "p" not in tunnel.channels:
                raise ValueError(f"{name}: a sway laser needs a tunnel with sway")
        self.lines = tuple(lines)
        self.counters = tuple(counters)
        self.noise_v = float(noise_v)
        self.pulse_width_s = float(pulse_width_s)
        self.clock = clock if clock is not None else DeviceClock()
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._connections: list[socket.socket] = []
        self._ai: dict[str, Any] | None = None  # the running analog task
        self._ai_owner: object | None = None
        self._lost_until = -math.inf  # true time the device is back after device_lost
        self._stall_s = 0.0  # the next answer waits this long (stall fault)
        self.tasks_started = 0
        self._tau0 = math.nan  # device time of sample 0 of the last analog task started
        self.address: tuple[str, int] | None = None

    # -- life cycle ---------------------------------------------------------------------------
    def start(self) -> str:
        """Serve on 127.0.0.1; return ``127.0.0.1:PORT`` (a URL's ``standin=`` value)."""
        if self._thread is not None:
            raise RuntimeError("simulator already started")
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.2)
        self.address = ("127.0.0.1", int(self._listener.getsockname()[1]))
        self._stop.clear()
        self._thread = threading.Thread(target=self._accept_loop, daemon=True,
                                        name=f"SimNiDaqmx {self.device}")
        self._thread.start()
        return f"{self.address[0]}:{self.address[1]}"

    def stop(self) -> None:
        """Stop serving and drop every connection; idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        self._drop_all()

    def __enter__(self) -> SimNiDaqmx:
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- faults -------------------------------------------------------------------------------
    def inject(self, fault: str, **params: Any) -> None:
        """Schedule a fault.

        - ``"stall"``, ``duration_s``: the next answer to a task waits ``duration_s`` (the
          acquisition goes on: beyond the buffer's length, the unread samples are overwritten);
        - ``"device_lost"``, ``downtime_s`` (default 0.3): every connection drops now and the
          device answers -201003 for ``downtime_s``; then a new task starts its clock at 0.
        """
        with self._lock:
            if fault == "stall":
                self._stall_s = float(params.pop("duration_s"))
            elif fault == "device_lost":
                self._lost_until = self.tunnel.clock.now() + float(params.pop("downtime_s", 0.3))
                self._ai, self._ai_owner = None, None
            else:
                raise ValueError(f"unknown fault {fault!r}")
            if params:
                raise TypeError(f"unknown parameter(s) for {fault!r}: {sorted(params)}")
        if fault == "device_lost":
            self._drop_all()

    def true_time_of(self, device_time: Any) -> Any:
        """Return the true time (s, tunnel clock) of samples at ``device_time`` (s, task clock).

        Valid for the last analog task started (a reconnection starts a new one).
        """
        with self._lock:
            start = self._tau0
        t = np.asarray(device_time, dtype=np.float64)
        return (start + t - self.clock.offset_s) / (1.0 + 1e-6 * self.clock.drift_ppm)

    # -- serving ------------------------------------------------------------------------------
    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            assert self._listener is not None
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._connections.append(conn)
            threading.Thread(target=self._serve, args=(conn,), daemon=True,
                             name=f"SimNiDaqmx {self.device} task").start()

    def _drop_all(self) -> None:
        with self._lock:
            conns, self._connections = self._connections, []
        for conn in conns:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass  # already closed by the peer: nothing left to shut
            conn.close()

    def _serve(self, conn: socket.socket) -> None:
        task: dict[str, Any] = {}
        rfile = conn.makefile("rb")
        try:
            while not self._stop.is_set():
                line = rfile.readline()
                if not line:
                    return
                try:
                    answer, payload = self._answer(json.loads(line), task, conn)
                except _Refused as exc:
                    answer, payload = {"error": exc.code, "message": exc.message}, b""
                if payload:
                    answer["bytes"] = len(payload)
                with self._lock:
                    stall, self._stall_s = self._stall_s, 0.0
                if stall > 0:
                    self._stop.wait(stall)
                conn.sendall(json.dumps(answer).encode() + b"\n" + payload)
        except OSError:
            return  # the connection dropped (a device_lost fault, or the client went away)
        finally:
            with self._lock:
                if self._ai_owner is conn:
                    self._ai, self._ai_owner = None, None
                if conn in self._connections:
                    self._connections.remove(conn)
            rfile.close()
            conn.close()

    def _answer(self, request: Mapping[str, Any], task: dict[str, Any],
                conn: socket.socket) -> tuple[dict[str, Any], bytes]:
        now = self.tunnel.clock.now()
        with self._lock:
            if now < self._lost_until:
                raise _Refused(_LOST, "Device cannot be accessed.")
        op = request.get("op")
        if op == "devices":
            return {"ok": True, "devices": [self.device]}, b""
        if op == "start":
            self._start_task(request, task, conn)
            return {"ok": True}, b""
        if op == "stop":  # stopping a task that is not running is not an error (as DAQmx)
            with self._lock:
                if self._ai_owner is conn:
                    self._ai, self._ai_owner = None, None
            task.clear()
            return {"ok": True}, b""
        if not task:
            raise _Refused(_INVALID, "the task is not running")
        total = self._total(task)
        if op == "total":
            return {"ok": True, "total": total}, b""
        if op == "read":
            first, n = int(request["from"]), int(request["n"])
            if first < total - int(task["buffer"]) or first < 0:
                raise _Refused(_OVERWRITTEN, "Attempted to read samples that are no longer "
                               "available. The requested sample was previously available, but "
                               "has since been overwritten.")
            n = max(0, min(n, total - first))
            rows = self._samples(task, first, n)
            return ({"ok": True, "n": n, "dtype": rows.dtype.str, "shape": list(rows.shape)},
                    rows.tobytes())
        raise _Refused(_INVALID, f"unknown request {op!r}")

    def _start_task(self, request: Mapping[str, Any], task: dict[str, Any],
                    conn: socket.socket) -> None:
        if request.get("device") != self.device:
            raise _Refused(_LOST, f"Device cannot be accessed: no device "
                                  f"{request.get('device')!r} (this one is {self.device})")
        kind, lines = request["kind"], list(request["lines"])
        rate, buffer = float(request["rate"]), int(request["buffer"])
        if not (rate > 0 and buffer > 0):
            raise _Refused(_INVALID, f"rate {rate} and buffer {buffer} must be > 0")
        with self._lock:
            if kind == "ai":
                bad = [ln for ln in lines if not (ln.startswith("ai") and ln[2:].isdigit()
                                                  and int(ln[2:]) < self.n_ai)]
                if bad:
                    raise _Refused(_INVALID, f"no analog input(s) {bad} on {self.device}")
                if self._ai is not None:
                    raise _Refused(_RESERVED, "The specified resource is reserved.")
                tau0 = self.clock.device_time(self.tunnel.clock.now())
                task.update(kind="ai", lines=lines, rate=rate, buffer=buffer, tau0=tau0,
                            min=float(request.get("min", -5.0)),
                            max=float(request.get("max", 5.0)))
                self._ai, self._ai_owner = task, conn
                self._tau0 = tau0
                self.tasks_started += 1
            else:
                known = self.lines if kind == "di" else self.counters
                if len(lines) != 1 or lines[0] not in known:
                    raise _Refused(_INVALID, f"{kind} input {lines} is not one of {list(known)}")
                if request.get("source") != f"/{self.device}/ai/SampleClock":
                    raise _Refused(_INVALID, "the simulated device clocks its digital inputs "
                                             "and counters from the analog sample clock only")
                task.update(kind=kind, lines=lines, rate=rate, buffer=buffer,
                            initial=int(request.get("initial", 0)))

    def _clocked_by(self, task: Mapping[str, Any]) -> Mapping[str, Any] | None:
        """Return the analog task whose sample clock a task runs on (itself, if analog)."""
        if task.get("kind") == "ai":
            return task
        with self._lock:
            return self._ai

    def _total(self, task: Mapping[str, Any]) -> int:
        ai = self._clocked_by(task)
        if ai is None:
            return 0
        tau = self.clock.device_time(self.tunnel.clock.now())
        return max(0, math.floor((tau - float(ai["tau0"])) * float(ai["rate"])) + 1)

    def _samples(self, task: Mapping[str, Any], first: int, n: int) -> npt.NDArray[Any]:
        ai = self._clocked_by(task)
        if ai is None or n == 0:
            width = len(task["lines"]) if task["kind"] == "ai" else 1
            return np.zeros((0, width), np.float64 if task["kind"] == "ai" else np.int64)
        tau = float(ai["tau0"]) + np.arange(first, first + n) / float(ai["rate"])
        a = self.clock.true_time(0.0)
        t_true = a + (self.clock.true_time(1.0) - a) * tau
        if task["kind"] != "ai":
            pulses = np.asarray(self.tunnel.trigger_times(), dtype=np.float64)
            if task["kind"] == "di":
                after = t_true[:, None] - pulses[None, :]
                high = ((after >= 0) & (after < self.pulse_width_s)).any(axis=1)
                return high.astype(np.int64).reshape(n, 1)
            counts = np.searchsorted(np.sort(pulses), t_true, side="right")
            return (int(task["initial"]) + counts).astype(np.int64).reshape(n, 1)
        physics = self.tunnel.sample(t_true)
        volts = np.zeros((n, len(task["lines"])))
        for j, line in enumerate(task["lines"]):
            source = self.channels.get(line)
            if source is not None:
                volts[:, j] = self._volts(source, physics)
        if self.noise_v > 0:
            volts += self.noise_v * self.rng.standard_normal(volts.shape)
        lo, hi = float(task["min"]), float(task["max"])
        # A 16-bit converter over the range; beyond it the ADC reads its limit.
        lsb = (hi - lo) / 65536.0
        return np.clip(np.round(volts / lsb) * lsb, lo, hi)

    @staticmethod
    def _volts(source: Mapping[str, Any], physics: Mapping[str, FloatArray]) -> FloatArray:
        kind = source["kind"]
        if kind == "constant":
            return np.full(physics["h"].shape, float(source["volts"]))
        if kind == "pitot":
            value = physics["qd"] / float(source.get("unit_pa", 1.0))
        else:
            standoff = float(source["standoff_mm"]) * 1e-3
            if source.get("axis", "vertical") == "sway":
                d = standoff - (physics["p"] - float(source.get("z", 0.0)) * physics["alpha"])
            else:
                d = standoff + physics["h"] + float(source.get("x", 0.0)) * physics["alpha"]
            value = d / float(source.get("unit_m", 1.0))
        return (value - float(source.get("offset", 0.0))) / float(source["gain"])


class _Refused(Exception):
    """An NI-DAQmx error the device answers a request with."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
