"""The structural model of a spring-mounted section model: heave and pitch, and optionally sway.

This module owns the structural matrices in windrig's generalised coordinates ``q = [h/B, alpha]``
or, with the lateral spring, ``q = [h/B, alpha, p/B]`` (``docs/reference/conventions.md``, "Signs
and coordinates", "Three degrees of freedom"). A 2-DOF section's matrices are the leading 2x2 block
of the 3-DOF ones: sway adds a row and a column and changes nothing else. It knows nothing of
aerodynamics; :mod:`ident.model.statespace` couples it with a
:class:`~ident.model.rfc.RationalFunctionModel`.

:func:`section_defaults` names the defaults a section file leaves to be taken (``rho``, ``S``,
and with sway ``zeta_p`` and ``m_p``), so that a command prints and records them: a default is
never silent. :func:`proportion_warnings` says when the section's width, mass and inertia do not
fit together as a section model's do, and names the unit that would make them.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.numerics import validate as v

__all__ = ["GYRATION_RANGE", "MASS_RATIO_RANGE", "SectionModel", "proportion_warnings",
           "section_defaults"]

#: Range of the radius of gyration over the width, ``sqrt(I / m) / B``, outside which a
#: section's proportions are warned of. A uniform plate has 0.29, bridge decks 0.3-0.4 (the
#: Great Belt's 0.34), section models with masses at their ends up to about 0.6; the range is
#: three times wider each way. A unit slip moves it by 10-1000 times.
GYRATION_RANGE = (0.05, 1.5)
#: Range of the mass ratio ``m / (rho B^2)`` outside which a section's mass is warned of:
#: decks and their section models are 5-200 (the tests' plate 27, the Great Belt's 19).
MASS_RATIO_RANGE = (0.5, 5000.0)
#: Unit slips :func:`proportion_warnings` tries: the fields, their factor to SI, the slip.
_UNIT_SLIPS: tuple[tuple[tuple[str, ...], float, str], ...] = (
    (("B",), 1e-3, "B looks like millimetres"),
    (("B",), 1e-2, "B looks like centimetres"),
    (("m",), 1e-3, "m looks like g/m"),
    (("m",), 1e3, "m looks like t/m"),
    (("I",), 1e-3, "I looks like g m^2/m"),
    (("I",), 1e-4, "I looks like kg cm^2/m"),
    (("I",), 1e-7, "I looks like g cm^2/m"),
    (("m", "I"), 1e-3, "m and I look like grams (g/m, g m^2/m)"),
)
#: Proportions a unit slip's correction must reach to be named: typical, not merely possible.
_TYPICAL_GYRATION = (0.1, 0.8)
_TYPICAL_MASS_RATIO = (1.0, 1000.0)


@dataclass(frozen=True)
class SectionModel:
    """Mass, stiffness and damping of a section model, per unit span (2 or 3 degrees of freedom).

    Parameters
    ----------
    B : float
        Deck width (chord), m. The reference length of every non-dimensional quantity.
    m : float
        Mass per unit span, kg/m.
    I : float
        Mass moment of inertia per unit span about the elastic axis, kg m^2/m.
    fh, fa : float
        Uncoupled natural frequencies in still vacuum of heave and pitch, Hz
        (``k_h = m (2 pi fh)^2``, ``k_a = I (2 pi fa)^2``).
    zeta_h, zeta_a : float
        Structural damping ratios of heave and pitch, in [0, 1).
    rho : float, optional
        Air density, kg/m^3. Default 1.225 (ISA sea level).
    S : float, optional
        Static unbalance ``m x_cg`` per unit span, kg m/m (x_cg: distance from the elastic axis to
        the centre of mass, positive downstream). Default 0.
    fp : float, optional
        Natural frequency of the lateral (along-wind, sway) spring in still vacuum, Hz. A section
        without it has two degrees of freedom (the default).
    zeta_p : float, optional
        Structural damping ratio of sway, in [0, 1); only with ``fp``. Default 0.
    m_p : float, optional
        Mass per unit span that moves in sway, kg/m (a sway carriage may carry more than the
        heave springs); only with ``fp``. Default ``m``.

    Raises
    ------
    ValueError
        If a mass, frequency, width or density is not > 0, a damping ratio is outside [0, 1), the
        mass matrix is not positive definite (``S^2 >= m I``), or ``zeta_p`` or ``m_p`` is given
        without ``fp``. The message names the field.

    Examples
    --------
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> s.mass_matrix()
    array([[0.27, 0.  ],
           [0.  , 0.03]])
    >>> SectionModel(B=0.3, m=-3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.0, zeta_a=0.0)
    Traceback (most recent call last):
    ...
    ValueError: m must be > 0, got -3.0

    With the lateral spring the matrices grow by a row and a column:

    >>> s3 = s.replace(fp=1.0, zeta_p=0.01)
    >>> s3.n_dof, s3.stiffness_matrix()[:2, :2].tolist() == s.stiffness_matrix().tolist()
    (3, True)
    """

    B: float
    m: float
    I: float  # noqa: E741 - the standard symbol for the moment of inertia
    fh: float
    fa: float
    zeta_h: float
    zeta_a: float
    rho: float = 1.225
    S: float = 0.0
    fp: float | None = None
    zeta_p: float | None = None
    m_p: float | None = None

    def __post_init__(self) -> None:
        # Convert and check every field once, here, so nothing downstream sees a bad value.
        for name in ("B", "m", "I", "fh", "fa", "rho"):
            object.__setattr__(self, name, v.positive(name, getattr(self, name)))
        for name in ("zeta_h", "zeta_a"):
            object.__setattr__(self, name, v.in_range(name, getattr(self, name), 0.0, 1.0))
        object.__setattr__(self, "S", v.finite("S", self.S))
        if self.S**2 >= self.m * self.I:
            raise ValueError(
                f"S must satisfy S^2 < m I for a positive-definite mass matrix, got S={self.S!r} "
                f"with m I={self.m * self.I!r}"
            )
        if self.fp is None:
            for name in ("zeta_p", "m_p"):
                if getattr(self, name) is not None:
                    raise ValueError(f"{name} needs fp (the lateral spring's frequency): a "
                                     "section without fp has two degrees of freedom")
        else:
            object.__setattr__(self, "fp", v.positive("fp", self.fp))
            object.__setattr__(self, "zeta_p", v.in_range("zeta_p", self.zeta_p or 0.0, 0.0, 1.0))
            object.__setattr__(self, "m_p", v.positive("m_p", self.m if self.m_p is None
                                                       else self.m_p))

    @property
    def n_dof(self) -> int:
        """Degrees of freedom: 2 (heave, pitch) or 3 (heave, pitch, sway)."""
        return 2 if self.fp is None else 3

    @property
    def omega_p(self) -> float | None:
        """Sway natural circular frequency, rad/s (None without the lateral spring)."""
        return None if self.fp is None else 2.0 * math.pi * self.fp

    @property
    def omega_h(self) -> float:
        """Heave natural circular frequency, rad/s."""
        return 2.0 * math.pi * self.fh

    @property
    def omega_a(self) -> float:
        """Pitch natural circular frequency, rad/s."""
        return 2.0 * math.pi * self.fa

    def mass_matrix(self) -> npt.NDArray[np.float64]:
        """Structural mass matrix ``Ms`` for ``q``, shape (n_dof, n_dof), kg m^2/m."""
        B = self.B
        M = np.array([[self.m * B**2, self.S * B], [self.S * B, self.I]])
        return self._with_sway(M, self.m_p)

    def damping_matrix(self) -> npt.NDArray[np.float64]:
        """Structural damping matrix ``Cs`` for ``q``, shape (n_dof, n_dof), kg m^2/(m s)."""
        B = self.B
        C = np.diag(
            [
                2.0 * self.m * self.zeta_h * self.omega_h * B**2,
                2.0 * self.I * self.zeta_a * self.omega_a,
            ]
        )
        sway = (None if self.m_p is None or self.omega_p is None
                else 2.0 * self.m_p * (self.zeta_p or 0.0) * self.omega_p)
        return self._with_sway(C, sway)

    def stiffness_matrix(self) -> npt.NDArray[np.float64]:
        """Structural stiffness matrix ``Ks`` for ``q``, shape (n_dof, n_dof), N m/m."""
        K = np.diag([self.m * self.omega_h**2 * self.B**2, self.I * self.omega_a**2])
        sway = None if self.m_p is None or self.omega_p is None else self.m_p * self.omega_p**2
        return self._with_sway(K, sway)

    def _with_sway(self, matrix: npt.NDArray[np.float64],
                   per_B2: float | None) -> npt.NDArray[np.float64]:
        """Append the sway row and column (``per_B2 B^2`` on the diagonal) to a 2x2 matrix."""
        if self.n_dof == 2 or per_B2 is None:
            return matrix
        out = np.zeros((3, 3))
        out[:2, :2] = matrix
        out[2, 2] = per_B2 * self.B**2
        return out

    def planar(self) -> SectionModel:
        """Return the section without its lateral spring (heave and pitch only)."""
        return self.replace(fp=None, zeta_p=None, m_p=None)

    def replace(self, **changes: Any) -> SectionModel:
        """Return a copy with some fields changed (validated again)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise TypeError(f"unknown SectionModel field(s): {sorted(unknown)}")
        return SectionModel(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, float]:
        """Return the fields as a plain dict of floats (JSON-ready).

        A 2-DOF section's dict has no lateral keys (as before three degrees of freedom).
        """
        data = asdict(self)
        if self.fp is None:
            for name in ("fp", "zeta_p", "m_p"):
                del data[name]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SectionModel:
        """Build a section from :meth:`to_dict` output; unknown keys raise ``TypeError``."""
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise TypeError(f"unknown SectionModel field(s): {sorted(unknown)}")
        return cls(**data)


