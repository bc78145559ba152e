"""The ``nidaqmx://`` URL: one NI-DAQmx task's device, analog channels and task options.

Responsibility: :class:`TaskAddress`, parsed and validated from a URL such as
``nidaqmx://Dev1/ai0:3?trigger=port0/line0&min=-10&max=10``. The URL names the whole task, not
one instrument: a multifunction DAQ device runs one hardware-timed analog input task at a time
(NI-DAQmx refuses a second one with "the specified resource is reserved"), so every instrument
read through the same device gives the same URL and picks its own channel in its settings
(``channel = "ai1"``); the driver shares one task between them
(:mod:`daq.instruments.ni_daqmx.task_group`).

The query:

- ``trigger``: the trigger line read with the analog samples on their sample clock, a digital
  line (``port0/line0``: a rising edge flags the sample) or a counter (``ctr0``: its edge
  count, a count that grew flags the sample); absent: no trigger line wired;
- ``min``, ``max``: the input range of every analog channel of the task, V (default -10, 10);
- ``terminal``: ``default``, ``rse``, ``nrse`` or ``diff`` (the channels' terminal
  configuration, default ``default``);
- ``buffer_s``: the host buffer of the task, s of samples (default 10 s; at least 0.05 s);
- ``standin``: ``127.0.0.1:PORT`` of a simulated device, read through the stand-in of the
  nidaqmx API (a simulated rig fills it in; loopback only). Absent: the real ``nidaqmx``.

Not responsible for: the channels' scales (the instruments' settings,
:mod:`daq.instruments.ni_daqmx.settings`), loading the API
(:mod:`daq.instruments.ni_daqmx.runtime`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Final
from urllib.parse import parse_qs, urlsplit

from daq.errors import ConfigError

__all__ = ["SCHEME", "TERMINALS", "TaskAddress", "expand_channels"]

#: The URL scheme of the NI-DAQmx drivers.
SCHEME: Final = "nidaqmx"

#: Terminal configurations accepted in the URL -> ``nidaqmx.constants.TerminalConfiguration``.
TERMINALS: Final = {"default": "DEFAULT", "rse": "RSE", "nrse": "NRSE", "diff": "DIFF"}

_QUERY_KEYS: Final = ("trigger", "min", "max", "terminal", "buffer_s", "standin")
_AI = re.compile(r"ai(\d+)(?::(\d+))?$")
_LINE = re.compile(r"port\d+/line\d+$")
_COUNTER = re.compile(r"ctr\d+$")
_DEVICE = re.compile(r"[A-Za-z][A-Za-z0-9_-]*$")


def expand_channels(spec: str, where: str) -> tuple[str, ...]:
    """Expand ``ai0:3`` or ``ai0,ai2`` (NI's physical-channel ranges) into ``(ai0, ai1, ...)``."""
    out: list[str] = []
    for part in spec.split(","):
        m = _AI.match(part.strip())
        if not m:
            raise ConfigError(f"{where}: {part!r} is not an analog input channel range such as "
                              "ai0 or ai0:3")
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) is not None else lo
        if hi < lo:
            raise ConfigError(f"{where}: channel range {part!r} runs backwards")
        out += [f"ai{i}" for i in range(lo, hi + 1)]
    if len(set(out)) != len(out):
        raise ConfigError(f"{where}: a channel is named twice in {spec!r}")
    return tuple(out)


