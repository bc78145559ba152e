"""A simulated rig served from its own process, as real instruments are.

Responsibility: :func:`start_rig_process` runs :func:`daq.sim.rig.start_simulated_rig` in
a child process (``spawn``) and returns a :class:`RigProcess` holding the rig config with the
simulators' loopback URLs filled in; on request it answers questions about the truth (the true
time of a device timestamp, the tunnel's decays), so that a recording made by the parent can be
checked against it; it injects the simulators' faults (a scanner's TCP reset, ...), reads
their state (a scanner's zero error) and, for a rig without a PLC, lets the model go and holds
it again by hand (:meth:`RigProcess.hand_release`).

Why a process: in one process the simulators, the drivers and the recorder share one
interpreter lock. Every simulated device then waits for the others' Python code, which
inflates transport latencies to milliseconds: realistic for nothing, and exactly what a clock
synchronisation test must not be measured against. Real instruments run on their own hardware;
a child process is the closest loopback equivalent.

Not responsible for: the simulators (:mod:`simulators`), checking a run (:mod:`daq.sim.sync_check`).
"""

from __future__ import annotations

import logging
import multiprocessing
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.config import RigConfig
from daq.errors import DaqError

__all__ = ["RigProcess", "start_rig_process"]

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger(__name__)


class RigProcess:
    """A simulated rig in a child process; start one with :func:`start_rig_process`.

    Attributes
    ----------
    config : RigConfig
        The config with every ``"auto"`` URL replaced by the child's simulator URL.
    origin_s : float
        The tunnel's true time 0 on the host's ``time.monotonic`` clock, s (shared by both
        processes on Linux).
    """

    def __init__(self, process: Any, conn: Any, config: RigConfig, origin_s: float) -> None:
        self._process = process
        self._conn = conn
        self.config = config
        self.origin_s = float(origin_s)

    def true_time_of(self, name: str, t_device: Any) -> FloatArray:
        """Return the true host time (``time.monotonic`` s) of device ``name``'s timestamps."""
        self._conn.send(("true_time_of", name, np.asarray(t_device, dtype=np.float64)))
        return np.asarray(self._reply(), dtype=np.float64)

    def decay_truth(self, t: Any) -> dict[str, FloatArray]:
        """Return the tunnel's decays at true times ``t`` (see ``VirtualTunnel.decay_truth``)."""
        self._conn.send(("decay_truth", np.asarray(t, dtype=np.float64)))
        return dict(self._reply())

    def inject(self, name: str, fault: str, **params: Any) -> None:
        """Inject ``fault`` into simulator ``name`` (its ``inject``: a reset, a dropout, ...)."""
        self._conn.send(("inject", name, fault, params))
        self._reply()

    def attribute(self, name: str, attribute: str) -> Any:
        """Return an attribute of simulator ``name`` (its truth: a scanner's zero error, ...)."""
        self._conn.send(("attribute", name, attribute))
        return self._reply()

    def hand_release(self) -> float:
        """Let the model go through the virtual tunnel directly, as an operator's hand does.

        For a rig without a (simulated) PLC: nothing on the wire says so; the recording finds
        the release in the lasers' signals. Returns the true release time on the host's
        ``time.monotonic`` clock, s.
        """
        self._conn.send(("tunnel", "release"))
        return float(self._reply())

    def hand_hold(self) -> None:
        """Catch the model and hold it at its hold position (the tunnel's magnet, by hand)."""
        self._conn.send(("tunnel", "arm"))
        self._reply()

    def clocked_devices(self) -> list[str]:
        """Return the devices whose timestamps have a truth (scanner, lasers)."""
        self._conn.send(("clocked_devices",))
        return list(self._reply())

    def close(self) -> None:
        """Stop the simulators and the child process (idempotent)."""
        if self._process.is_alive():
            try:
                self._conn.send(("close",))
                self._reply()
            finally:
                self._process.join(10.0)
                self._kill()
        self._conn.close()

    def _reply(self) -> Any:
        kind, payload = self._conn.recv()
        if kind == "error":
            raise RuntimeError(f"simulated rig process: {payload}")
        return payload

    def _kill(self) -> None:
        if self._process.is_alive():
            self._process.kill()
            self._process.join(5.0)

    def __enter__(self) -> RigProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_rig_process(config: RigConfig, *, start_timeout_s: float = 30.0) -> RigProcess:
    """Start the simulated rig of ``config`` in a child process (see the module docstring).

    Parameters
    ----------
    config : RigConfig
        A simulated rig config (its ``[simulation]`` table).
    start_timeout_s : float
        How long the child may take to start every simulator, s.

    Returns
    -------
    RigProcess
        Use it as a context manager, or call ``close()``.

    Raises
    ------
    DaqError
        The child's own error when it is windrig's (a ConfigError of the rig config, a
        PluginError of a simulator plugin), raised here as it is.
    RuntimeError
        The child failed to start the rig otherwise (its error is in the message).
    TimeoutError
        It did not answer within ``start_timeout_s``.
    """
    ctx = multiprocessing.get_context("spawn")  # no fork of a threaded parent
    conn, child = ctx.Pipe()
    process = ctx.Process(target=_serve, args=(child, config.text, config.source),
                          name="windrig-simulated-rig", daemon=True)
    process.start()
    child.close()
    try:
        if not conn.poll(start_timeout_s):
            raise TimeoutError(f"the simulated rig process did not start within "
                               f"{start_timeout_s:g} s")
        kind, payload = conn.recv()
        if kind == "error" and isinstance(payload, DaqError):
            raise payload  # the rig config's or a plugin's error, as it would be in-process
        if kind == "error":
            raise RuntimeError(f"simulated rig process: {payload}")
    except BaseException:
        if process.is_alive():
            process.kill()
            process.join(5.0)
        conn.close()
        raise
    live_config, origin = payload
    if any(inst.url.startswith("nidaqmx://") for inst in live_config.instruments):
        # The drivers in this process read the child's simulated DAQ through the stand-in of
        # the nidaqmx API: a client library (the simulated device stays in the child), loaded
        # only for a rig that has one.
        from daq.instruments.ni_daqmx.runtime import register_standin
        from simulators.nidaqmx_standin import standin_api

        register_standin(standin_api)
    return RigProcess(process, conn, live_config, origin)


