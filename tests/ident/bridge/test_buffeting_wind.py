"""The WIND.toml of a bridge buffeting analysis (ident.bridge.wind): reading and clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ident.bridge.wind import coherence, read_wind, wind_warnings
from ident.physics.turbulence import davenport_function

GOOD = """Iu = 0.10
Iw = 0.05
Lux = 150.0
Lwx = 20.0
Cuy = 10.0
Cwy = 8
admittance = {kind = "davenport", decay = 6.5}
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "WIND.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_reads_a_good_file(tmp_path: Path) -> None:
    spec = read_wind(_write(tmp_path, GOOD))
    assert (spec.Iu, spec.Iw, spec.Lux, spec.Lwx, spec.Cuy, spec.Cwy) == (
        0.10, 0.05, 150.0, 20.0, 10.0, 8.0)
    assert spec.admittance == "davenport" and spec.decay == 6.5
    # The admittance on the amplitude: chi^2 on the spectrum, chi = Davenport's function of
    # c f B / U (f B / U = 1 here).
    assert spec.admittance_squared([1.0], 31.0, 31.0)[0] == pytest.approx(
        float(davenport_function(6.5)) ** 2, rel=1e-12)
    plain = read_wind(_write(tmp_path, GOOD.replace(
        'admittance = {kind = "davenport", decay = 6.5}', 'admittance = "none"')))
    assert plain.admittance == "none"
    assert plain.admittance_squared([0.3], 20.0, 31.0)[0] == 1.0


@pytest.mark.parametrize(("change", "message"), [
    (("Cwy = 8\n", ""), "WIND.toml: missing key(s) Cwy"),
    (("Iu = 0.10", "Iu = 0.10\nIv = 0.03"), "unknown key(s) Iv"),
    (("Lux = 150.0", 'Lux = "long"'), "key Lux = 'long' is not a finite number"),
    (("Lwx = 20.0", "Lwx = -20.0"), "Lwx must be > 0"),
    (("Iw = 0.05", "Iw = -0.05"), "Iw must be >= 0"),
    (('kind = "davenport"', 'kind = "sears"'), "admittance kind = 'sears' is not known"),
    (("decay = 6.5", "decay = 0"), "admittance decay = 0 must be a number > 0"),
    (('admittance = {kind = "davenport", decay = 6.5}', 'admittance = "sears"'),
     "admittance = 'sears' is not known"),
    (('admittance = {kind = "davenport", decay = 6.5}', "admittance = 7"),
     "neither a name nor a table"),
    (("Cwy = 8\n", "Cwy = 8\n["), "not valid TOML"),
])
def test_bad_files_name_the_file_and_key(tmp_path: Path, change: tuple[str, str],
                                         message: str) -> None:
    path = _write(tmp_path, GOOD.replace(*change))
    with pytest.raises(ValueError) as info:
        read_wind(path)
    text = str(info.value)
    assert text.startswith(str(path)) and message in text and "\n" not in text


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="cannot read the wind file"):
        read_wind(tmp_path / "nowhere.toml")


def test_coherence_is_exponential_in_reduced_separation() -> None:
    f = np.array([0.0, 0.1, 0.5])
    assert np.allclose(coherence(f, -40.0, 20.0, 8.0), np.exp(-8.0 * f * 40.0 / 20.0),
                       rtol=1e-15)
    assert np.all(coherence(f, 100.0, 20.0, 0.0) == 1.0)  # C = 0: fully coherent
    with pytest.raises(ValueError, match="U must be > 0"):
        coherence(f, 1.0, 0.0, 8.0)


@pytest.mark.parametrize(("key", "value", "hint"), [
    ("Iu", "15", "key Iu = 15 is sigma / U, a fraction < 1 (a percentage? 15 % is 0.15)"),
    ("Iw", "5", "key Iw = 5 is sigma / U, a fraction < 1 (a percentage? 5 % is 0.05)"),
    ("Iu", "1.0", "key Iu = 1 is sigma / U"),
])
def test_an_intensity_of_one_or_more_is_refused_as_a_percentage(tmp_path: Path, key: str,
                                                                 value: str, hint: str) -> None:
    """``Iu = 15`` meant as 15 % had given the example bridge a sway RMS of 35 m without a word."""
    old = {"Iu": "Iu = 0.10", "Iw": "Iw = 0.05"}[key]
    path = _write(tmp_path, GOOD.replace(old, f"{key} = {value}"))
    with pytest.raises(ValueError) as info:
        read_wind(path)
    text = str(info.value)
    assert text.startswith(str(path)) and hint in text and "\n" not in text


def test_length_scales_in_km_or_swapped_are_warned(tmp_path: Path) -> None:
    """A scale under 1 m is one in km; Lux < Lwx is a swap; a plausible wind has no warning."""
    assert wind_warnings(read_wind(_write(tmp_path, GOOD))) == []
    km = read_wind(_write(tmp_path, GOOD.replace("Lux = 150.0", "Lux = 0.15")
                          .replace("Lwx = 20.0", "Lwx = 0.02")))
    lines = wind_warnings(km, source="WIND.toml")
    assert lines == [
        "WIND.toml: Lux = 0.15 m is no atmospheric length scale (tens to hundreds of m at a "
        "deck): given in km? 0.15 km is 150 m",
        "WIND.toml: Lwx = 0.02 m is no atmospheric length scale (tens to hundreds of m at a "
        "deck): given in km? 0.02 km is 20 m"]
    swapped = read_wind(_write(tmp_path, GOOD.replace("Lux = 150.0", "Lux = 20.0")
                               .replace("Lwx = 20.0", "Lwx = 150.0")))
    assert wind_warnings(swapped, source="w") == [
        "w: Lux = 20 m < Lwx = 150 m: the length scale of u is several times that of w in the "
        "atmosphere; swapped?"]
    # A gust that is absent (intensity 0) has a scale that does not act: nothing to say.
    no_u = read_wind(_write(tmp_path, GOOD.replace("Iu = 0.10", "Iu = 0.0")
                            .replace("Lux = 150.0", "Lux = 0.5")))
    assert wind_warnings(no_u) == []
