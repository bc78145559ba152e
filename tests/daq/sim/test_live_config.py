"""A simulated rig's config rewritten with its simulators' URLs (``simulate --write-config``)."""

from __future__ import annotations

import pytest

from daq.config import parse_rig_config
from daq.errors import ConfigError
from daq.sim.live_config import live_config_text, write_live_config

from support.configs import FAST_FAN, SIM_FLAT_PLATE

CONFIG = SIM_FLAT_PLATE
EXTRA = FAST_FAN
URLS = {"scanner": "tcp://127.0.0.1:4001", "laser_front": "serial:///dev/pts/7",
        "laser_rear": "socket://127.0.0.1:4003", "laser_check": "socket://127.0.0.1:4004",
        "fan": "modbus+tcp://127.0.0.1:4005?unit=1", "plc": "modbus+tcp://127.0.0.1:4006?unit=1",
        "barometer": "serial:///dev/pts/8?bytesize=8&parity=N"}


def _config():
    return parse_rig_config(CONFIG.read_text() + EXTRA, source="sim.toml")


def test_every_url_is_replaced_and_the_simulation_tables_left_out():
    text = live_config_text(_config(), URLS, {"scanner": 4100}, note="line one\nline two")
    assert text.startswith("# line one\n# line two\n")
    rewritten = parse_rig_config(text)
    assert {i.name: i.url for i in rewritten.instruments} == URLS
    assert rewritten.instrument("scanner").settings["data_port"] == 4100
    assert rewritten.simulation is None and "[simulation" not in text
    assert "ramp_rpm_per_s" not in text  # the [simulation.devices.fan] sub-table went too
    # Everything else kept as written: the section, the taps, the comments.
    assert rewritten.section == _config().section
    assert "# m, chord" in text
    assert rewritten.instrument("laser_rear").settings == _config().instrument(
        "laser_rear").settings


def test_a_missing_url_is_refused_naming_the_instrument():
    urls = {k: v for k, v in URLS.items() if k != "plc"}
    with pytest.raises(ConfigError, match=r"no simulator URL for instrument\(s\) \['plc'\]"):
        live_config_text(_config(), urls)


def test_an_inline_url_it_cannot_rewrite_is_refused():
    text = CONFIG.read_text().replace('[barometer]\ndriver = "vaisala_ptb330"\nurl = "auto"\n',
                                      "")
    text = 'barometer = {driver = "vaisala_ptb330", url = "auto"}\n' + text  # top level
    config = parse_rig_config(text, source="inline.toml")
    with pytest.raises(ConfigError, match=r"cannot rewrite the URLs of \['barometer'\]"):
        live_config_text(config, URLS)


def test_written_atomically_with_what_it_is(tmp_path):
    out = write_live_config(_config(), URLS, tmp_path / "live.toml", {"scanner": 4100})
    text = out.read_text()
    assert text.startswith("# Written by `windrig simulate --write-config`")
    assert "valid while that command runs" in text
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left


def test_an_unwritable_destination_is_named_not_its_temporary_file(tmp_path):
    out = tmp_path / "missing" / "live.toml"
    with pytest.raises(FileNotFoundError) as caught:
        write_live_config(_config(), URLS, out, {"scanner": 4100})
    assert caught.value.filename == str(out)
