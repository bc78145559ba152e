"""Recovery of a run file whose writer never closed it (SIGKILL, power cut, a crash).

Responsible for: making such a file an ordinary HDF5 file again, one that any HDF5 tool opens
(``h5py.File(path)``, ``h5dump``, silx, nexusformat), keeping every row that reached the disk;
trimming the rows of a last, partly written append (the datasets of ``/entry/sync`` and of each
raw stream are resized one after the other, so after a crash they may differ in length, and a
size may have reached the file before its chunk did: fill-value rows); and marking the run as
recovered (``/entry`` attribute ``recovered``, ``/entry/metadata/recovery`` and a
``file_recovered`` event).

Not responsible for: redoing what the writer computes at close (the final clock fits and the
acquisition summary): the raw streams keep every host and device time for that.

Why the superblock is edited here
---------------------------------
The writer records in SWMR mode, which needs the version 3 superblock. That superblock has a
"file status flags" byte (bit 0: open for writing, bit 2: open for SWMR writing) that HDF5 sets
when a writer opens the file and clears when it closes it. After a crash the flags stay set and
HDF5 then refuses every open except a SWMR read ("file is already open for write (may use
<h5clear file> to clear file consistency flags)"). HDF5's ``h5clear -s`` clears them through a
library-private file-access property that neither h5py nor HDF5's public API exposes, and the
HDF5 command-line tools are not a dependency of windrig. So :func:`clear_status_flags` does what
``h5clear -s`` does, on the 48 bytes of the superblock only: it zeroes the flags byte, raises
the stored end-of-file address to the file's size if the file is longer (what ``h5clear
--increment`` is for: space past the stored address may hold chunks the crashed writer
allocated, which a later writer must not reuse), and recomputes the superblock's checksum
(Jenkins' lookup3, the checksum of every HDF5 metadata block). HDF5 verifies that checksum when
it opens the file, so a mistake here makes the file refuse to open; it cannot go unnoticed.
The rest of the file is edited through h5py. The superblock layout is that of the HDF5 File
Format Specification, version 3.0, section II.A (superblock versions 2 and 3).
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.errors import NotARunFileError, RecoveryError
from daq.recording.layout import (
    STREAM_TABLES,
    SWAY_COLUMNS,
    SYNC_COLUMNS,
    append_rows,
    now_iso,
    open_run_file,
    write_metadata,
)

__all__ = ["RECOVERED_EVENT", "RecoveryReport", "Superblock", "clear_status_flags", "holders",
           "lookup3", "needs_recovery", "read_superblock", "recover_run"]

_SIGNATURE = b"\x89HDF\r\n\x1a\n"

#: Superblock v2/v3: signature, version, sizes of offsets and lengths, status flags, then four
#: addresses (base, superblock extension, end of file, root group) and a 4-byte checksum.
_V2_LENGTH = 48

#: The ``/entry/events`` kind that marks a recovered run (``recovered`` alone is a device's).
RECOVERED_EVENT = "file_recovered"


@dataclass(frozen=True)
class Superblock:
    """Where a file's superblock is and what its status flags say.

    Attributes
    ----------
    offset : int
        Byte offset of the superblock (0, or after a user block: 512, 1024, ...).
    version : int
        Superblock version (0-3); status flags exist from version 2 on.
    flags : int
        The status flags byte: bit 0 open for writing, bit 2 open for SWMR writing.
    """

    offset: int
    version: int
    flags: int


@dataclass
class RecoveryReport:
    """What :func:`recover_run` did to one file.

    Attributes
    ----------
    path : str
    flags_before : int
        The superblock status flags the crash left (0: the file had been closed).
    recovered : bool
        Whether anything was done (False: a cleanly closed or already recovered file).
    recovered_before : str or None
        When an earlier ``windrig recover`` recovered it (ISO 8601 UTC), if one did.
    sync_rows : int
        Rows of ``/entry/sync`` kept.
    end_s : float
        Time of the last row of ``/entry/sync`` kept, s from the run start (NaN: none).
    trimmed : dict of str to int
        Rows removed per dataset (path inside the file); datasets with none are left out.
    kept : dict of str to int
        Rows kept per raw stream (``/entry/instrument/<device>``).
    """

    path: str
    flags_before: int
    recovered: bool
    recovered_before: str | None = None
    sync_rows: int = 0
    end_s: float = float("nan")
    trimmed: dict[str, int] = field(default_factory=dict)
    kept: dict[str, int] = field(default_factory=dict)


def lookup3(data: bytes, initval: int = 0) -> int:
    """Return Bob Jenkins' lookup3 ``hashlittle`` of ``data``, HDF5's metadata checksum.

    Parameters
    ----------
    data : bytes
    initval : int
        Seed (HDF5 uses 0).

    Returns
    -------
    int
        The 32-bit checksum.

    Examples
    --------
    >>> hex(lookup3(b""))
    '0xdeadbeef'
    >>> hex(lookup3(b"Four score and seven years ago"))
    '0x17770551'
    """
    mask = 0xFFFFFFFF

    def rot(x: int, k: int) -> int:
        return ((x << k) | (x >> (32 - k))) & mask

    length = len(data)
    a = b = c = (0xDEADBEEF + length + initval) & mask
    if length == 0:
        return c
    # Whole 12-byte blocks but the last (which may be whole too) are mixed; the last is padded
    # with zero bytes, which adds nothing to the sums, as hashlittle's fall-through cases do.
    blocks = (length - 1) // 12
    tail = data[12 * blocks:] + bytes(12 - (length - 12 * blocks))
    for i in range(blocks):
        x, y, z = struct.unpack_from("<3I", data, 12 * i)
        a, b, c = (a + x) & mask, (b + y) & mask, (c + z) & mask
        a = ((a - c) & mask) ^ rot(c, 4)
        c = (c + b) & mask
        b = ((b - a) & mask) ^ rot(a, 6)
        a = (a + c) & mask
        c = ((c - b) & mask) ^ rot(b, 8)
        b = (b + a) & mask
        a = ((a - c) & mask) ^ rot(c, 16)
        c = (c + b) & mask
        b = ((b - a) & mask) ^ rot(a, 19)
        a = (a + c) & mask
        c = ((c - b) & mask) ^ rot(b, 4)
        b = (b + a) & mask
    x, y, z = struct.unpack("<3I", tail)
    a, b, c = (a + x) & mask, (b + y) & mask, (c + z) & mask
    c = ((c ^ b) - rot(b, 14)) & mask
    a = ((a ^ c) - rot(c, 11)) & mask
    b = ((b ^ a) - rot(a, 25)) & mask
    c = ((c ^ b) - rot(b, 16)) & mask
    a = ((a ^ c) - rot(c, 4)) & mask
    b = ((b ^ a) - rot(a, 14)) & mask
    c = ((c ^ b) - rot(b, 24)) & mask
    return c


def read_superblock(path: str | os.PathLike[str]) -> Superblock:
    """Find a file's HDF5 superblock and read its version and status flags.

    Raises
    ------
    RecoveryError
        If the file has no HDF5 signature at 0 or at any power of two from 512 on.
    """
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        offset = 0
        while offset + 12 <= size:
            fh.seek(offset)
            head = fh.read(12)
            if head[:8] == _SIGNATURE:
                version = head[8]
                # Versions 0 and 1 have a 4-byte "file consistency flags" field that HDF5
                # never sets; only versions 2 and 3 carry status flags.
                flags = head[11] if version >= 2 else 0
                return Superblock(offset=offset, version=version, flags=flags)
            offset = 512 if offset == 0 else 2 * offset
    raise NotARunFileError(f"{os.fspath(path)}: not an HDF5 file (no HDF5 signature found)")


def needs_recovery(path: str | os.PathLike[str]) -> bool:
    """Tell whether a run file was left open by its writer (its status flags are set)."""
    return read_superblock(path).flags != 0


def clear_status_flags(path: str | os.PathLike[str]) -> int:
    """Clear the superblock status flags of an HDF5 file, as ``h5clear -s`` does.

    Also raises the stored end-of-file address to the file's size when the file is longer (see
    the module docstring). Only the superblock's 48 bytes are rewritten.

    Parameters
    ----------
    path : path-like
        An HDF5 file with a version 2 or 3 superblock whose writer is gone.

    Returns
    -------
    int
        The flags found (0: nothing was written).

    Raises
    ------
    RecoveryError
        If the superblock's checksum does not match its bytes (a damaged superblock is not
        rewritten), or if its addresses are not 8 bytes (windrig files always have 8).
    """
    sb = read_superblock(path)
    if sb.flags == 0:
        return 0
    with open(path, "r+b") as fh:
        fh.seek(sb.offset)
        block = bytearray(fh.read(_V2_LENGTH))
        if len(block) != _V2_LENGTH or block[9] != 8:
            raise RecoveryError(f"{os.fspath(path)}: superblock version {sb.version} with "
                                f"{block[9] if len(block) > 9 else '?'}-byte addresses is not "
                                "one windrig writes; use HDF5's h5clear -s")
        (stored,) = struct.unpack_from("<I", block, 44)
        if lookup3(bytes(block[:44])) != stored:
            raise RecoveryError(f"{os.fspath(path)}: the superblock's checksum does not match "
                                "its bytes: the superblock itself is damaged, not only flagged")
        block[11] = 0
        (base, _ext, eof, _root) = struct.unpack_from("<4Q", block, 12)
        size = os.fstat(fh.fileno()).st_size
        if base + eof < size:
            struct.pack_into("<Q", block, 28, size - base)
        struct.pack_into("<I", block, 44, lookup3(bytes(block[:44])))
        fh.seek(sb.offset)
        fh.write(block)
        fh.flush()
        os.fsync(fh.fileno())
    return sb.flags


def holders(path: str | os.PathLike[str]) -> list[int]:
    """Return the ids of other processes that have ``path`` open (Linux ``/proc``; else [])."""
    path = Path(path)
    proc = Path("/proc")
    if not (proc / "self" / "fd").is_dir():
        return []
    target = path.stat()
    pids = []
    for entry in proc.iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            fds = list((entry / "fd").iterdir())
        except OSError:  # gone, or another user's
            continue
        for fd in fds:
            try:
                st = fd.stat()
            except OSError:
                continue
            if (st.st_dev, st.st_ino) == (target.st_dev, target.st_ino):
                pids.append(int(entry.name))
                break
    return pids


def _keep_prefix(valid: np.ndarray) -> int:
    """Return the length of ``valid`` without its trailing False entries."""
    hits = np.flatnonzero(valid)
    return int(hits[-1]) + 1 if hits.size else 0


def _resize(ds: h5py.Dataset, n: int, report: RecoveryReport) -> None:
    if ds.shape[0] > n:
        report.trimmed[ds.name] = ds.shape[0] - n
        ds.resize(n, axis=0)


def _trim_sync(entry: h5py.Group, report: RecoveryReport) -> int:
    sync = entry["sync"]
    columns = [sync[name] for name in (*SYNC_COLUMNS, *SWAY_COLUMNS) if name in sync]
    n = min((ds.shape[0] for ds in columns), default=0)
    if "time" in sync:
        # A real row always has a finite time; a fill row (size written, chunk not) has NaN.
        n = _keep_prefix(np.isfinite(sync["time"][:n]))
        report.end_s = float(sync["time"][n - 1]) if n else float("nan")
    for ds in columns:
        _resize(ds, n, report)
    return n


def _trim_stream(group: h5py.Group, report: RecoveryReport) -> None:
    rows = [ds for name, ds in group.items()
            if isinstance(ds, h5py.Dataset) and name not in STREAM_TABLES]
    n = min((ds.shape[0] for ds in rows), default=0)
    if "host_time_ns" in group:  # a fill row reads -1; host times are monotonic_ns >= 0
        n = _keep_prefix(group["host_time_ns"][:n] >= 0)
    for ds in rows:
        _resize(ds, n, report)
    if "gaps" in group:  # a fill row is (-1, 0); a real gap has length >= 1 or -1
        gaps = group["gaps"]
        _resize(gaps, _keep_prefix(gaps["length"][:] != 0) if gaps.shape[0] else 0, report)
    report.kept[group.name] = n


def _trim_tables(entry: h5py.Group, sync_rows: int, report: RecoveryReport) -> None:
    if "releases" in entry:
        releases = entry["releases"]
        table = releases[:]
        valid = ((table["start_index"] >= 0) & (table["stop_index"] <= sync_rows)
                 & np.isfinite(table["release_time"]))
        # Rows are appended in order: keep those before the first that is not whole.
        _resize(releases, int(np.argmin(valid)) if not valid.all() else valid.size, report)
    if "events" in entry:
        events = entry["events"]
        _resize(events, _keep_prefix(np.isfinite(events["time"][:])) if events.shape[0] else 0,
                report)


def recover_run(path: str | os.PathLike[str]) -> RecoveryReport:
    """Make a run file left open by a crashed writer readable by any HDF5 tool.

    Clears the superblock status flags (:func:`clear_status_flags`), trims each group's datasets
    to the rows written whole, and marks the run: ``/entry`` attributes ``recovered`` (ISO 8601
    UTC) and ``recovered_note``, ``/entry/metadata/recovery`` (the superblock flags found, rows
    trimmed per dataset) and a ``file_recovered`` event at the last kept sync time.

    Parameters
    ----------
    path : path-like
        A windrig run file.

    Returns
    -------
    RecoveryReport
        ``recovered`` is False, and the file untouched, if it had been closed cleanly.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    NotARunFileError
        If it is a directory, not an HDF5 file, or not a windrig run file.
    RecoveryError
        If another process still has it open (a writer still recording) or its superblock is
        damaged.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    if path.is_dir():
        raise NotARunFileError(f"{path}: a directory, not a run file")
    flags = read_superblock(path).flags
    report = RecoveryReport(path=str(path), flags_before=flags, recovered=False)
    try:  # check the layout before any write
        with open_run_file(path) as f:
            # The sync view is what readers need; raw streams are optional (the smallest
            # run file of docs/reference/file_format.md, written by another program, has none).
            missing = [p for p in ("entry/sync",) if p not in f]
            before = f["entry"].attrs.get("recovered") if "entry" in f else None
    except (OSError, RuntimeError, KeyError, ValueError) as exc:  # h5py's, on a damaged file
        raise RecoveryError(f"{path}: HDF5 cannot read it even read-only ({exc}): more is "
                            "damaged than a crash leaves") from exc
    if missing:
        raise NotARunFileError(f"{path}: has no /{missing[0]}: not a windrig run file")
    if before is not None:
        report.recovered_before = before.decode() if isinstance(before, bytes) else str(before)
    if flags == 0:
        return report
    writers = holders(path)
    if writers:
        raise RecoveryError(f"{path}: still open in process {', '.join(map(str, writers))} "
                            "(a recording in progress?); recover a file only once its writer "
                            "has ended")
    clear_status_flags(path)
    try:
        with h5py.File(path, "r+") as f:
            entry = f["entry"]
            report.sync_rows = _trim_sync(entry, report)
            for group in (entry["instrument"].values() if "instrument" in entry else ()):
                if isinstance(group, h5py.Group):
                    _trim_stream(group, report)
            _trim_tables(entry, report.sync_rows, report)
            _mark(entry, report)
    except (OSError, RuntimeError, KeyError, ValueError) as exc:
        raise RecoveryError(f"{path}: the status flags are cleared, but HDF5 failed while "
                            f"trimming ({exc}): the file is damaged beyond what a crash leaves; "
                            "it still opens read-only") from exc
    report.recovered = True
    return report


