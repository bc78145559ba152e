"""analyze_campaign: one object with everything a campaign's front ends show."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ident import Release
from ident.errors import IdentError, RankDeficiencyError
from ident.identification import e2rfc, results
from ident.identification.campaign import analyze_campaign
from ident.model import flat_plate
from ident.model import flutter as fl
from simulators import simulate_release

from support.sections import FLAT_PLATE

MODEL = flat_plate.jones_model()
U_F = fl.analyze(FLAT_PLATE, MODEL).speed


def releases(fractions=(0.5, 0.65, 0.8)):
    return [Release.from_simulation(simulate_release(
        FLAT_PLATE, MODEL, f * U_F, 0.004, 0.02, duration=8.0, fs=500.0, noise=0.02, rng=i))
        for i, f in enumerate(fractions)]


def test_the_analysis_holds_what_identify_and_the_flutter_analysis_give():
    data = releases()
    analysis = analyze_campaign(data, FLAT_PLATE)
    model = e2rfc.identify(data, FLAT_PLATE)
    result, std = model.flutter(FLAT_PLATE)
    # The same chain: the same numbers (identify is deterministic).
    assert analysis.flutter_speed == pytest.approx(result.speed, rel=1e-12)
    assert analysis.flutter_std == pytest.approx(std, rel=1e-9)
    assert analysis.flutter_speed == pytest.approx(U_F, rel=0.01)  # 2 % noise, 8 s decays
    assert analysis.wind_speeds == tuple(r.U for r in data)
    assert analysis.structures.labels[0] == analysis.structure
    # Modes named by energy: heave near 2 Hz, pitch below 4 Hz and falling with the wind.
    assert analysis.release_speeds == tuple(r.U for r in data)
    assert all(1.9 < m.f_h < 2.2 and 3.0 < m.f_a < 4.0 for m in analysis.modes)
    assert analysis.modes[0].f_a > analysis.modes[-1].f_a
    truth = MODEL.flutter_derivatives(analysis.K)
    assert np.allclose(analysis.derivatives["A2"], truth["A2"], rtol=0.05, atol=0.02)
    assert analysis.table is not None and analysis.table_error is None
    text = analysis.summary()
    assert f"{analysis.flutter_speed:.2f} +- {analysis.flutter_std:.2f} m/s" in text
    as_json = json.loads(json.dumps(analysis.to_dict()))
    assert as_json["flutter_speed"] == pytest.approx(analysis.flutter_speed)
    assert set(as_json["flutter_std_parts"]) == {"noise", "structure", "extrapolation",
                                                 "one_lag_more", "release_scatter",
                                                 "below_decaying_release",
                                                 "other_estimator"}


def test_two_wind_speeds_are_enough_and_the_table_is_optional():
    """E2RFC needs two wind speeds; the indirect method's table is skipped when not asked for."""
    analysis = analyze_campaign(releases((0.5, 0.8)), FLAT_PLATE, table=False)
    assert analysis.table is None and analysis.table_error is None
    assert analysis.flutter_speed == pytest.approx(U_F, rel=0.01)
    assert len(analysis.wind_speeds) == 2


def test_one_wind_speed_is_refused():
    with pytest.raises(RankDeficiencyError):
        analyze_campaign(releases((0.6, 0.6)), FLAT_PLATE)


def test_a_model_without_still_air_modes_is_an_identification_error_not_a_crash(monkeypatch):
    """A chosen model whose added mass overturns the structure's gives an IdentError.

    The campaign runner and the console print an IdentError; a bare ValueError from the flutter
    search would stop them. Such a model is built by hand: the selection by held-out error has
    not chosen one on any data seen so far.
    """
    data = releases()
    real = e2rfc.identify(data, FLAT_PLATE, n_lags=1, with_A3=True)
    A = real.A.copy()
    A[2] = 1e3 * np.eye(2)
    wild = results.IdentifiedModel(A, real.d, real.diagnostics)
    monkeypatch.setattr(e2rfc, "identify", lambda *args, **kwargs: wild)
    with pytest.raises(IdentError, match=r"n_lags=1, A3=fitted.*oscillatory still-air modes"):
        analyze_campaign(data, FLAT_PLATE)
