"""``windrig identify`` on run files converted wrongly: the guards' error line and warnings.

Run files are written by the acquisition's own recorder (:mod:`daq.recording.synthetic`) from
simulated releases of the flat-plate rig (``rig_configs/sim_flat_plate.toml``, Jones's
aerodynamics) at 6 and 8 m/s, two holds each, 1 s held before each release (0.2 % of each
displacement's RMS as noise, 1 % on the forces), then converted as a lab's script might have:
the pitch left in degrees, the forces total over a 0.9 m span.
"""

from __future__ import annotations

import json
import re
import types

import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate
from simulators.tunnel import simulate_release

from support.configs import SIM_FLAT_PLATE

CONFIG = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
TRUTH = flat_plate.jones_model()
NOISE = {"h": 0.002, "alpha": 0.002, "lift": 0.01, "moment": 0.01}


@pytest.fixture(scope="module")
def sims():
    return [simulate_release(CONFIG.section, TRUTH, U, h0, alpha0, duration=6.0, fs=500.0,
                             pre_s=1.0, noise=NOISE, rng=10 * k + j)
            for k, U in enumerate((6.0, 8.0))
            for j, (h0, alpha0) in enumerate(((0.008, 0.04), (0.006, 0.03)))]


def _converted(sims, **scale):
    """Return the releases with channels multiplied as a wrong conversion would."""
    return [types.SimpleNamespace(t=s.t, U=s.U, rho=s.rho,
                                  **{c: scale.get(c, 1.0) * getattr(s, c)
                                     for c in ("h", "alpha", "lift", "moment")})
            for s in sims]


def test_a_pitch_in_degrees_is_one_error_line_naming_it(sims, tmp_path, capsys):
    run = tmp_path / "degrees.h5"
    write_release_run(run, CONFIG, _converted(sims, alpha=180.0 / np.pi))
    code = main(["identify", str(run)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1
    assert err[0].startswith("error: ") and "alpha looks like degrees" in err[0]


def test_forces_over_the_span_are_a_printed_and_json_warning(sims, tmp_path, capsys):
    run, out = tmp_path / "span.h5", tmp_path / "span.json"
    write_release_run(run, CONFIG, _converted(sims, lift=0.9, moment=0.9))
    assert main(["identify", str(run), "--json", str(out)]) == 0
    printed = [line for line in capsys.readouterr().out.splitlines()
               if line.startswith("warning: the forces are")]
    assert len(printed) == 1 and "per unit span" in printed[0]
    warnings = json.loads(out.read_text())["warnings"]
    found = [w for w in warnings if w.startswith("the forces are")]
    assert len(found) == 1
    # Fitted from the modes' eigenvalue shifts (1 % force noise): within 2 % of 0.9.
    factor = float(re.search(r"the forces are ([0-9.]+) times", found[0]).group(1))
    assert factor == pytest.approx(0.9, rel=0.02)


def test_rightly_converted_files_carry_no_guard_warning(sims, tmp_path):
    run, out = tmp_path / "right.h5", tmp_path / "right.json"
    write_release_run(run, CONFIG, _converted(sims))
    assert main(["identify", str(run), "--json", str(out)]) == 0
    warnings = json.loads(out.read_text())["warnings"]
    guards = ("looks like", "the forces are", "release instant", "does not predict")
    assert not [w for w in warnings if any(g in w for g in guards)]


def test_the_json_carries_the_parameter_covariance_of_its_model(sims, tmp_path):
    """``model_covariance``: read back by its own reader, it fits the written model.

    The bridge's uncertainty (`windrig bridge --uncertainty`) reads it; here it must be the
    model's shape, symmetric, and its lag-root variances positive (both lags were fitted).
    """
    from ident.identification.covariance import ModelCovariance
    from ident.model.rfc import RationalFunctionModel

    run, out = tmp_path / "right.h5", tmp_path / "right.json"
    write_release_run(run, CONFIG, _converted(sims))
    assert main(["identify", str(run), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    model = RationalFunctionModel.from_dict(data["model"])
    covariance = ModelCovariance.from_dict(data["model_covariance"])
    covariance.check_model(model)
    assert covariance.size == len(data["model_covariance"]["parameters"])
    assert covariance.n_lags == model.n_lags
    assert np.all(np.diag(covariance.matrix)[-model.n_lags:] > 0.0)
