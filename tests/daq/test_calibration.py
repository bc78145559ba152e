"""Calibration keys of the rig config (daq.calibration).

Parsed, applied, and every bad value a ConfigError naming its key.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from daq.calibration import LaserCalibration, PitotCalibration
from daq.config import parse_rig_config
from daq.errors import ConfigError
from daq.recording.devices import ScannerRawRows
from daq.recording.sync_view import polled_conditions, tap_columns
from ident.physics.air import moist_air_density

from support.configs import CONFIGS, SIM_FLAT_PLATE

BASE = SIM_FLAT_PLATE.read_text()
TAPS_LINE = "taps_per_face = 28          # 2 x 28 on the faces + 2 x 3 on the edges = 62 taps\n"
N_TAPS = 62


def with_taps(extra: str, base: str = BASE) -> str:
    """Return the shipped flat-plate config with ``extra`` lines in its [taps] table."""
    assert TAPS_LINE in base
    return base.replace(TAPS_LINE, TAPS_LINE + extra + "\n")


def two_modules(text: str) -> str:
    return text.replace("modules = 1\n", "modules = 2\n")


def wiring(pairs: list[tuple[int, int]]) -> str:
    return "channels = [" + ", ".join(f"[{m}, {c}]" for m, c in pairs) + "]"


REVERSED = [(1, 61 - i) for i in range(N_TAPS)]  # module 1, channels 61 .. 0


def test_without_calibration_keys_nothing_changes():
    """The shipped simulated rigs parse to the identity calibration: today's behaviour."""
    for path in sorted(CONFIGS.glob("sim_*.toml")):
        cal = parse_rig_config(path.read_text(), path.name).calibration
        assert cal.taps.dead == () and not cal.taps.configured
        assert cal.pitot.dynamic_pressure(50.0) == 50.0
        assert cal.air.relative_humidity is None and cal.span is None and dict(cal.lasers) == {}
        assert cal.tap_channels(4) == (0, 1, 2, 3)


def test_a_full_calibration_is_read():
    text = two_modules(with_taps(wiring(REVERSED) + '\ndead = [3, 40]\nsource = "survey"\n'
                                 "date = 2026-11-20"))
    text = text.replace("[section]\n", "[section]\nspan = 0.6\n")
    text = text.replace("wind_per_rpm = 0.01         # (m/s)/rpm, tunnel calibration\n",
                        "wind_per_rpm = 0.01\n[tunnel.pitot]\nfan_rpm = [0, 1000]\n"
                        "factor = [1.1, 1.0]\noffset_pa = 0.5\ndate = 2026-11-18T09:30:00Z\n")
    text = text.replace("[fan]\n", "[lasers.calibration]\ngain = 1.01\noffset_mm = -0.2\n"
                                   "angle_deg = 5.0\n\n[fan]\n")
    text += "\n[air]\nrelative_humidity = 0.45\nco2_mole_fraction = 0.0005\n"
    cal = parse_rig_config(text, "full.toml").calibration
    assert cal.tap_channels(N_TAPS)[:2] == (64 + 61, 64 + 60)
    assert cal.taps.dead == (3, 40) and cal.taps.source == "survey"
    assert cal.taps.date == "2026-11-20" and cal.span == 0.6
    assert cal.pitot.fan_rpm == (0.0, 1000.0) and cal.pitot.date == "2026-11-18T09:30:00+00:00"
    laser = cal.laser("laser_check")  # the last [[lasers]] before [lasers.calibration]
    assert laser.gain == 1.01 and laser.offset_m == pytest.approx(-2e-4)
    assert cal.laser("laser_front") == LaserCalibration()
    assert cal.air.relative_humidity == 0.45 and cal.air.co2_mole_fraction == 0.0005
    records = cal.records(N_TAPS)
    assert set(records) == {"taps", "pitot", "air", "laser_laser_check", "section"}
    assert list(records["taps"][0]["dead"]) == [3, 40]
    assert records["pitot"][1]["configured"] == "yes"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (two_modules(with_taps(wiring(REVERSED[:-1]))),
         r"\[taps\] channels must list one \[module, channel\] per tap: 62 taps, got 61"),
        (two_modules(with_taps(wiring(REVERSED[:-1])[:-1] + ", 7]")),
         r"\[taps\] channels: entry 61 must be \[module, channel\]"),
        (with_taps(wiring(REVERSED)),
         r"\[taps\] channels: tap 0 = \[1, 61\] is outside the scanner: module in \[0, 0\]"),
        (two_modules(with_taps(wiring([(0, 64)] + REVERSED[1:]))),
         r"\[taps\] channels: tap 0 = \[0, 64\] is outside .* channel in \[0, 63\]"),
        (two_modules(with_taps(wiring([(1, 0)] + REVERSED[1:]))),
         r"\[taps\] channels: taps 0 and 61 share module 1 channel 0"),
        (two_modules(with_taps(wiring([(0, 63)] + REVERSED[1:]))),
         r"\[taps\] channels: tap 0 is on the Pitot's channel \(\[scanner\] pitot_channel = 63"),
        (with_taps('channels = "0..61"'), r"\[taps\] channels must be an array"),
        (with_taps("dead = [62]"), r"\[taps\] dead must list tap indices in \[0, 61\]"),
        (with_taps("dead = [1.5]"), r"\[taps\] dead must list tap indices"),
        (with_taps("dead = [4, 4]"), r"\[taps\] dead lists a tap twice"),
        (with_taps("dead = [56, 57, 58]"),
         r"\[taps\] dead = \[56, 57, 58\]: dead tap 56 has no live tap on its face"),
        (with_taps("source = 3"), r"\[taps\] source must be a text"),
        (with_taps('date = "20 Nov 2026"'),
         r"\[taps\] date = '20 Nov 2026' is not an ISO 8601"),
        (with_taps("date = 09:30:00"), r"\[taps\] date must be an ISO 8601 date"),
        (with_taps("shape2 = 1"),
         r"\[taps\]: taps table: missing keys \[\], unknown keys \['shape2'\]"),
    ],
)
def test_bad_tap_wiring_is_a_config_error_naming_the_key(text, match):
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(text, "bad.toml")


