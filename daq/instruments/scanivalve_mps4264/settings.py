"""Settings of the Scanivalve MPS4264-class scanner driver, and their validation.

Responsibility: :class:`Mps4264Settings`, the validated ``[scanner]`` table of a rig config (without
``driver``, ``url`` and ``name``), and the bounds it is checked against (:data:`MAX_RATE_HZ`,
:data:`MAX_MODULES`, :data:`MAX_MIN_BLOCK_S`): every key is checked with its range, and a bad value
is a :class:`~daq.errors.ConfigError` naming the key and the range. Not responsible for: applying
the settings to a scanner (the driver, :mod:`daq.instruments.scanivalve_mps4264.driver`, which
uses them) or reading the rig config file (:mod:`daq.config`). No I/O.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from daq.errors import ConfigError
from daq.instruments.scanivalve_mps4264.frames import CHANNELS_PER_MODULE
from daq.validation import check_keys, number

__all__ = [
    "DEFAULT_MIN_BLOCK_S",
    "MAX_MIN_BLOCK_S",
    "MAX_MODULES",
    "MAX_RATE_HZ",
    "Mps4264Settings",
]

#: Highest frame rate a rig config may ask for, Hz. [unverified]: the scanner's rate limit was
#: not confirmed (the manuals read give no maximum scan rate), so this is only the config's bound.
MAX_RATE_HZ = 2000.0
#: Highest number of modules in one scanner.
MAX_MODULES = 8
#: Default and upper bound of :attr:`Mps4264Settings.min_block_s`, s (see there why).
DEFAULT_MIN_BLOCK_S = 0.02
MAX_MIN_BLOCK_S = 0.25


def _integer(table: Mapping[str, Any], key: str, where: str, lo: int, hi: int,
             default: int | None = None) -> int:
    if key not in table and default is not None:
        return default
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        if key not in table:
            raise ConfigError(f"{where}: missing required key {key!r}")
        raise ConfigError(f"{where} {key} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= value <= hi:
        raise ConfigError(f"{where} {key} = {value!r} is outside the allowed range [{lo}, {hi}]")
    return value


@dataclass(frozen=True)
class Mps4264Settings:
    """Settings of the scanner (the ``[scanner]`` table of a rig config, without driver/url/name).

    Attributes
    ----------
    modules : int
        Number of 64-channel modules, 1..8.
    rate_hz : float
        Frame rate, Hz, in (0, 2000] ([unverified] rate limit, hence configurable).
    byte_order : str
        ``"big"`` or ``"little"``: the byte order the scanner is expected to send. The decoder
        detects it from every packet's type word; a mismatch is logged and counted.
    pitot_channel : int
        Global 0-based channel (over all modules) of the Pitot dynamic pressure,
        ``< 64 * modules``. Taps occupy channels ``0 .. n_taps - 1`` in the rig's tap order.
    data_port : int
        TCP port of module 0's binary data server (module ``k`` on ``data_port + k``), 1..65535,
        default 503 (docs/reference/wire_formats.md, "Pressure scanner"). A simulated scanner's
        ports are ephemeral: the launcher fills this from the simulator's ``data_port``.
    command_timeout_s : float
        Timeout of a command's reply, and default timeout of
        :meth:`~daq.instruments.scanivalve_mps4264.driver.ScanivalveMps4264.read_block`, s, in (0,
        60], default 2.
    min_block_s : float
        Batching of :meth:`~daq.instruments.scanivalve_mps4264.driver.ScanivalveMps4264.read_block`,
        s, in [0, 0.25], default 0.02: once a frame is complete, the read keeps collecting for at
        most this long (or until this many seconds of frames, ``ceil(min_block_s * rate_hz)``, are
        complete) and returns them in one block. Why: every block costs a fixed overhead whatever
        its size (decoding and merging in the driver, then the per-block work of the pipeline and
        the recorder): one block per frame (500 per second at 8 modules) took most of a core, 20 ms
        blocks (10 frames at 500 Hz) a fraction of it; 20 ms is also the block size the pipeline's
        clock windows are sized for (25 scanner blocks per 0.5 s window) and adds at most 20 ms of
        latency. 0 returns each frame as soon as it is complete. At most 0.25 s, so that every 0.5 s
        clock window still sees several blocks (the clock fit keeps the least-latency block of each)
        and the live view stays fluid. The read timeout still bounds the whole read.
    """

    modules: int
    rate_hz: float
    byte_order: str
    pitot_channel: int
    data_port: int = 503
    command_timeout_s: float = 2.0
    min_block_s: float = 0.02

    def __post_init__(self) -> None:
        where = "scanivalve_mps4264 settings"
        table = {name: getattr(self, name) for name in self.__dataclass_fields__}
        _validated(table, where)  # raises ConfigError naming the key and its range

    @property
    def n_channels(self) -> int:
        """Pressure channels over all modules."""
        return CHANNELS_PER_MODULE * self.modules

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> Mps4264Settings:
        """Validate a rig-config table (without ``driver``, ``url``, ``name``).

        Raises
        ------
        ConfigError
            Unknown or missing key, or a value outside its range (the message names both).
        """
        return cls(**_validated(table, where))


def _validated(table: Mapping[str, Any], where: str) -> dict[str, Any]:
    check_keys(table, where, {"modules", "rate_hz", "byte_order", "pitot_channel"},
               {"data_port", "command_timeout_s", "min_block_s"})
    modules = _integer(table, "modules", where, 1, MAX_MODULES)
    rate_hz = number(table, "rate_hz", where, lo=0.0, hi=MAX_RATE_HZ, lo_open=True)
    byte_order = table["byte_order"]
    if byte_order not in ("big", "little"):
        raise ConfigError(f"{where} byte_order must be 'big' or 'little', got {byte_order!r}")
    pitot = _integer(table, "pitot_channel", where, 0, CHANNELS_PER_MODULE * modules - 1)
    data_port = _integer(table, "data_port", where, 1, 65535, default=503)
    if data_port + modules - 1 > 65535:
        raise ConfigError(f"{where} data_port = {data_port} leaves no room for {modules} "
                          "consecutive module ports below 65536")
    timeout = number(table, "command_timeout_s", where, lo=0.0, hi=60.0, lo_open=True,
                     default=2.0)
    min_block = number(table, "min_block_s", where, lo=0.0, hi=MAX_MIN_BLOCK_S,
                       default=DEFAULT_MIN_BLOCK_S)
    return {"modules": modules, "rate_hz": rate_hz, "byte_order": byte_order,
            "pitot_channel": pitot, "data_port": data_port, "command_timeout_s": timeout,
            "min_block_s": min_block}