def section_defaults(data: dict[str, Any], source: str = "") -> list[str]:
    """Return one line per default a section's fields leave :class:`SectionModel` to take.

    Parameters
    ----------
    data : dict
        The fields given (a section file's JSON object), as :meth:`SectionModel.from_dict`
        takes them; only which keys are present is read (and ``m`` for ``m_p``'s default).
    source : str, optional
        The file, named at the start of each line.

    Returns
    -------
    list of str
        ``rho`` (1.225 kg/m^3), ``S`` (0) and, for a section with sway (``fp``), ``zeta_p``
        (0) and ``m_p`` (``m``), each with the value taken; the structural damping of heave
        and pitch has no default (a section without it is an error).

    Examples
    --------
    >>> for line in section_defaults({"B": 0.3, "m": 3.0, "I": 0.03, "fh": 2.0, "fa": 4.0,
    ...                               "zeta_h": 0.005, "zeta_a": 0.005, "fp": 1.0}, "deck.json"):
    ...     print(line)
    deck.json: no air density rho: taken as 1.225 kg/m^3 (ISA sea level)
    deck.json: no static unbalance S: taken as 0 kg m/m (the centre of mass on the elastic axis)
    deck.json: no zeta_p: taken as 0 (no structural damping in sway)
    deck.json: no m_p: taken as m = 3 kg/m (the sway carriage adds no mass)
    """
    where = f"{source}: " if source else ""
    out = []
    if data.get("rho") is None:
        out.append(f"{where}no air density rho: taken as {SectionModel.rho} kg/m^3 (ISA sea "
                   "level)")
    if data.get("S") is None:
        out.append(f"{where}no static unbalance S: taken as 0 kg m/m (the centre of mass on the "
                   "elastic axis)")
    if data.get("fp") is not None:
        if data.get("zeta_p") is None:
            out.append(f"{where}no zeta_p: taken as 0 (no structural damping in sway)")
        if data.get("m_p") is None:
            m = data.get("m")
            mass = f"{m:g}" if isinstance(m, (int, float)) else repr(m)
            out.append(f"{where}no m_p: taken as m = {mass} kg/m (the sway carriage adds no "
                       "mass)")
    return out


