"""A simulator plugin that can be reached from outside this host is refused, in one line.

windrig's simulators bind 127.0.0.1 only (a simulated release PLC or fan drive must not be
reachable from the lab's network). A plugin's simulator is held to the same rule. Before, one
that listened on every interface (``0.0.0.0``) was started and used without a word, whatever
URL it returned. The plugin here is a distribution installed on ``sys.path`` for the test (a
``.dist-info`` with its entry points), whose simulator listens on a real socket.
"""

from __future__ import annotations

import socket
import sys
import textwrap
from pathlib import Path

import pytest

from daq.cli import main
from daq.config import load_rig_config
from daq.errors import ConfigError, PluginError
from daq.sim.rig import start_simulated_rig
from daq.sim.rig_process import start_rig_process

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

MINIMAL_RIG = Path(__file__).resolve().parents[1] / "minimal_rig.toml"

#: The plugin: a barometer driver (the PTB330's pieces) and a simulator listening on 0.0.0.0.
PLUGIN = """
import socket

from daq.instruments.entry import DriverEntry
from daq.instruments.vaisala_ptb330.driver import VaisalaPtb330
from daq.instruments.vaisala_ptb330.settings import Ptb330Settings
from daq.sim.devices import SimulatorEntry

STARTED = []


class OpenSim:
    def __init__(self, tunnel, *, url_host="0.0.0.0", clock=None, rng=None):
        self.url_host = url_host
        self.listener = None

    def start(self):
        self.listener = socket.create_server(("0.0.0.0", 0))  # every interface: the mistake
        STARTED.append(self)
        return f"socket://{self.url_host}:{self.listener.getsockname()[1]}"

    def stop(self):
        if self.listener is not None:
            self.listener.close()


DRIVER = DriverEntry(name="open_baro", role="barometer", factory=VaisalaPtb330,
                     validate=Ptb330Settings.from_table)
SIMULATOR = SimulatorEntry("open_baro", lambda tunnel, settings, **kw: OpenSim(tunnel, **kw),
                           OpenSim)
"""


@pytest.fixture
def open_plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """Install the plugin on sys.path; return its module once imported (after the test)."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "open_baro_plugin.py").write_text(textwrap.dedent(PLUGIN))
    info = site / "lab_open-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: lab-open\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[windrig.drivers]\nopen_baro = open_baro_plugin:DRIVER\n\n"
        "[windrig.simulators]\nopen_baro = open_baro_plugin:SIMULATOR\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.delitem(sys.modules, "open_baro_plugin", raising=False)
    return lambda: sys.modules["open_baro_plugin"]


def rig(tmp_path: Path, url_host: str) -> Path:
    """Write the minimal rig with the plugin's barometer, its simulator returning ``url_host``."""
    config = tmp_path / f"rig_{url_host}.toml"
    config.write_text(MINIMAL_RIG.read_text()
                      + '\n[barometer]\ndriver = "open_baro"\nurl = "auto"\n'
                      + f'\n[simulation.devices.barometer]\nurl_host = "{url_host}"\n')
    return config


def outward_address() -> str | None:
    """Return this host's address towards others (None: loopback only, nothing exposed)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))
        except OSError:
            return None
        address = probe.getsockname()[0]
    return None if address.startswith("127.") else address


def test_a_simulator_url_on_every_interface_is_refused_and_stopped(open_plugin, tmp_path):
    config = load_rig_config(rig(tmp_path, "0.0.0.0"))
    with pytest.raises(PluginError) as info:
        start_simulated_rig(config)
    text = str(info.value)
    assert text.startswith(f"{config.source}: the simulator of instrument 'barometer' (driver "
                           "'open_baro') serves socket://0.0.0.0:")
    assert "not a loopback address: simulators bind to loopback only" in text
    (sim,) = open_plugin().STARTED
    assert sim.listener.fileno() == -1  # stopped: nothing left listening


def test_a_simulator_bound_to_every_interface_is_refused_whatever_url_it_gives(
        open_plugin, tmp_path):
    config = load_rig_config(rig(tmp_path, "127.0.0.1"))
    if outward_address() is None:
        # A host with no address but loopback exposes nothing: the rig starts, and must.
        start_simulated_rig(config).close()
        (sim,) = open_plugin().STARTED
        assert sim.listener.fileno() == -1
        return
    with pytest.raises(PluginError, match=r"serves socket://127\.0\.0\.1:(\d+), but its port "
                       r"\1 also accepts connections on this host's address .* \(bound to "
                       r"every interface\)"):
        start_simulated_rig(config)
    (sim,) = open_plugin().STARTED
    assert sim.listener.fileno() == -1


def test_windrig_check_simulate_says_it_in_one_line(open_plugin, tmp_path, capsys):
    assert main(["check", "--config", str(rig(tmp_path, "0.0.0.0")), "--simulate"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err
    assert "simulators bind to loopback only" in err


def test_the_rig_process_raises_windrigs_own_errors_as_they_are(tmp_path):
    """Raise a ConfigError of the child as itself, not as a RuntimeError (a traceback).

    `windrig acquire --simulate` starts the simulated rig in a child process.
    """
    config = tmp_path / "rig.toml"
    config.write_text(SIM_FLAT_PLATE.read_text() + "\n[simulation.devices.barometer]\nrng = 3\n")
    with pytest.raises(ConfigError, match=r"\[simulation.devices.barometer\]: unknown key\(s\) "
                       r"\['rng'\]"):
        start_rig_process(load_rig_config(config))
