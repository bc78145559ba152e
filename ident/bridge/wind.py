"""The wind of a full-bridge buffeting analysis: the WIND.toml file and span-wise coherence.

A WIND.toml (``windrig bridge --wind``, shared DESIGN "Command line") holds the statistics of the
oncoming turbulence at deck level, as non-dimensional intensities and length scales in m::

    Iu = 0.10      # sigma_u / U
    Iw = 0.05      # sigma_w / U
    Lux = 150.0    # integral length scale of u, m
    Lwx = 20.0     # integral length scale of w, m
    Cuy = 10.0     # span-wise decay constant of the coherence of u
    Cwy = 8.0      # ... of w (0: fully coherent)
    admittance = {kind = "davenport", decay = 7.0}   # or admittance = "none"

The spectra (von Karman), the admittance (Davenport's ``chi(x) = 2 (x - 1 + e^-x) / x^2``,
``x = c f B / U``, on the force amplitude) and the quasi-steady gains are those of
:mod:`ident.physics.turbulence` (one implementation for the section and the bridge; its docstring
and
``docs/reference/conventions.md`` state the forms). This module adds what a bridge needs beyond a
section: the coherence of the gusts at two deck nodes ``dx`` apart, ``coh(f) = exp(-C f |dx| / U)``.

A wind file's slips are caught by name: an intensity of 1 or more (``Iu = 15`` meant as 15 %) is
an error, a length scale under 1 m (given in km) or ``Lux < Lwx`` (swapped) a warning
(:func:`wind_warnings`).

Not responsible for: the buffeting forces on the modes and the response
(:mod:`ident.bridge.buffeting`).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.physics.turbulence import ADMITTANCES, TurbulenceSpec

__all__ = ["WIND_KEYS", "coherence", "read_wind", "wind_from_dict", "wind_warnings"]

#: The numeric keys of a WIND.toml (all required), with what each is.
WIND_KEYS: dict[str, str] = {
    "Iu": "turbulence intensity of u, sigma_u / U, a fraction, 0 <= Iu < 1",
    "Iw": "turbulence intensity of w, sigma_w / U, a fraction, 0 <= Iw < 1",
    "Lux": "integral length scale of u, m, > 0",
    "Lwx": "integral length scale of w, m, > 0",
    "Cuy": "span-wise coherence decay constant of u, >= 0",
    "Cwy": "span-wise coherence decay constant of w, >= 0",
}

#: Shortest integral length scale (m) taken without a warning. Atmospheric scales at deck level
#: are tens to hundreds of metres (``Lwx`` about 10 to 60 m, ``Lux`` 50 to 300 m), while the same
#: scales written in km are 0.01 to 0.3: everything below 1 m is a unit slip, not a wind.
MIN_PLAUSIBLE_LENGTH = 1.0


def coherence(f: Any, dx: Any, U: float, C: float) -> npt.NDArray[np.float64]:
    """Span-wise coherence ``exp(-C f |dx| / U)`` of a gust at two points ``dx`` apart.

    Parameters
    ----------
    f : array_like
        Frequencies, Hz, >= 0 (broadcast against ``dx``).
    dx : array_like
        Separations along the span, m (the sign does not matter).
    U : float
        Mean wind speed, m/s, > 0.
    C : float
        Decay constant (``Cuy`` or ``Cwy``), >= 0; 0 is full coherence.

    Returns
    -------
    ndarray
        Coherence in (0, 1] (of the amplitudes: the cross-spectrum is ``coh sqrt(S1 S2)``).

    Examples
    --------
    >>> float(coherence(0.1, 50.0, 25.0, 8.0).round(6))
    0.201897
    """
    if not (math.isfinite(U) and U > 0.0):
        raise ValueError(f"U must be > 0, got {U!r}")
    f_arr = np.asarray(f, dtype=float)
    dx_arr = np.abs(np.asarray(dx, dtype=float))
    return np.asarray(np.exp(-C * f_arr * dx_arr / U), dtype=float)


def wind_from_dict(data: dict[str, Any], *, source: str = "wind") -> TurbulenceSpec:
    """Build a :class:`~ident.physics.turbulence.TurbulenceSpec` from the keys of a WIND.toml.

    Parameters
    ----------
    data : dict
        ``Iu, Iw, Lux, Lwx, Cuy, Cwy`` (numbers) and optionally ``admittance``: ``"none"``
        (default), ``"davenport"`` (decay 7) or a table ``{kind = "davenport", decay = c}``.
    source : str
        Name of the file (or other origin) for the error messages.

    Raises
    ------
    ValueError
        With one line naming ``source``, the key and what is allowed: a missing or unknown key,
        a value that is not a number, out of range, or an unknown admittance.

    Examples
    --------
    >>> spec = wind_from_dict({"Iu": 0.0, "Iw": 0.05, "Lux": 1.0, "Lwx": 20.0, "Cuy": 0.0,
    ...                        "Cwy": 0.0, "admittance": {"kind": "davenport", "decay": 7.0}})
    >>> spec.admittance, spec.decay
    ('davenport', 7.0)
    >>> wind_from_dict({"Iu": 0.1}, source="w.toml")
    Traceback (most recent call last):
    ...
    ValueError: w.toml: missing key(s) Cuy, Cwy, Iw, Lux, Lwx (needed: Iu, Iw, Lux, Lwx, Cuy, Cwy)
    """
    allowed = set(WIND_KEYS) | {"admittance"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {', '.join(unknown)} (allowed: "
                         f"{', '.join(WIND_KEYS)}, admittance)")
    missing = sorted(set(WIND_KEYS) - set(data))
    if missing:
        raise ValueError(f"{source}: missing key(s) {', '.join(missing)} (needed: "
                         f"{', '.join(WIND_KEYS)})")
    values: dict[str, Any] = {}
    for key, meaning in WIND_KEYS.items():
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise ValueError(f"{source}: key {key} = {value!r} is not a finite number ({meaning})")
        values[key] = float(value)
    for key in ("Iu", "Iw"):
        # sigma / U of 1 or more is no wind a linearised (quasi-steady) buffeting theory can
        # take, and it is what a percentage looks like: refuse it with the likely slip.
        if values[key] >= 1.0:
            raise ValueError(f"{source}: key {key} = {values[key]:g} is sigma / U, a fraction "
                             f"< 1 (a percentage? {values[key]:g} % is "
                             f"{values[key] / 100.0:g})")
    kind, decay = _admittance(data.get("admittance", "none"), source)
    try:
        return TurbulenceSpec(**values, admittance=kind, decay=decay)
    except ValueError as exc:  # a range check of TurbulenceSpec: name the file too
        raise ValueError(f"{source}: {exc}") from exc


def wind_warnings(spec: TurbulenceSpec, *, source: str = "wind") -> list[str]:
    """Return a sentence for each implausible value of a wind that is otherwise valid.

    Parameters
    ----------
    spec : TurbulenceSpec
        The wind (:func:`read_wind`).
    source : str
        Name of the file, for the sentences.

    Returns
    -------
    list of str
        One sentence per slip, naming the file, the key and the likely mistake: a length scale
        ``Lux`` or ``Lwx`` under :data:`MIN_PLAUSIBLE_LENGTH` m (given in km?), ``Lux < Lwx``
        (the along-wind scale of u is several times that of w in the atmosphere: swapped?).
        Empty for a plausible wind. A gust of intensity 0 is not looked at (its scale does
        not act).

    Examples
    --------
    >>> spec = TurbulenceSpec(Iu=0.1, Iw=0.05, Lux=0.15, Lwx=25.0, Cuy=10.0, Cwy=8.0)
    >>> [line.split("): ")[1] for line in wind_warnings(spec, source="w.toml")]
    ['given in km? 0.15 km is 150 m']
    """
    out = []
    for key, intensity in (("Lux", spec.Iu), ("Lwx", spec.Iw)):
        value = float(getattr(spec, key))
        if intensity > 0.0 and value < MIN_PLAUSIBLE_LENGTH:
            out.append(f"{source}: {key} = {value:g} m is no atmospheric length scale (tens to "
                       f"hundreds of m at a deck): given in km? {value:g} km is "
                       f"{1000.0 * value:g} m")
    if not out and spec.Iu > 0.0 and spec.Iw > 0.0 and spec.Lux < spec.Lwx:
        out.append(f"{source}: Lux = {spec.Lux:g} m < Lwx = {spec.Lwx:g} m: the length scale "
                   f"of u is several times that of w in the atmosphere; swapped?")
    return out


def _admittance(value: Any, source: str) -> tuple[str, float]:
    allowed = ('admittance = "none", admittance = "davenport" or '
               'admittance = {kind = "davenport", decay = 7.0}')
    if isinstance(value, str):
        if value not in ADMITTANCES:
            raise ValueError(f"{source}: admittance = {value!r} is not known ({allowed})")
        return value, 7.0
    if not isinstance(value, dict):
        raise ValueError(f"{source}: admittance = {value!r} is neither a name nor a table "
                         f"({allowed})")
    extra = sorted(set(value) - {"kind", "decay"})
    if extra:
        raise ValueError(f"{source}: admittance has unknown key(s) {', '.join(extra)} "
                         f"(allowed: kind, decay)")
    kind = value.get("kind")
    if kind not in ADMITTANCES:
        raise ValueError(f"{source}: admittance kind = {kind!r} is not known (allowed: "
                         f"{', '.join(repr(a) for a in ADMITTANCES)})")
    decay = value.get("decay", 7.0)
    if isinstance(decay, bool) or not isinstance(decay, (int, float)) \
            or not math.isfinite(decay) or decay <= 0.0:
        raise ValueError(f"{source}: admittance decay = {decay!r} must be a number > 0 "
                         f"(Davenport's c in chi(c f B / U))")
    return str(kind), float(decay)


def read_wind(path: Path | str) -> TurbulenceSpec:
    """Read a WIND.toml file (keys in the module docstring) into a ``TurbulenceSpec``.

    Raises
    ------
    ValueError
        One line naming the file: it cannot be read, is not TOML, or a key is wrong.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the wind file ({exc})") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from exc
    return wind_from_dict(data, source=str(path))