@dataclass(frozen=True)
class TaskAddress:
    """One NI-DAQmx analog input task, as its URL gives it.

    Attributes
    ----------
    url : str
        The URL, verbatim.
    device : str
        NI device name (``Dev1``, ``cDAQ1Mod1``).
    channels : tuple of str
        The task's analog input channels, in task order (``ai0``, ``ai1``, ...).
    trigger : str
        The trigger line (``port0/line0``), counter (``ctr0``) or "" (none).
    min_v, max_v : float
        Input range of every channel, V.
    terminal : str
        A key of :data:`TERMINALS`.
    buffer_s : float
        Host buffer of the task, s of samples.
    standin : tuple of (str, int) or None
        Host and port of a simulated device (the stand-in API); None: the real ``nidaqmx``.
    """

    url: str
    device: str
    channels: tuple[str, ...]
    trigger: str = ""
    min_v: float = -10.0
    max_v: float = 10.0
    terminal: str = "default"
    buffer_s: float = 10.0
    standin: tuple[str, int] | None = None

    @classmethod
    def parse(cls, url: str) -> TaskAddress:
        """Parse and check a ``nidaqmx://DEVICE/CHANNELS?QUERY`` URL; ConfigError names the part."""
        where = f"url {url!r}"
        parts = urlsplit(url)
        if parts.scheme != SCHEME:
            raise ConfigError(f"{where}: the NI-DAQmx drivers take {SCHEME}://DEVICE/ai0:3 URLs")
        device = parts.netloc
        if not _DEVICE.match(device):
            raise ConfigError(f"{where}: {device!r} is not an NI device name such as Dev1")
        channels = expand_channels(parts.path.lstrip("/"), where)
        query = parse_qs(parts.query, keep_blank_values=True, strict_parsing=False)
        unknown = sorted(set(query) - set(_QUERY_KEYS))
        if unknown:
            raise ConfigError(f"{where}: unknown query key(s) {unknown}; allowed: "
                              f"{list(_QUERY_KEYS)}")
        repeated = sorted(k for k, v in query.items() if len(v) > 1)
        if repeated:
            raise ConfigError(f"{where}: query key(s) {repeated} given twice")
        q = {k: v[0] for k, v in query.items()}
        trigger = q.get("trigger", "")
        if trigger and not (_LINE.match(trigger) or _COUNTER.match(trigger)):
            raise ConfigError(f"{where}: trigger={trigger!r} is neither a digital line "
                              "(port0/line0) nor a counter (ctr0)")
        min_v = _volts(q, "min", -10.0, where)
        max_v = _volts(q, "max", 10.0, where)
        if not min_v < max_v:
            raise ConfigError(f"{where}: min={min_v:g} V must be below max={max_v:g} V")
        terminal = q.get("terminal", "default").lower()
        if terminal not in TERMINALS:
            raise ConfigError(f"{where}: terminal={terminal!r} is not one of {list(TERMINALS)}")
        buffer_s = _float(q, "buffer_s", 10.0, where)
        if not 0.05 <= buffer_s <= 600.0:
            raise ConfigError(f"{where}: buffer_s={buffer_s:g} is outside [0.05, 600] s")
        standin = None
        if "standin" in q:
            host, _, port = q["standin"].rpartition(":")
            if host not in ("127.0.0.1", "localhost") or not port.isdigit():
                raise ConfigError(f"{where}: standin={q['standin']!r} must be 127.0.0.1:PORT "
                                  "(simulated devices are served on loopback only)")
            standin = ("127.0.0.1", int(port))
        return cls(url=url, device=device, channels=channels, trigger=trigger, min_v=min_v,
                   max_v=max_v, terminal=terminal, buffer_s=buffer_s, standin=standin)

    @property
    def counter_trigger(self) -> bool:
        """Measure whether the trigger is read as a counter's edge count (else a digital line)."""
        return bool(_COUNTER.match(self.trigger))

    def physical(self, channel: str) -> str:
        """Return the physical channel name NI-DAQmx takes (``Dev1/ai0``)."""
        return f"{self.device}/{channel}"

    def buffer_samples(self, rate_hz: float) -> int:
        """Return the host buffer size at ``rate_hz``, samples per channel (at least 1000)."""
        return max(1000, int(math.ceil(self.buffer_s * rate_hz)))


def _float(q: dict[str, str], key: str, default: float, where: str) -> float:
    if key not in q:
        return default
    try:
        value = float(q[key])
    except ValueError:
        raise ConfigError(f"{where}: {key}={q[key]!r} is not a number") from None
    if not math.isfinite(value):
        raise ConfigError(f"{where}: {key}={q[key]!r} is not a finite number")
    return value


def _volts(q: dict[str, str], key: str, default: float, where: str) -> float:
    value = _float(q, key, default, where)
    if not -100.0 <= value <= 100.0:
        raise ConfigError(f"{where}: {key}={value:g} V is outside [-100, 100] V")
    return value
