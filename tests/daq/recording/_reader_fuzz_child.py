"""Helper process for tests/daq/recording/test_reader_fuzz.py (not a test module).

``python _reader_fuzz_child.py BASE.h5 WORKDIR TIMEOUT_S``
    For each JSON line on stdin, a list of mutations (``["set", offset, byte]``,
    ``["truncate", offset]``, ``["zero", offset, length]``), write BASE.h5 so mutated to WORKDIR,
    run the run-file readers on it (``ident.records.run_file.read_run``,
    ``daq.recording.info.run_info``,
    ``daq.recording.recover.recover_run`` on a copy) and print one JSON line: per reader
    ``"ok"`` or ``"<module>.<class>: <message>"``. Each reader call has TIMEOUT_S: past it,
    :mod:`faulthandler` prints the stack and ends the process (exit status 1), which the parent
    reports as a hang.
"""

from __future__ import annotations

import faulthandler
import json
import shutil
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from daq.recording.info import run_info
from daq.recording.recover import recover_run
from ident.records.run_file import read_run


def mutate(data: bytes, mutations: list[list[int | str]]) -> bytes:
    """Return ``data`` with the mutations applied in turn (offsets wrap to its length)."""
    out = bytearray(data)
    for kind, *args in mutations:
        if not out:
            break
        offset = int(args[0]) % len(out)
        if kind == "set":
            out[offset] = int(args[1])
        elif kind == "truncate":
            del out[offset:]
        elif kind == "zero":
            length = min(int(args[1]), len(out) - offset)
            out[offset:offset + length] = bytes(length)
    return bytes(out)


def outcome(call: Callable[[], Any], timeout_s: float) -> str:
    """Run ``call`` under the watchdog; return ``"ok"`` or the exception's class and text."""
    faulthandler.dump_traceback_later(timeout_s, exit=True)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            call()
    except Exception as exc:  # reported to the parent, which judges it
        return f"{type(exc).__module__}.{type(exc).__name__}: {str(exc)[:300]}"
    finally:
        faulthandler.cancel_dump_traceback_later()
    return "ok"


def main() -> None:
    base, work, timeout_s = Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3])
    data = base.read_bytes()
    path, copy = work / "fuzzed.h5", work / "fuzzed_copy.h5"
    for line in sys.stdin:
        path.write_bytes(mutate(data, json.loads(line)))
        shutil.copyfile(path, copy)
        result = {"read_run": outcome(lambda: read_run(path), timeout_s),
                  "info": outcome(lambda: run_info(path), timeout_s),
                  "recover": outcome(lambda: recover_run(copy), timeout_s)}
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
