"""Driver plugins: entry points of ``windrig.drivers`` found, loaded by name, and refused clearly.

Each test installs a small distribution of its own into a folder on ``sys.path`` (a
``.dist-info`` with ``METADATA`` and ``entry_points.txt``, and its module): importlib.metadata
finds it exactly as it finds one installed by pip.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest

from daq.cli import main
from daq.errors import ConfigError, PluginError
from daq.instruments import registry

from support.configs import SIM_FLAT_PLATE

TESTS = Path(__file__).resolve().parents[1]
BUILT_IN = {"scanivalve_mps4264": "scanner", "microepsilon_ild1420": "lasers",
            "abb_acs580": "fan", "modbus_plc": "plc", "vaisala_ptb330": "barometer"}

#: A working barometer plugin's module: its DriverEntry reuses the PTB330 driver's pieces.
GOOD_MODULE = """
from daq.instruments.entry import DriverEntry
from daq.instruments.vaisala_ptb330.driver import VaisalaPtb330
from daq.instruments.vaisala_ptb330.settings import Ptb330Settings

DRIVER = DriverEntry(name={name!r}, role="barometer", factory=VaisalaPtb330,
                     validate=Ptb330Settings.from_table)
"""


def install(root: Path, dist: str, module: str, source: str, entries: dict[str, str],
            monkeypatch: pytest.MonkeyPatch, group: str = "windrig.drivers") -> None:
    """Install ``dist`` (module ``module``, ``entries``: name -> object) on sys.path."""
    root.mkdir(parents=True, exist_ok=True)
    (root / f"{module}.py").write_text(textwrap.dedent(source))
    info = root / f"{dist.replace('-', '_')}-1.2.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.2\n")
    lines = "".join(f"{name} = {value}\n" for name, value in entries.items())
    (info / "entry_points.txt").write_text(f"[{group}]\n{lines}")
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.delitem(sys.modules, module, raising=False)


def test_the_built_in_drivers_are_entry_points_of_windrig():
    """The five drivers come through the same path as a plugin's: entry points of windrig."""
    listed = {d.name: d for d in registry.available_drivers()}
    for name, role in BUILT_IN.items():
        assert listed[name].role == role
        assert listed[name].distribution.startswith("windrig ")
        assert listed[name].entry_point.startswith(f"daq.instruments.{name}.driver:")


def test_a_plugin_driver_is_loaded_by_name_only_when_asked_for(tmp_path, monkeypatch):
    """Listed without being asked for by a config; imported at first use, then cached."""
    install(tmp_path, "lab-baro", "lab_baro_plugin", GOOD_MODULE.format(name="lab_baro"),
            {"lab_baro": "lab_baro_plugin:DRIVER"}, monkeypatch)
    assert "lab_baro_plugin" not in sys.modules
    entry = registry.driver_entry("lab_baro")
    assert "lab_baro_plugin" in sys.modules
    assert (entry.name, entry.role) == ("lab_baro", "barometer")
    assert registry.driver_entry("lab_baro") is entry


