"""The ``windrig`` command line: flutter and identify subcommands, run in-process.

The demo (a whole simulated campaign) is tested end to end in tests/hil/test_demo_hil.py.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from daq.cli import main
from ident import SectionModel
from ident.model import flat_plate, flutter

from support.configs import SIM_FLAT_PLATE
from support.run_files import write_run
from support.sections import FLAT_PLATE


def test_flutter_command_reads_json_section_and_model(tmp_path, capsys):
    """`windrig flutter` gives the same speed as the library call."""
    section = SectionModel(B=0.4, m=8.0, I=0.12, fh=1.5, fa=3.5, zeta_h=0.003, zeta_a=0.003)
    (tmp_path / "s.json").write_text(json.dumps(section.to_dict()))
    (tmp_path / "m.json").write_text(json.dumps(flat_plate.jones_model().to_dict()))
    assert main(["flutter", "--section", str(tmp_path / "s.json"),
                 "--model", str(tmp_path / "m.json")]) == 0
    expected = flutter.analyze(section, flat_plate.jones_model()).speed
    assert f"flutter at U = {expected:.4g} m/s" in capsys.readouterr().out


def test_flutter_command_refuses_an_unknown_section_key(tmp_path, capsys):
    """A misspelt key in the section file is an error naming it, not a silent default."""
    data = SectionModel(B=0.4, m=8.0, I=0.12, fh=1.5, fa=3.5, zeta_h=0.0, zeta_a=0.0).to_dict()
    data["zeta_alpha"] = 0.01
    (tmp_path / "s.json").write_text(json.dumps(data))
    (tmp_path / "m.json").write_text(json.dumps(flat_plate.jones_model().to_dict()))
    assert main(["flutter", "--section", str(tmp_path / "s.json"),
                 "--model", str(tmp_path / "m.json")]) == 2
    assert "zeta_alpha" in capsys.readouterr().err


def test_flutter_command_names_a_section_unit_slip(tmp_path, capsys):
    """A mass in g/m gives "no flutter" within the search, now with the slip named."""
    (tmp_path / "s.json").write_text(json.dumps(FLAT_PLATE.replace(m=3000.0).to_dict()))
    (tmp_path / "m.json").write_text(json.dumps(flat_plate.jones_model().to_dict()))
    out = tmp_path / "out.json"
    assert main(["flutter", "--section", str(tmp_path / "s.json"), "--model",
                 str(tmp_path / "m.json"), "--json", str(out)]) == 0
    printed = [line for line in capsys.readouterr().out.splitlines()
               if line.startswith("warning: ") and "m looks like g/m" in line]
    assert len(printed) == 1
    assert any("m looks like g/m" in w for w in json.loads(out.read_text())["warnings"])


def test_flutter_command_prints_the_table_s_findings_before_its_error(tmp_path, capsys):
    """Print the warning that names a table's Ur headed K before the error it causes.

    The plate's table with Ur = 2 pi / K under a K header stops the analysis (a mode grows
    in still air); the warning was lost with the error.
    """
    K = np.geomspace(0.2, 3.0, 15)[::-1]
    fd = flat_plate.flutter_derivatives(K)
    names = ("H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4")
    rows = [",".join(["K", *names])] + [
        ",".join(f"{x:.6g}" for x in (2 * math.pi / K[i], *(fd[n][i] for n in names)))
        for i in range(K.size)]
    (tmp_path / "t.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "s.json").write_text(json.dumps(FLAT_PLATE.to_dict()))
    code = main(["flutter", "--section", str(tmp_path / "s.json"), "--table",
                 str(tmp_path / "t.csv")])
    captured = capsys.readouterr()
    assert code != 0 and captured.err.startswith("error: ")
    (warning,) = [line for line in captured.out.splitlines() if line.startswith("warning: ")]
    assert "the first column looks like the reduced velocity Ur" in warning


def test_flutter_command_in_three_degrees_of_freedom(tmp_path, capsys):
    """A section with sway and a 3-DOF model: the library's speed; the JSON has 3x3 A."""
    from ident.model.quasi_steady import StaticCoefficients, quasi_steady_model

    section = SectionModel(B=0.4, m=8.0, I=0.12, fh=1.5, fa=3.5, zeta_h=0.003, zeta_a=0.003,
                           fp=1.1, zeta_p=0.004)
    sway = quasi_steady_model(StaticCoefficients(C_D=0.6, C_L=-0.2, C_M=0.05, dC_D=-0.5,
                                                 dC_L=-5.0, dC_M=1.3))
    model = flat_plate.jones_model().with_sway(sway)
    (tmp_path / "s.json").write_text(json.dumps(section.to_dict()))
    (tmp_path / "m.json").write_text(json.dumps(model.to_dict()))
    out = tmp_path / "out.json"
    assert main(["flutter", "--section", str(tmp_path / "s.json"), "--model",
                 str(tmp_path / "m.json"), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    expected = flutter.analyze(section, model)
    assert result["flutter_speed"] == pytest.approx(expected.speed, rel=1e-12)
    assert result["n_dof"] == 3 and len(result["model"]["A"][0]) == 3
    # The frequency-domain check agrees (both refine to ~1e-12; 1e-6 is their grids' margin).
    assert result["flutter_speed_frequency_domain"] == pytest.approx(expected.speed, rel=1e-6)
    assert capsys.readouterr().err == ""


def test_flutter_command_from_a_table_in_z_up_signs(tmp_path, capsys):
    """Theodorsen's plate as a z-up table: read with --convention z_up, the exact speed.

    The table (40 rows, K 0.1 to 3) is fitted with rational functions for the state space
    (its lags chosen by held-out rows) and interpolated for the frequency domain: both within
    0.2 % of the exact frequency-domain speed (measured: under 0.05 %). Read with windrig's own
    signs, the same file gives another answer (+16 %): the convention matters and is not
    guessed. It matters through the static unbalance S: flipping h and L together is a change
    of coordinates that a section without S does not see.
    """
    import numpy as np

    section = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005,
                           S=0.02)
    K = np.geomspace(0.1, 3.0, 40)
    fd = flat_plate.flutter_derivatives(K)
    flips = {"H2", "H3", "A1", "A4"}
    names = ["H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4"]
    rows = [",".join([repr(float(k))] + [repr(float(-fd[n][i] if n in flips else fd[n][i]))
                                         for n in names]) for i, k in enumerate(K)]
    (tmp_path / "t.csv").write_text("K," + ",".join(f"{n}*" for n in names) + "\n"
                                     + "\n".join(rows) + "\n")
    (tmp_path / "s.json").write_text(json.dumps(section.to_dict()))
    exact = flutter.frequency_domain(section, flat_plate.flutter_derivatives).speed
    out = tmp_path / "out.json"
    assert main(["flutter", "--section", str(tmp_path / "s.json"), "--table",
                 str(tmp_path / "t.csv"), "--convention", "z_up", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["flutter_speed"] == pytest.approx(exact, rel=0.002)
    assert result["flutter_speed_frequency_domain"] == pytest.approx(exact, rel=0.002)
    assert max(result["table_fit_relative_error"]) < 0.01
    assert "lag(s)" in capsys.readouterr().out
    assert main(["flutter", "--section", str(tmp_path / "s.json"), "--table",
                 str(tmp_path / "t.csv"), "--json", str(out)]) == 0
    wrong = json.loads(out.read_text())["flutter_speed"]
    assert wrong is None or abs(wrong / exact - 1.0) > 0.1


def test_flutter_command_gives_the_iabse_benchmark_flutter_speed(tmp_path, capsys):
    """The IABSE superstructure benchmark, step 1.1a: a 2-DOF flat plate, 77.45 m/s within 1 %.

    Section data of the benchmark (B = 31 m, m = 22 740 kg/m, I = 2.47e6 kg m^2/m, f_h =
    0.100 Hz, f_alpha = 0.278 Hz, damping 0.3 %, rho = 1.22 kg/m^3) and Theodorsen's flutter
    derivatives, given as a table over reduced velocities Ur = U/(f B) (30 rows, 1 to 60) as a
    published table would be; 1 % is the issue's tolerance for the benchmark's 77.45 m/s.
    """
    import numpy as np

    section = SectionModel(B=31.0, m=22740.0, I=2.47e6, fh=0.100, fa=0.278, zeta_h=0.003,
                           zeta_a=0.003, rho=1.22)
    Ur = np.geomspace(1.0, 60.0, 30)
    fd = flat_plate.flutter_derivatives(2 * np.pi / Ur)
    names = ["H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4"]
    rows = [",".join([repr(float(u))] + [repr(float(fd[n][i])) for n in names])
            for i, u in enumerate(Ur)]
    (tmp_path / "iabse.csv").write_text("Ur," + ",".join(names) + "\n" + "\n".join(rows) + "\n")
    (tmp_path / "s.json").write_text(json.dumps(section.to_dict()))
    out = tmp_path / "out.json"
    assert main(["flutter", "--section", str(tmp_path / "s.json"), "--table",
                 str(tmp_path / "iabse.csv"), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["flutter_speed"] == pytest.approx(77.45, rel=0.01)
    assert result["flutter_speed_frequency_domain"] == pytest.approx(77.45, rel=0.01)
    assert "flutter at U" in capsys.readouterr().out


def test_unknown_subcommand_exits_with_usage(capsys):
    """An unknown command is rejected by argparse with exit status 2."""
    with pytest.raises(SystemExit) as exc:
        main(["fly"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


@pytest.mark.realtime  # starts the simulated instruments on loopback sockets
def test_simulate_prints_a_loopback_url_for_every_instrument(capsys):
    """`windrig simulate` starts the rig's simulators and lists where to connect."""
    config = SIM_FLAT_PLATE
    assert main(["simulate", "--config", str(config), "--duration", "0.2"]) == 0
    out = capsys.readouterr().out
    for name in ("scanner", "laser_front", "laser_rear", "laser_check", "fan", "plc",
                 "barometer"):
        line = next(line for line in out.splitlines() if line.strip().startswith(name))
        assert "127.0.0.1:" in line
    assert "binary data port" in out


def test_identify_reads_run_files_and_prints_the_flutter_speed(tmp_path, capsys):
    """`windrig identify` on recorded files gives the flutter speed of the simulated truth."""
    files = []
    for i in range(2):  # two files, two wind speeds each: the campaign spans files
        files.append(tmp_path / f"run{i}.h5")
        write_run(files[-1])
    out_json = tmp_path / "model.json"
    assert main(["identify", *map(str, files), "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "4 release(s) from 2 file(s)" in out
    result = json.loads(out_json.read_text())
    truth = flutter.analyze(FLAT_PLATE, flat_plate.jones_model())
    # Noise-free records (4 s at 200 Hz): E2RFC is exact up to solver tolerances.
    assert result["flutter_speed"] == pytest.approx(truth.speed, rel=1e-4)
    # The 2-std interval, printed and written: around the estimate, beyond the stable speeds.
    low, high = result["flutter_speed_interval"]
    assert low <= result["flutter_speed"] <= high
    assert f"2-std interval {low:.3f} to {high:.3f} m/s" in out


def test_identify_names_a_bad_file(tmp_path, capsys):
    """A file that is not a run file is reported by name (its exception with --debug)."""
    from ident.records.run_file import FileFormatError

    junk = tmp_path / "junk.h5"
    junk.write_text("junk")
    assert main(["identify", str(junk)]) == 2
    assert "junk.h5" in capsys.readouterr().err
    with pytest.raises(FileFormatError, match="junk.h5"):
        main(["--debug", "identify", str(junk)])


def test_identify_s_turbulence_choices_are_e2rfc_s_names():
    """The CLI lists its choices literally (a fast ``--help`` imports no numerics): the same."""
    import argparse

    from daq.campaign import plan
    from daq.cli import _build_parser

    parser = _build_parser()
    identify = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)
                    ).choices["identify"]
    choices = {a.dest: tuple(a.choices) for a in identify._actions if a.choices is not None}
    assert choices["closed_loop_buffeting"] == plan.CLOSED_LOOP_BUFFETINGS
    assert choices["turbulent_estimator"] == plan.TURBULENT_ESTIMATORS
