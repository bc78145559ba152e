"""The scanner's binary packets, encoded from the manual's facts: the 0x6D and legacy 0x0A frames.

Responsibility: the constants of an MPS4264-class module (64 pressure and 8 temperature channels,
the units table of ``SET UNITS``) and the two packets the simulated scanner sends
(``docs/reference/wire_formats.md``, "Pressure scanner"): :func:`words_eu`, the MPS-4264 EU packet
(type 0x6D, 304 bytes), and :func:`words_legacy`, the legacy 64-channel packet (type 0x0A, 348
bytes), each as rows of 32-bit words, for many frames at once (the caller picks the byte order).
They are written from ``mps-protocol.h``, independently of the driver's decoder
(:mod:`daq.instruments.scanivalve_mps4264`), so that a test of the one checks the other.

Not responsible for: what the frames hold (:mod:`simulators.devices.scanivalve_mps4264.scanner`
computes the pressures, times and triggers) or sending them
(:mod:`simulators.devices.scanivalve_mps4264.servers`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["CHANNELS", "NS", "PSI_PA", "SIZE_EU64", "SIZE_LEGACY", "TEMPS", "TYPE_EU64",
           "TYPE_LEGACY", "UNITS", "words_eu", "words_legacy"]

CHANNELS = 64  # pressure channels per module (mps-protocol.h)
TEMPS = 8  # temperature channels per module
PSI_PA = 6894.75977  # Pa per psi: the PA factor of the units table (mps-protocol.h)
#: SET UNITS name -> (Appendix A unit index, conversion factor from psi).
UNITS = {"PSI": (0, 1.0), "KPA": (14, PSI_PA / 1000.0), "PA": (23, PSI_PA)}
TYPE_EU64, SIZE_EU64 = 0x6D, 304
TYPE_LEGACY, SIZE_LEGACY = 0x0A, 348
NS = 1_000_000_000


def words_eu(frame: npt.NDArray[np.int64], t_ns: npt.NDArray[np.int64],
              temps: npt.NDArray[np.float32], press: npt.NDArray[np.float32]
              ) -> npt.NDArray[np.uint32]:
    """MPS-4264 EU packet (type 0x6D, 304 bytes) as 76 words per row (mps-protocol.h)."""
    words = np.empty((frame.size, SIZE_EU64 // 4), np.uint32)
    words[:, 0] = TYPE_EU64
    words[:, 1] = frame % (1 << 32)
    words[:, 2] = t_ns // NS
    words[:, 3] = t_ns % NS
    words[:, 4:12] = temps.view(np.uint32)
    words[:, 12:76] = press.view(np.uint32)
    return words


def words_legacy(frame: npt.NDArray[np.int64], t_ns: npt.NDArray[np.int64],
                  temps: npt.NDArray[np.float32], press: npt.NDArray[np.float32], *,
                  serial: int, rate_hz: float, unit_index: int, conversion: float,
                  start_ns: int, ext_rel_ns: npt.NDArray[np.int64]) -> npt.NDArray[np.uint32]:
    """Legacy 64-channel packet (type 0x0A, 348 bytes) as 87 words per row (mps-protocol.h).

    ``ext_rel_ns`` < 0 means no external trigger yet: every trigger field is 0.
    """
    n = frame.size
    words = np.zeros((n, SIZE_LEGACY // 4), np.uint32)
    words[:, 0] = TYPE_LEGACY
    words[:, 1] = SIZE_LEGACY
    words[:, 2] = frame % (1 << 32)
    words[:, 3] = np.uint32(serial)
    words[:, 4] = np.float32(rate_hz).view(np.uint32)
    words[:, 5] = 0  # valve_status 0 = Px (the MPS4264 has no calibration valve)
    words[:, 6] = unit_index
    words[:, 7] = np.float32(conversion).view(np.uint32)
    words[:, 8] = start_ns // NS
    words[:, 9] = start_ns % NS
    has = ext_rel_ns >= 0
    rel = np.where(has, ext_rel_ns, 0)
    words[:, 10] = (rel // 1000) % (1 << 32)  # ext_trigger_time_us
    words[:, 11:19] = temps.view(np.uint32)
    words[:, 19:83] = press.view(np.uint32)
    words[:, 83] = t_ns // NS
    words[:, 84] = t_ns % NS
    words[:, 85] = rel // NS
    words[:, 86] = rel % NS
    return words