def _serve(conn: Any, config_text: str, source: str) -> None:
    """Child process: start the rig, answer truth requests until told to close."""
    # The simulators are imported in the child only: the parent (a recorder, the console)
    # never loads them.
    from daq.config import parse_rig_config
    from daq.sim.rig import start_simulated_rig

    try:
        rig = start_simulated_rig(parse_rig_config(config_text, source))
    except DaqError as exc:
        # windrig's own errors (a ConfigError of [simulation.devices], a PluginError of a
        # simulator) are messages for the user: the parent raises them as they are, one
        # `error:` line, not a RuntimeError's traceback. Sent as a new one of the same type:
        # the chained traceback does not cross the pipe (it stays in this process's log).
        log.debug("the simulated rig did not start", exc_info=True)
        try:
            error: Any = type(exc)(str(exc))
        except Exception:  # a subclass with another constructor: its text, as for the others
            error = f"{type(exc).__name__}: {exc}"
        conn.send(("error", error))
        return
    except Exception as exc:  # reported to the parent, which raises it
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    origin = float(getattr(rig.tunnel.clock, "origin_s", 0.0))  # a MonotonicClock's
    try:
        conn.send(("ok", (rig.config, origin)))
        while True:
            try:
                request = conn.recv()
            except (EOFError, OSError):  # the parent went away (killed): the instruments stop
                return
            try:
                if request[0] == "close":
                    break
                if request[0] == "true_time_of":
                    sim = rig.simulators[request[1]]
                    answer: Any = origin + sim.true_time_of(request[2])
                elif request[0] == "decay_truth":
                    answer = rig.tunnel.decay_truth(request[1])
                elif request[0] == "inject":
                    answer = rig.simulators[request[1]].inject(request[2], **request[3])
                elif request[0] == "attribute":
                    answer = getattr(rig.simulators[request[1]], request[2])
                elif request[0] == "tunnel" and request[1] == "release":
                    answer = origin + rig.tunnel.release()
                elif request[0] == "tunnel" and request[1] == "arm":
                    rig.tunnel.arm()
                    answer = None
                elif request[0] == "clocked_devices":
                    answer = [n for n, s in rig.simulators.items() if hasattr(s, "true_time_of")]
                else:
                    raise ValueError(f"unknown request {request[0]!r}")
            except Exception as exc:  # reported to the parent, which raises it
                conn.send(("error", f"{type(exc).__name__}: {exc}"))
            else:
                conn.send(("ok", answer))
    finally:
        rig.close()
    conn.send(("ok", None))