def test_a_tap_map_needs_a_scanner():
    no_scanner = BASE[:BASE.index("[scanner]")] + BASE[BASE.index("[[lasers]]"):]
    with pytest.raises(ConfigError, match=r"\[taps\] channels: the rig has no \[scanner\]"):
        parse_rig_config(with_taps(wiring(REVERSED), no_scanner), "bad.toml")


TUNNEL = "wind_per_rpm = 0.01         # (m/s)/rpm, tunnel calibration\n"


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ("factor = 3.0", r"\[tunnel.pitot\] factor = 3.0 is outside the allowed range"),
        ("factor = 0", r"\[tunnel.pitot\] factor = 0.0 is outside"),
        ("offset_pa = 500.0", r"\[tunnel.pitot\] offset_pa = 500.0 is outside"),
        ('factor = "1.02"', r"\[tunnel.pitot\] factor must be a number"),
        ("gain = 1.0", r"\[tunnel.pitot\]: unknown key\(s\) \['gain'\]"),
        ("fan_rpm = [0, 1000]\nfactor = [1.0]", r"\[tunnel.pitot\] factor must be an array as "
                                                r"long as fan_rpm"),
        ("fan_rpm = [1000, 500]\nfactor = [1.0, 1.1]", r"\[tunnel.pitot\] fan_rpm must increase"),
        ("fan_rpm = [0, 1000]\nfactor = [1.0, 9.0]", r"\[tunnel.pitot\] factor = 9.0 is outside"),
        ("fan_rpm = [-5, 1000]\nfactor = [1.0, 1.0]",
         r"\[tunnel.pitot\] fan_rpm = -5.0 is outside"),
        ("date = 2026-13-01", r"not valid TOML"),
        ('date = "2026-13-01"', r"\[tunnel.pitot\] date = '2026-13-01' is not an ISO 8601"),
    ],
)
def test_bad_pitot_calibration_is_a_config_error_naming_the_key(table, match):
    text = BASE.replace(TUNNEL, TUNNEL + "\n[tunnel.pitot]\n" + table + "\n")
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(text, "bad.toml")