def test_windrig_drivers_lists_built_in_and_plugin_drivers(tmp_path, monkeypatch, capsys):
    install(tmp_path, "lab-baro2", "lab_baro2_plugin", GOOD_MODULE.format(name="lab_baro2"),
            {"lab_baro2": "lab_baro2_plugin:DRIVER"}, monkeypatch)
    assert main(["drivers"]) == 0
    out = capsys.readouterr().out.splitlines()
    row = next(line for line in out if line.startswith("lab_baro2 "))
    assert row.split()[:4] == ["lab_baro2", "barometer", "lab-baro2", "1.2"]
    assert any(line.startswith("scanivalve_mps4264 ") and " scanner " in line for line in out)
    assert main(["drivers", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["warnings"] == []
    by_name = {d["name"]: d for d in report["drivers"]}
    assert by_name["lab_baro2"]["distribution"] == "lab-baro2 1.2"
    assert set(BUILT_IN) <= set(by_name)


def test_a_rig_config_names_a_plugin_driver_as_a_built_in_one(tmp_path, monkeypatch):
    install(tmp_path / "site", "lab-baro3", "lab_baro3_plugin",
            GOOD_MODULE.format(name="lab_baro3"), {"lab_baro3": "lab_baro3_plugin:DRIVER"},
            monkeypatch)
    from daq.config import load_rig_config

    config = tmp_path / "rig.toml"
    config.write_text((TESTS / "minimal_rig.toml").read_text()
                      + '\n[barometer]\ndriver = "lab_baro3"\nurl = "loop://"\n')
    inst = load_rig_config(config).instrument("barometer")
    assert (inst.driver, inst.role) == ("lab_baro3", "barometer")


@pytest.mark.parametrize("case, source, value, expected", [
    ("import", "import no_such_module_of_anyone\n", "DRIVER",
     "cannot be imported (distribution lab-broken-import 1.2, entry point broken_import = "
     "broken_import_plugin:DRIVER): ModuleNotFoundError: No module named "
     "'no_such_module_of_anyone'"),
    ("object", "DRIVER = {'name': 'broken_object'}\n", "DRIVER",
     "driver plugin 'broken_object' is a dict, not a daq.instruments.entry.DriverEntry "
     "(distribution lab-broken-object 1.2, entry point broken_object = "
     "broken_object_plugin:DRIVER)"),
    ("name", GOOD_MODULE.format(name="some_other_name"), "DRIVER",
     "holds the entry of driver 'some_other_name'"),
])
def test_a_broken_plugin_is_one_error_line_naming_its_distribution(
        tmp_path, monkeypatch, capsys, case, source, value, expected):
    name = f"broken_{case}"
    install(tmp_path / "site", f"lab-broken-{case}", f"{name}_plugin", source,
            {name: f"{name}_plugin:{value}"}, monkeypatch)
    with pytest.raises(PluginError, match="distribution lab-broken-"):
        registry.driver_entry(name)
    config = tmp_path / "rig.toml"
    config.write_text((TESTS / "minimal_rig.toml").read_text()
                      + f'\n[barometer]\ndriver = "{name}"\nurl = "loop://"\n')
    assert main(["check", "--config", str(config)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and expected in err
    assert "Traceback" not in err
    # windrig drivers still lists the others, and says what is wrong with this one.
    assert main(["drivers"]) == 1
    captured = capsys.readouterr()
    assert f"error: driver plugin {name!r}" in captured.err
    assert any(line.startswith("vaisala_ptb330 ") for line in captured.out.splitlines())


def test_two_distributions_giving_one_driver_name_are_refused(tmp_path, monkeypatch):
    for dist in ("lab-one", "lab-two"):
        install(tmp_path / dist, dist, f"{dist.replace('-', '_')}_dup",
                GOOD_MODULE.format(name="dup_baro"),
                {"dup_baro": f"{dist.replace('-', '_')}_dup:DRIVER"}, monkeypatch)
    with pytest.raises(PluginError) as info:
        registry.driver_entry("dup_baro")
    text = str(info.value)
    assert "more than one distribution" in text
    assert "lab-one 1.2" in text and "lab-two 1.2" in text and "\n" not in text


def test_an_unknown_driver_names_the_known_ones_and_the_group():
    with pytest.raises(ConfigError) as info:
        registry.driver_entry("no_such_driver")
    assert "windrig.drivers" in str(info.value) and "'vaisala_ptb330'" in str(info.value)


def test_a_driver_registered_in_code_may_not_shadow_an_installed_one():
    entry = registry.driver_entry("vaisala_ptb330")
    with pytest.raises(RuntimeError, match="installed already"):
        registry.register(entry)


def test_the_built_in_simulators_are_entry_points_too():
    from daq.sim.devices import simulator_entry

    for name in BUILT_IN:
        assert simulator_entry(name, "test").name == name


def test_a_broken_simulator_plugin_is_one_error_naming_its_distribution(tmp_path, monkeypatch):
    from daq.sim.devices import simulator_entry

    install(tmp_path, "lab-sim", "lab_sim_plugin", "SIMULATOR = object()\n",
            {"lab_sim": "lab_sim_plugin:SIMULATOR"}, monkeypatch, group="windrig.simulators")
    with pytest.raises(PluginError) as info:
        simulator_entry("lab_sim", "rig.toml")
    assert str(info.value) == (
        "simulator plugin 'lab_sim' is not the daq.sim.devices.SimulatorEntry of that driver "
        "(distribution lab-sim 1.2, entry point lab_sim = lab_sim_plugin:SIMULATOR)")
    with pytest.raises(ConfigError, match="rig.toml: no simulator for driver 'nobody'"):
        simulator_entry("nobody", "rig.toml")


@pytest.mark.parametrize("key", ["rng", "clock"])
def test_a_simulator_option_windrig_passes_itself_is_refused_in_the_config(tmp_path, key):
    """`rng = 3` in [simulation.devices.barometer] would be replaced without a word: refused."""
    from daq.config import load_rig_config
    from daq.sim.devices import VAISALA_PTB330
    from daq.sim.rig import start_simulated_rig

    assert {"clock", "rng"}.isdisjoint(VAISALA_PTB330.accepted_options())
    assert "noise_pa" in VAISALA_PTB330.accepted_options()
    source = SIM_FLAT_PLATE
    config = tmp_path / "rig.toml"
    config.write_text(source.read_text() + f"\n[simulation.devices.barometer]\n{key} = 3\n")
    with pytest.raises(ConfigError, match=rf"\[simulation.devices.barometer\]: unknown key\(s\) "
                       rf"\['{key}'\]"):
        start_simulated_rig(load_rig_config(config))


#: A barometer plugin whose validate has a bug: it raises a KeyError, not a ConfigError.
BUGGY_VALIDATE_MODULE = """
from daq.instruments.entry import DriverEntry
from daq.instruments.vaisala_ptb330.driver import VaisalaPtb330

def validate(table, where):
    return {"address": table["address"]}  # a KeyError when the table has none

DRIVER = DriverEntry(name="buggy_validate", role="barometer", factory=VaisalaPtb330,
                     validate=validate)
"""


def test_a_plugin_validate_that_raises_a_bug_is_one_line_naming_the_plugin(
        tmp_path, monkeypatch, capsys):
    """Before: the rig config's loading let the KeyError through, a traceback."""
    install(tmp_path / "site", "lab-buggy", "buggy_validate_plugin", BUGGY_VALIDATE_MODULE,
            {"buggy_validate": "buggy_validate_plugin:DRIVER"}, monkeypatch)
    from daq.config import load_rig_config

    config = tmp_path / "rig.toml"
    config.write_text((TESTS / "minimal_rig.toml").read_text()
                      + '\n[barometer]\ndriver = "buggy_validate"\nurl = "loop://"\n')
    with pytest.raises(PluginError) as info:
        load_rig_config(config)
    assert str(info.value) == (
        "driver 'buggy_validate' (distribution lab-buggy 1.2, entry point buggy_validate = "
        f"buggy_validate_plugin:DRIVER): its validate of {config} [barometer] raised KeyError: "
        "'address' (a driver raises the exceptions of daq.errors, a ConfigError for a bad "
        "setting: this is a bug of the driver)")
    assert isinstance(info.value.__cause__, KeyError)  # chained: --debug shows where
    assert main(["check", "--config", str(config)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: driver 'buggy_validate' (")
    assert "Traceback" not in err


class _BuggyFactory:
    """A barometer driver whose constructor has a bug (an AttributeError)."""

    def __init__(self, link: object, settings: object) -> None:
        self.port = link.no_such_attribute  # type: ignore[attr-defined]


def test_a_driver_factory_that_raises_a_bug_is_a_plugin_error_naming_the_instrument(tmp_path):
    """Before: build_driver let the AttributeError through (acquire --skip-check: a traceback)."""
    from daq.config import load_rig_config
    from daq.instruments.build import build_driver
    from daq.instruments.entry import DriverEntry

    from support.drivers_in_code import rigs_with_drivers

    entry = DriverEntry(name="buggy_factory", role="barometer", factory=_BuggyFactory,
                        validate=lambda table, where: dict(table))
    table = '\n[barometer]\ndriver = "buggy_factory"\nurl = "loop://"\n'
    with rigs_with_drivers(tmp_path, {"buggy": (entry, table)}) as configs:
        config = load_rig_config(configs["buggy"])
        with pytest.raises(PluginError) as info:
            build_driver(config.instrument("barometer"), config.limits)
    assert str(info.value).startswith(
        "driver 'buggy_factory' (registered in code): its factory of instrument 'barometer' "
        "raised AttributeError: ")
    assert "no_such_attribute" in str(info.value)
    assert isinstance(info.value.__cause__, AttributeError)