def _mark(entry: h5py.Group, report: RecoveryReport) -> None:
    """Write the attributes, metadata entry and event that say the run was recovered."""
    when = now_iso()
    note = ("the writer ended without closing the file (a crash); windrig recover cleared the "
            "HDF5 status flags and trimmed a partly written last append")
    entry.attrs["recovered"] = when
    entry.attrs["recovered_note"] = note
    meta = entry.require_group("metadata")
    name = "recovery" if "recovery" not in meta else f"recovery_{len(meta)}"
    trimmed = {path.strip("/").replace("/", "__"): n for path, n in report.trimmed.items()}
    record: dict[str, Any] = {"time": when, "status_flags_found": report.flags_before,
                              "sync_rows": report.sync_rows, "end_s": report.end_s}
    if trimmed:
        record["rows_trimmed"] = trimmed
    write_metadata(meta, name, record)
    if "events" in entry:
        events = entry["events"]
        # After the last kept row and the last event: the table stays in time order.
        times = events["time"][:] if events.shape[0] else np.zeros(0)
        t = float(np.nanmax(np.concatenate(([report.end_s, 0.0], times))))
        text = f"windrig recover: {note} " + json.dumps({"sync_rows": report.sync_rows,
                                                         "rows_trimmed": sum(trimmed.values())})
        row = np.zeros(1, dtype=events.dtype)
        row["time"], row["kind"], row["text"] = t, RECOVERED_EVENT, text
        append_rows(events, events.shape[0], row)