def test_a_pitot_table_needs_a_fan():
    no_fan = BASE[:BASE.index("[fan]")] + BASE[BASE.index("[plc]"):]
    text = no_fan.replace(TUNNEL, TUNNEL + "[tunnel.pitot]\nfan_rpm = [0, 1000]\n"
                                           "factor = [1.0, 1.1]\n")
    with pytest.raises(ConfigError, match=r"\[tunnel.pitot\] fan_rpm: .* needs a \[fan\]"):
        parse_rig_config(text, "bad.toml")


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ("relative_humidity = 50", r"\[air\] relative_humidity = 50.0 is outside the allowed "
                                   r"range \[0.0, 1.0\]"),
        ('relative_humidity = "50%"', r"\[air\] relative_humidity must be a fraction in "
                                      r"\[0, 1\] \(0.5 = 50 %RH\) or \"barometer\", got '50%'"),
        ("relative_humidity = true", r"\[air\] relative_humidity must be a number"),
        ("co2_mole_fraction = 0.5", r"\[air\] co2_mole_fraction = 0.5 is outside"),
        ("humidity = 0.5", r"\[air\]: unknown key\(s\) \['humidity'\]"),
        ('relative_humidity = "hygrometer"', r"\[air\] relative_humidity must be a fraction in "
                                             r"\[0, 1\] \(0.5 = 50 %RH\) or \"barometer\""),
    ],
)
def test_bad_air_is_a_config_error_naming_the_key(table, match):
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(BASE + "\n[air]\n" + table + "\n", "bad.toml")


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ("gain = 0.0", r"\(laser_check\) \[lasers.calibration\] gain = 0.0 is outside"),
        ("offset_mm = 80.0", r"\[lasers.calibration\] offset_mm = 80.0 is outside the allowed "
                             r"range \[-50.0, 50.0\]"),
        ("angle_deg = 60.0", r"\[lasers.calibration\] angle_deg = 60.0 is outside"),
        ("tilt = 1.0", r"\[lasers.calibration\]: unknown key\(s\) \['tilt'\]"),
        ("source = false", r"\[lasers.calibration\] source must be a text"),
    ],
)
def test_bad_laser_calibration_is_a_config_error_naming_the_key(table, match):
    text = BASE.replace("[fan]\n", "[lasers.calibration]\n" + table + "\n\n[fan]\n")
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(text, "bad.toml")


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("span = 0.0", r"\[section\] span = 0.0 is outside the allowed range \(0.0, 20.0\]"),
        ("span = -1", r"\[section\] span = -1.0 is outside"),
        ('span = "0.6 m"', r"\[section\] span must be a number"),
    ],
)
def test_bad_span_is_a_config_error_naming_the_key(line, match):
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(BASE.replace("[section]\n", f"[section]\n{line}\n"), "bad.toml")


def test_section_span_and_simulated_span_must_agree():
    turbulence = ("\n[simulation.static]\nC_D = 0.02\nC_L = 0.0\nC_M = 0.0\ndC_D = 0.0\n"
                  "dC_L = -6.283\ndC_M = 1.571\n\n[simulation.turbulence]\nIu = 0.0\nIw = 0.05\n"
                  "Lux = 1.0\nLwx = 0.3\nspan = 1.0\n")
    same = BASE.replace("[section]\n", "[section]\nspan = 1.0\n") + turbulence
    assert parse_rig_config(same, "ok.toml").calibration.span == 1.0
    other = BASE.replace("[section]\n", "[section]\nspan = 0.6\n") + turbulence
    with pytest.raises(ConfigError, match=r"\[section\] span = 0.6 m disagrees with "
                                          r"\[simulation.turbulence\] span = 1.0 m"):
        parse_rig_config(other, "bad.toml")


def test_the_section_span_serves_the_simulated_turbulence():
    """[simulation.turbulence] without a span takes the section's (one model, one span)."""
    turbulence = ("\n[simulation.static]\nC_D = 0.02\nC_L = 0.0\nC_M = 0.0\ndC_D = 0.0\n"
                  "dC_L = -6.283\ndC_M = 1.571\n\n[simulation.turbulence]\nIu = 0.0\n"
                  "Iw = 0.05\nLux = 1.0\nLwx = 0.3\n")
    config = parse_rig_config(BASE.replace("[section]\n", "[section]\nspan = 0.8\n")
                              + turbulence, "ok.toml")
    assert config.simulation is not None and config.simulation.span == 0.8
    assert config.calibration.span == 0.8
    with pytest.raises(ConfigError, match=r"\[section\] span = -0.8 is outside"):
        parse_rig_config(BASE.replace("[section]\n", "[section]\nspan = -0.8\n") + turbulence,
                         "bad.toml")
    with pytest.raises(ConfigError, match=r"\[simulation.turbulence\]: missing required "
                                          r"key\(s\) \['span'\] .*or give \[section\] span"):
        parse_rig_config(BASE + turbulence, "bad.toml")


def test_pitot_calibration_is_applied_and_interpolated_on_the_fan_speed():
    """q_true = factor q_pitot + offset; a table is linear in rpm and held at its ends."""
    fixed = PitotCalibration(factor=(1.05,), offset_pa=-0.5)
    assert fixed.dynamic_pressure([100.0, 0.0]).tolist() == pytest.approx([104.5, -0.5])
    table = PitotCalibration(factor=(1.10, 1.00), fan_rpm=(200.0, 1000.0))
    assert table.dynamic_pressure(50.0, fan_rpm=600.0) == pytest.approx(52.5)
    assert table.dynamic_pressure(50.0, fan_rpm=1500.0) == pytest.approx(50.0)
    assert table.dynamic_pressure(50.0, fan_rpm=0.0) == pytest.approx(55.0)
    assert math.isnan(table.dynamic_pressure(50.0))  # no fan speed yet: no wind speed