def proportion_warnings(section: SectionModel, source: str = "") -> list[str]:
    """Return a warning when the section's width, mass and inertia do not fit together.

    The radius of gyration over the width, ``sqrt(I / m) / B``, must lie in
    :data:`GYRATION_RANGE`, and the mass ratio ``m / (rho B^2)`` in :data:`MASS_RATIO_RANGE`.
    Outside, the flutter speed is wrong (``m`` or ``I`` off) or the reduced frequencies and
    flutter derivatives are (``B`` off), so the warning names the one unit slip that brings
    both to a section model's typical proportions, if one does.

    Parameters
    ----------
    section : SectionModel
    source : str, optional
        Where the section came from, named at the start of the line.

    Returns
    -------
    list of str
        Empty, or one line.

    Examples
    --------
    >>> plate = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> proportion_warnings(plate)
    []
    >>> print(proportion_warnings(plate.replace(m=3000.0))[0])  # doctest: +NORMALIZE_WHITESPACE
    the section's proportions are not a section model's: radius of gyration sqrt(I/m) = 0.0032 m
    is 0.011 of the width B = 0.3 m (0.05-1.5), mass ratio m/(rho B^2) = 2.7e+04 (0.5-5000):
    m looks like g/m (m = 3 kg/m?); the flutter speed and the derivatives depend on them
    """
    def proportions(B: float, m: float, I: float) -> tuple[float, float]:
        return math.sqrt(I / m) / B, m / (section.rho * B**2)

    values = {"B": section.B, "m": section.m, "I": section.I}
    gyration, mass_ratio = proportions(**values)
    if (GYRATION_RANGE[0] <= gyration <= GYRATION_RANGE[1]
            and MASS_RATIO_RANGE[0] <= mass_ratio <= MASS_RATIO_RANGE[1]):
        return []
    fixes = []
    units = {"B": "m", "m": "kg/m", "I": "kg m^2/m"}
    for names, factor, slip in _UNIT_SLIPS:
        fixed = {k: x * factor if k in names else x for k, x in values.items()}
        g, mu = proportions(**fixed)
        if (_TYPICAL_GYRATION[0] <= g <= _TYPICAL_GYRATION[1]
                and _TYPICAL_MASS_RATIO[0] <= mu <= _TYPICAL_MASS_RATIO[1]):
            # Nearest a uniform plate's gyration first: g m^2 and kg cm^2 may both fit.
            fixes.append((abs(math.log(g / 0.29)), f"{slip} (" + ", ".join(
                f"{k} = {fixed[k]:.4g} {units[k]}" for k in names) + "?)"))
    fixes.sort()
    cause = ("check their units (B in m, m in kg/m, I in kg m^2/m, per metre of span)"
             if not fixes else fixes[0][1] if len(fixes) == 1
             else f"{fixes[0][1]}, or another unit")
    where = f"{source}: " if source else ""
    return [f"{where}the section's proportions are not a section model's: radius of gyration "
            f"sqrt(I/m) = {gyration * section.B:.2g} m is {gyration:.2g} of the width B = "
            f"{section.B:.4g} m ({GYRATION_RANGE[0]:g}-{GYRATION_RANGE[1]:g}), mass ratio "
            f"m/(rho B^2) = {mass_ratio:.2g} ({MASS_RATIO_RANGE[0]:g}-{MASS_RATIO_RANGE[1]:g}): "
            f"{cause}; the flutter speed and the derivatives depend on them"]
