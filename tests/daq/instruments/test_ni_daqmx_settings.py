"""The NI-DAQmx drivers' rig-config keys and URL: each mistake is one ConfigError naming it."""

from __future__ import annotations

import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.errors import ConfigError
from daq.instruments.ni_daqmx.address import TaskAddress
from daq.instruments.ni_daqmx.settings import LinearScale

from support.configs import CONFIGS

NIDAQ = (CONFIGS / "sim_flat_plate_nidaq.toml").read_text()
SCALE = 'scale = { gain = 5.0, offset = 0.0, units = "mm", valid_volts = [-0.1, 10.0] }'


def test_the_shipped_config_parses_with_its_scales():
    config = parse_rig_config(NIDAQ, "nidaq")
    lasers = config.by_role("lasers")
    assert [inst.settings["channel"] for inst in lasers] == ["ai0", "ai1", "ai2"]
    assert {inst.url for inst in lasers} == {
        "nidaqmx://Dev1/ai0:2?trigger=port0/line0&min=-10&max=10&terminal=diff"}


@pytest.mark.parametrize(("old", "new", "names"), [
    (SCALE, SCALE.replace('"mm"', '"Pa"'), "units = 'Pa'"),
    (SCALE, SCALE.replace("gain = 5.0", "gain = 0.0"), "gain = 0"),
    (SCALE, SCALE.replace("gain = 5.0", "gain = nan"), "gain"),
    (SCALE, SCALE.replace("offset = 0.0", 'offset = "zero"'), "offset must be a number"),
    (SCALE, SCALE.replace("[-0.1, 10.0]", "[10.0, -0.1]"), "valid_volts"),
    (SCALE, SCALE.replace(", offset = 0.0", ""), "missing required key(s) ['offset']"),
    (SCALE, SCALE.replace("}", ", volts = 3 }"), "unknown key(s) ['volts']"),
    ('channel = "ai0"', 'channel = "ao0"', "channel = 'ao0'"),
    ("rate_hz = 2000.0", "rate_hz = -1.0", "rate_hz"),
])
def test_a_bad_scale_or_key_is_one_error_naming_it(old, new, names):
    text = NIDAQ.replace(old, new, 1)
    assert text != NIDAQ
    with pytest.raises(ConfigError) as info:
        parse_rig_config(text, "nidaq.toml")
    message = str(info.value)
    assert "\n" not in message and names in message and "[[lasers]] #0" in message


@pytest.mark.parametrize(("url", "names"), [
    ("nidaqmx://Dev1/ao0", "'ao0' is not an analog input"),
    ("nidaqmx://Dev1/ai3:1", "runs backwards"),
    ("nidaqmx://Dev1/ai0?trigger=pfi0", "trigger='pfi0'"),
    ("nidaqmx://Dev1/ai0?min=5&max=1", "min=5 V must be below max=1 V"),
    ("nidaqmx://Dev1/ai0?buffer_s=0.001", "buffer_s=0.001"),
    ("nidaqmx://Dev1/ai0?standin=10.0.0.1:5", "loopback only"),
    ("nidaqmx://Dev1/ai0?rate=5", "unknown query key(s) ['rate']"),
    ("tcp://Dev1/ai0", "nidaqmx://DEVICE"),
])
def test_a_bad_url_is_one_error_naming_the_part(url, names):
    with pytest.raises(ConfigError, match=None) as info:
        TaskAddress.parse(url)
    assert names in str(info.value) and url in str(info.value)


def test_a_url_expands_ranges_and_lists():
    address = TaskAddress.parse("nidaqmx://cDAQ1Mod1/ai0:2,ai5?trigger=ctr0&max=5&min=-5")
    assert address.channels == ("ai0", "ai1", "ai2", "ai5")
    assert address.counter_trigger and (address.min_v, address.max_v) == (-5.0, 5.0)
    assert address.physical("ai5") == "cDAQ1Mod1/ai5"
    assert address.buffer_samples(2000.0) == 20000  # 10 s by default


def test_a_scale_delivers_si_units_and_inverts():
    scale = LinearScale.from_table({"gain": 5.0, "offset": 1.0, "units": "mm"}, "t")
    volts = np.array([0.0, 2.0])
    assert scale.si_units == "m"
    assert np.allclose(scale.apply(volts), [1e-3, 11e-3])
    assert np.allclose(scale.volts_of(scale.apply(volts)), volts)


def test_an_analog_pitot_must_be_a_pressure():
    text = NIDAQ + '''
[[analog]]
name = "pitot_daq"
driver = "ni_daqmx_analog"
url = "nidaqmx://Dev1/ai3"
rate_hz = 2000.0
channels = [{ name = "pitot", channel = "ai3", gain = 100.0, offset = 0.0, units = "m/s" }]
'''
    with pytest.raises(ConfigError, match="'pitot' gives the dynamic pressure"):
        parse_rig_config(text, "nidaq.toml")
    ok = parse_rig_config(text.replace('units = "m/s"', 'units = "Pa"'), "nidaq.toml")
    assert [inst.name for inst in ok.by_role("analog")] == ["pitot_daq"]