def test_laser_calibration_projects_the_tilted_beam():
    """A beam tilted by 30 degrees reads d / cos(30): 2/sqrt(3) times the vertical distance."""
    cal = LaserCalibration(gain=2.0, offset_m=0.001, angle_rad=math.radians(30.0))
    vertical = 0.025
    reading = (vertical / math.cos(math.radians(30.0)) - 0.001) / 2.0
    assert float(cal.distance(reading)) == pytest.approx(vertical, rel=1e-12)
    assert math.isnan(float(cal.distance(math.nan)))


def test_the_barometers_humidity_needs_a_barometer():
    no_baro = BASE[:BASE.index("[barometer]")] + BASE[BASE.index("[simulation]"):]
    with pytest.raises(ConfigError, match=r"\[air\] relative_humidity = \"barometer\" needs a "
                                          r"\[barometer\]"):
        parse_rig_config(no_baro + '\n[air]\nrelative_humidity = "barometer"\n', "bad.toml")


def test_the_barometers_own_humidity_gives_the_density():
    """``relative_humidity = "barometer"``: each reading's RH; a reading without RH has none."""
    air = parse_rig_config(BASE + '\n[air]\nrelative_humidity = "barometer"\n', "air.toml")
    values = {"pressure": np.array([101325.0]), "temperature": np.array([293.15]),
              "density": np.array([1.2041]), "relative_humidity": np.array([0.3])}
    rho = polled_conditions("barometer", values, air, math.nan)[1]
    assert rho == pytest.approx(float(moist_air_density(101325.0, 293.15, 0.3)), rel=1e-12)
    values["relative_humidity"] = np.array([math.nan])  # a PTB330: no humidity, no density
    assert math.isnan(polled_conditions("barometer", values, air, math.nan)[1])


def test_humid_air_replaces_the_drivers_dry_density():
    text = BASE + "\n[air]\nrelative_humidity = 0.5\n"
    air = parse_rig_config(text, "air.toml")
    values = {"pressure": np.array([101325.0]), "temperature": np.array([293.15]),
              "density": np.array([1.2041])}
    fan, rho = polled_conditions("barometer", values, air, 700.0)
    assert fan == 700.0
    assert rho == pytest.approx(float(moist_air_density(101325.0, 293.15, 0.5)), rel=1e-12)
    dry = parse_rig_config(BASE, "dry.toml")
    assert polled_conditions("barometer", values, dry, 700.0)[1] == 1.2041
    speed = {"speed": np.array([650.0, np.nan])}
    assert polled_conditions("fan", speed, dry, 700.0) == (700.0, pytest.approx(math.nan,
                                                                                  nan_ok=True))


def test_the_raw_stream_takes_each_taps_wired_column():
    cal = parse_rig_config(two_modules(with_taps(wiring(REVERSED))), "w.toml").calibration
    columns = tap_columns(cal, N_TAPS)
    frame = np.arange(128, dtype=np.float64)[None, :] * np.ones((3, 1))
    rows = ScannerRawRows(cal.tap_channels(N_TAPS), "float32")
    table, _ = rows({"pressure": frame, "pitot": np.full(3, -1.0)}, 3)
    assert table[0, :3].tolist() == [125.0, 124.0, 123.0] and table[0, -1] == -1.0
    assert frame[:, columns][0, :3].tolist() == [125.0, 124.0, 123.0]
    assert tap_columns(parse_rig_config(BASE, "b.toml").calibration, N_TAPS) == slice(0, N_TAPS)


def test_the_example_real_rig_config_uses_every_calibration_with_its_source_and_date():
    """rig_configs/example_real_rig.toml: real transports, and each calibration key in use."""
    config = parse_rig_config((CONFIGS / "example_real_rig.toml").read_text(), "example")
    assert config.simulation is None
    schemes = {inst.name: inst.url.split(":", 1)[0] for inst in config.instruments}
    assert schemes == {"scanner": "tcp", "laser_front": "serial", "laser_rear": "serial",
                       "laser_check": "serial", "fan": "modbus+tcp", "plc": "modbus+tcp",
                       "barometer": "serial"}
    cal = config.calibration
    assert cal.taps.configured and cal.taps.dead == (17, 88)
    assert len(set(cal.tap_channels(config.taps.n_taps))) == config.taps.n_taps
    assert cal.pitot.dynamic_pressure(100.0) == pytest.approx(101.8)
    assert cal.air.relative_humidity == pytest.approx(0.45)
    assert cal.span == pytest.approx(1.2)
    assert set(cal.lasers) == {"laser_front", "laser_rear"}
    assert config.tubing and config.tubing[0].taps is None  # every tap on one tube length
    for part in (cal.taps, cal.pitot, cal.air, *cal.lasers.values()):
        assert part.source and part.date, part
