"""The DSA3217's binary "Scan EU with Time" packet (type 7), decoded with numpy.

The layout, from the DSA3217 manual's packet tables ("Scan EU with Time Packet"):

====  =====  ==========================================
size  type   field
====  =====  ==========================================
2     int16  packet type, 7
2     int16  pad (quad-byte alignment)
4     int32  frame number
64    float  pressure, channels 1-16, engineering units
32    int16  temperature, channels 1-16 (raw counts)
4     int32  time (units in the next field)
4     int32  time units: 1 = microseconds, 2 = milliseconds
====  =====  ==========================================

112 bytes. [unverified] Little-endian (the manual's tables give sizes, not the byte order); the
time is read as unsigned 32 bits and unwrapped by the driver.
"""

from __future__ import annotations

import numpy as np

PACKET_TYPE = 7
PACKET = np.dtype([("type", "<i2"), ("pad", "<i2"), ("frame", "<i4"), ("pressure", "<f4", 16),
                   ("temperature", "<i2", 16), ("time", "<u4"), ("time_units", "<i4")])
PACKET_SIZE = PACKET.itemsize  # 112
#: Seconds per time unit, by the time-units field.
TIME_UNIT_S = {1: 1e-6, 2: 1e-3}


def decode(data: bytes | bytearray) -> np.ndarray:
    """Decode whole packets (``len(data)`` a multiple of 112); raise ValueError on a bad one."""
    packets = np.frombuffer(bytes(data), dtype=PACKET)
    bad = (packets["type"] != PACKET_TYPE) | ~np.isin(packets["time_units"], list(TIME_UNIT_S))
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"packet {i}: type {int(packets['type'][i])}, time units "
                         f"{int(packets['time_units'][i])} (expected type {PACKET_TYPE}, "
                         f"units 1 or 2)")
    return packets
