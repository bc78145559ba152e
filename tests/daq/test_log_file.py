"""``windrig acquire --log-file``: the run's log on disk, errors with their traceback (issue 17).

A real (simulated) acquisition writes its log; a refused one logs its traceback in the file
while the terminal gets one ``error:`` line; a log file that cannot be opened is refused before
anything starts.
"""

from __future__ import annotations

import logging
import re
from datetime import datetime

import pytest

from daq.cli import main
from daq.log_file import close_log_file, open_log_file

from support.configs import SIM_FLAT_PLATE

CONFIG = SIM_FLAT_PLATE
LINE = re.compile(r"^(\S+) (DEBUG|INFO|WARNING|ERROR)\s+(\S+) \[([^\]]+)\] (.*)$")


@pytest.mark.slow
@pytest.mark.realtime  # a simulated acquisition: the rig in a process of its own
def test_an_acquisition_writes_its_log(tmp_path, capsys):
    log = tmp_path / "run.log"
    argv = ["acquire", "--config", str(CONFIG), "--simulate", "--duration", "1.5", "--out",
            str(tmp_path / "run.h5"), "--log-file", str(log)]
    assert main(argv) == 0
    assert capsys.readouterr().out.startswith(f"wrote {tmp_path / 'run.h5'}")
    records = [LINE.match(line) for line in log.read_text().splitlines()]
    assert all(records), log.read_text()
    for record in records:
        datetime.fromisoformat(record.group(1))
    messages = [(r.group(3), r.group(5)) for r in records if r is not None]
    assert messages[0][0] == "daq.cli" and messages[0][1].startswith("windrig ")
    assert "--log-file" in messages[0][1]
    assert any(name == "daq.acquisition.engine" and text.startswith("acquisition started")
               for name, text in messages)
    assert any(text.startswith("acquisition stopped (duration)") for _, text in messages)
    assert messages[-1] == ("daq.cli", "acquire ended, exit status 0")
    assert not logging.getLogger("daq").handlers  # removed again


def test_a_refused_run_logs_its_traceback_and_prints_one_line(tmp_path, capsys):
    log = tmp_path / "run.log"
    log.write_text("earlier run\n")
    code = main(["acquire", "--config", str(CONFIG), "--simulate", "--duration", "1", "--out",
                 str(tmp_path / "missing" / "run.h5"), "--log-file", str(log)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and err[0].startswith("error: ") and "missing" in err[0]
    text = log.read_text()
    assert text.startswith("earlier run\n")  # appended to
    assert "acquire ended with an error" in text and "Traceback (most recent call last)" in text
    assert "StorageError" in text


@pytest.mark.parametrize(("name", "message"), [
    ("missing/run.log", "missing/run.log: No such file or directory"),
    (".", "Is a directory (give a file name)"),
])
def test_a_log_file_that_cannot_be_opened_is_refused_first(tmp_path, capsys, name, message):
    out = tmp_path / "run.h5"
    code = main(["acquire", "--config", str(CONFIG), "--simulate", "--duration", "1", "--out",
                 str(out), "--log-file", str(tmp_path / name)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not out.exists()  # nothing was recorded


def test_open_log_file_checks_the_level_and_closes(tmp_path):
    with pytest.raises(ValueError, match="log level 'LOUD'"):
        open_log_file(tmp_path / "x.log", "LOUD")
    handler = open_log_file(tmp_path / "x.log", "WARNING")
    logging.getLogger("ident.something").info("not written")
    logging.getLogger("simulators.x").warning("written")
    close_log_file(handler)
    logging.getLogger("daq").warning("after the close")
    lines = (tmp_path / "x.log").read_text().splitlines()
    assert len(lines) == 1 and lines[0].endswith("simulators.x [MainThread] written")
