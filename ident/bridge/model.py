"""The full bridge: deck nodes, still-air modes and static coefficients, and strip theory on them.

A :class:`BridgeModel` is the bridge model file of DESIGN ("Full-bridge flutter and buffeting"):
the deck width ``B``, the air density ``rho``, the deck nodes ``nodes_x`` along the span, the
whole structure's still-air modes (frequency in Hz, damping ratio, generalised mass, and the
deck's shape at the nodes: ``h`` in m, ``alpha`` in rad, ``p`` in m per unit modal coordinate,
windrig's signs: h down, alpha nose-up, p downwind) and optionally the section's static
coefficients (for buffeting and for quasi-steady sway terms).

**Strip theory.** At a deck station ``x`` the section coordinates are
``q(x) = [h/B, alpha, p/B] = Phi(x) eta`` with the modal coordinates ``eta`` and
``Phi(x)`` of shape (3, n_modes) (:meth:`BridgeModel.shapes`). The section's self-excited force
per unit span ``f(x) = [L B, M, D B] = qd B^2 Q(p) q(x)`` does the virtual work
``L dh + M dalpha + D dp = f(x) . dq(x)``, so the generalised modal force is
``F = int Phi(x)^T f(x) dx = qd B^2 Q_modal(p) eta`` with::

    Q_modal(p) = sum_ij Q_ij(p) G_ij,   G_ij = int Phi_i(x)^T Phi_j(x) dx   (n_modes x n_modes)

(:meth:`BridgeModel.shape_integrals`: the trapezoid rule over ``nodes_x``; ``G_ij`` in m per
unit modal coordinate squared). The section's ``Q`` is the same along the deck, so Roger's form
carries over entry by entry: ``A_k,modal = sum_ij A_k[i, j] G_ij`` with the section's lag roots
(:meth:`BridgeModel.modal_coefficients`). A 2-DOF section model (heave and pitch) projects with
the leading 2x2 block only: the deck's sway then feels no air.

The modes are the whole structure's (cables and towers carry mass), so their deck-only products
need not be orthogonal; :meth:`BridgeModel.notes` mentions it, nothing refuses it.

**Inputs checked.** A value the file leaves out and that has a default (``rho``, a mode's
``damping`` or ``generalised_mass``) is taken and recorded in :attr:`BridgeModel.defaults`, one
line naming the file, the mode, the key and the value taken, for the command to print and write.
Implausible inputs are recorded in :attr:`BridgeModel.warnings` (:mod:`ident.bridge.mode_checks`):
a mode's equivalent deck mass per metre far from the other modes' or lighter than any deck, the
modes' common deck mass ratio no deck's (masses in tonnes, mass-normalised shapes with the
finite-element program's modal mass, shapes in mm), a damping ratio of
:data:`IMPLAUSIBLE_DAMPING` or more (a percentage written as a ratio). A mode that does not move
the deck at all is an error: the wind cannot act on it, and a table's zero column or a shape
in the wrong file is the likely cause.

Not responsible for: the equations of motion in the wind (:mod:`ident.bridge.statespace`),
flutter (:mod:`ident.bridge.flutter`).
"""

from __future__ import annotations

import functools
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.bridge.mode_checks import (
    IMPLAUSIBLE_DAMPING,
    LIGHTEST_DECK,
    MASS_SPREAD,
    damping_warning,
    deck_mass_ratio_warning,
    mass_warnings,
)
from ident.model.quasi_steady import StaticCoefficients
from ident.numerics.quadrature import trapezoid_weights

__all__ = ["DEFAULT_DAMPING", "DEFAULT_RHO", "IMPLAUSIBLE_DAMPING", "LIGHTEST_DECK", "MASS_SPREAD",
           "BridgeModel", "Mode", "SHAPE_NAMES"]

FloatArray = npt.NDArray[np.float64]

#: Shape components of a mode at the deck nodes, in the order of ``q = [h/B, alpha, p/B]``.
SHAPE_NAMES: tuple[str, ...] = ("h", "alpha", "p")
_SHAPE_UNITS = {"h": "m", "alpha": "rad", "p": "m"}
_TOP_KEYS = {"name", "B", "rho", "nodes_x", "modes", "static"}
_MODE_KEYS = {"frequency", "damping", "generalised_mass", *SHAPE_NAMES, "name"}
#: Air densities accepted, kg/m^3: anything outside is a unit mistake (g/m^3, kg/l).
_RHO_RANGE = (0.5, 2.0)
#: Air density taken when the file gives none, kg/m^3 (ISA sea level).
DEFAULT_RHO = 1.225
#: Damping ratio taken when a mode gives none: a welded steel deck's structural logarithmic
#: decrement 0.02 (EN 1991-1-4, Table F.2) is 0.0032; the lower round value errs on the safe
#: side for flutter and buffeting.
DEFAULT_DAMPING = 0.003
#: Generalised mass taken when a mode gives none, kg (shapes normalised to a unit modal mass).
DEFAULT_MASS = 1.0


@dataclass(frozen=True, eq=False)
class Mode:
    """One still-air mode of the whole structure, seen at the deck nodes.

    Parameters
    ----------
    frequency : float
        Natural frequency in still air, Hz, > 0.
    damping : float
        Structural damping ratio, in [0, 1).
    generalised_mass : float
        Generalised (modal) mass, kg per unit modal coordinate squared (1 for mass-normalised
        modes), > 0.
    h, alpha, p : ndarray, shape (n_nodes,)
        Deck shape per unit modal coordinate: heave (m, down), pitch (rad, nose-up), sway (m,
        downwind).
    name : str
        Optional label (e.g. the FE program's mode number).
    """

    frequency: float
    damping: float
    generalised_mass: float
    h: FloatArray
    alpha: FloatArray
    p: FloatArray
    name: str = ""

    @property
    def omega(self) -> float:
        """Circular frequency, rad/s."""
        return 2.0 * math.pi * self.frequency


@dataclass(frozen=True, eq=False)
class BridgeModel:
    """A bridge deck's still-air modes and section data (build with :meth:`from_dict`).

    Attributes
    ----------
    name : str
    B : float
        Deck width, m: the reference length of the section's aerodynamics.
    rho : float
        Air density, kg/m^3.
    nodes_x : ndarray, shape (n_nodes,)
        Deck stations along the span, m, strictly increasing.
    modes : tuple of Mode
    static : StaticCoefficients or None
        The section's static coefficients and slopes (windrig's signs), if given.
    given : frozenset of str
        The top-level keys the source gave (to tell a default from a given value).
    defaults : tuple of str
        Every default taken for a value the source left out, one line each naming the file,
        the mode, the key and the value (``"bridge.json: modes[2] (V1S): no damping: taken as
        0.003"``).
    warnings : tuple of str
        Implausible inputs, one line each naming the file, the mode, the key and the value
        (a generalised mass orders of magnitude from the other modes').

    Examples
    --------
    A uniform heave mode on a 2 m deck: ``int (h/B)^2 dx = 2 / B^2``.

    >>> bridge = BridgeModel.from_dict({"B": 2.0, "rho": 1.2, "nodes_x": [0.0, 1.0, 2.0],
    ...     "modes": [{"frequency": 0.5, "damping": 0.01, "h": [1.0, 1.0, 1.0]}]})
    >>> float(bridge.shape_integrals()[0, 0, 0, 0])
    0.5
    >>> BridgeModel.from_dict({"B": 2.0, "nodes_x": [0.0, 1.0, 0.5], "modes": []})
    Traceback (most recent call last):
    ...
    ValueError: nodes_x must be strictly increasing (m along the span), but nodes_x[2] = 0.5 \
follows 1
    """

    name: str
    B: float
    rho: float
    nodes_x: FloatArray
    modes: tuple[Mode, ...]
    static: StaticCoefficients | None = None
    given: frozenset[str] = field(default_factory=frozenset)
    defaults: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()

    # -- sizes and structural matrices ---------------------------------------------------------

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return len(self.modes)

    @property
    def n_nodes(self) -> int:
        """Number of deck nodes."""
        return int(self.nodes_x.size)

    @property
    def frequencies(self) -> FloatArray:
        """Still-air frequencies, Hz, shape (n_modes,)."""
        return np.array([m.frequency for m in self.modes])

    def mass_matrix(self) -> FloatArray:
        """Modal mass matrix ``diag(M_r)``, kg, shape (n_modes, n_modes)."""
        return np.diag([m.generalised_mass for m in self.modes])

    def damping_matrix(self) -> FloatArray:
        """Modal damping matrix ``diag(2 M_r zeta_r omega_r)``, kg/s."""
        return np.diag([2.0 * m.generalised_mass * m.damping * m.omega for m in self.modes])

    def stiffness_matrix(self) -> FloatArray:
        """Modal stiffness matrix ``diag(M_r omega_r^2)``, N/m (per unit modal coordinate)."""
        return np.diag([m.generalised_mass * m.omega**2 for m in self.modes])

    # -- strip theory --------------------------------------------------------------------------

    def shapes(self) -> FloatArray:
        """Section coordinates per unit modal coordinate, ``Phi``, shape (n_nodes, 3, n_modes).

        ``Phi[j, :, r] = [h_r/B, alpha_r, p_r/B]`` at node ``j``: ``q(x_j) = Phi[j] @ eta``.
        """
        out = np.empty((self.n_nodes, 3, self.n_modes))
        for r, mode in enumerate(self.modes):
            out[:, 0, r] = mode.h / self.B
            out[:, 1, r] = mode.alpha
            out[:, 2, r] = mode.p / self.B
        return out

    def quadrature_weights(self) -> FloatArray:
        """Trapezoid weights of the deck nodes, m, shape (n_nodes,): ``int g dx = w @ g``."""
        return trapezoid_weights(self.nodes_x)

    def shape_integrals(self) -> FloatArray:
        """``G[i, j] = int Phi_i^T Phi_j dx``, shape (3, 3, n_modes, n_modes), m.

        ``i, j`` index the section coordinates ``h/B, alpha, p/B`` (trapezoid rule over the
        nodes).
        """
        return self._shape_integrals

    @functools.cached_property
    def _shape_integrals(self) -> FloatArray:
        # Computed once (the frequency-domain scan projects Q at every K); read-only, since
        # the bridge is a value.
        phi = self.shapes()
        weighted = phi * self.quadrature_weights()[:, None, None]
        # Nine matrix products (BLAS) rather than one einsum, which loops in C without BLAS:
        # 1000 modes on 1000 nodes took 27 s by einsum on the loaded two-core host.
        G = np.empty((3, 3, self.n_modes, self.n_modes))
        for i in range(3):
            for j in range(3):
                G[i, j] = weighted[:, i, :].T @ phi[:, j, :]
        G.flags.writeable = False
        return G

    def modal_coefficients(self, A: Any) -> FloatArray:
        """Project section matrices on the modes: ``sum_ij A[..., i, j] G_ij``.

        Parameters
        ----------
        A : array_like, shape (..., n, n), n = 2 or 3
            Section matrices for ``q = [h/B, alpha(, p/B)]`` (e.g. a Roger model's ``A``, or
            ``Q(iK)`` samples, complex allowed). With n = 2 only heave and pitch are projected.

        Returns
        -------
        ndarray, shape (..., n_modes, n_modes)
            Real or complex as ``A``; multiplies ``eta`` to give the generalised force over
            ``qd B^2``.
        """
        A_arr = np.asarray(A)
        n = A_arr.shape[-1]
        if A_arr.ndim < 2 or A_arr.shape[-2] != n or n not in (2, 3):
            raise ValueError(f"section matrices must be (..., n, n) with n = 2 or 3, got shape "
                             f"{A_arr.shape}")
        G = self.shape_integrals()[:n, :n]
        return np.asarray(np.einsum("...ij,ijrs->...rs", A_arr, G))

    def load_matrix(self) -> FloatArray:
        """Generalised forces of loads at the nodes: ``F = sum_j,c P[:, j, c] f[j, c]``.

        Shape (n_modes, n_nodes, 3): with ``f[j] = [L, M, D]`` per unit span at node ``j``
        (N/m, N m/m, N/m; windrig's signs), ``F_r = int (L h_r + M alpha_r + D p_r) dx`` by the
        same trapezoid rule as :meth:`shape_integrals`. For buffeting forces.
        """
        w = self.quadrature_weights()
        out = np.empty((self.n_modes, self.n_nodes, 3))
        for r, mode in enumerate(self.modes):
            out[r, :, 0] = w * mode.h
            out[r, :, 1] = w * mode.alpha
            out[r, :, 2] = w * mode.p
        return out

    def mode_kinds(self) -> list[str]:
        """Return each mode's dominant deck motion: vertical, torsional, lateral (or none).

        The largest of ``int h^2``, ``int (alpha B/2)^2`` (the deck edge's displacement in
        pitch) and ``int p^2`` along the deck decides.
        """
        w = self.quadrature_weights()
        kinds = ("vertical", "torsional", "lateral")
        out = []
        for mode in self.modes:
            energy = [w @ mode.h**2, w @ (mode.alpha * self.B / 2.0) ** 2, w @ mode.p**2]
            out.append(kinds[int(np.argmax(energy))] if max(energy) > 0.0 else "no deck motion")
        return out

    def mode_labels(self) -> list[str]:
        """Return a short label per mode: name or number, frequency and dominant deck motion."""
        return [f"{mode.name or f'mode {r + 1}'} ({mode.frequency:.4g} Hz, {kind})"
                for r, (mode, kind) in enumerate(zip(self.modes, self.mode_kinds(), strict=True))]

    def notes(self) -> list[str]:
        """Remarks on the input that are not errors (for the user to read, not to fix).

        The defaults taken and the implausible inputs are :attr:`defaults` and
        :attr:`warnings`.
        """
        out: list[str] = []
        if self.n_modes > 1:
            # Deck-only products of whole-structure modes are not orthogonal in general; report
            # the largest normalised product for information only.
            # Products of the deck's displacements: h, the edge's alpha B/2, p.
            G = self.shape_integrals()
            gram = self.B**2 * (G[0, 0] + G[1, 1] / 4.0 + G[2, 2])
            diag = np.sqrt(np.clip(np.diag(gram), 1e-300, None))
            corr = np.abs(gram / np.outer(diag, diag))
            np.fill_diagonal(corr, 0.0)
            r, s = np.unravel_index(int(np.argmax(corr)), corr.shape)
            if corr[r, s] > 0.1:
                out.append(f"the deck-only shapes of modes {min(r, s) + 1} and {max(r, s) + 1} "
                           f"are not orthogonal (normalised product {corr[r, s]:.2f}): normal for "
                           "a whole structure's modes (cables and towers carry mass)")
        if self.static is not None and self.static.dC_L > 0.0:
            out.append(f"static dC_L = {self.static.dC_L:g} > 0: in windrig's signs lift is "
                       "positive downward, so most decks have dC_L < 0; if the source has lift "
                       "positive upward, flip C_L and dC_L")
        return out

    # -- (de)serialisation ---------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """Return the bridge model file's JSON object (DESIGN's keys)."""
        out: dict[str, Any] = {"name": self.name, "B": self.B, "rho": self.rho,
                               "nodes_x": self.nodes_x.tolist(), "modes": []}
        for mode in self.modes:
            entry: dict[str, Any] = {"frequency": mode.frequency, "damping": mode.damping,
                                     "generalised_mass": mode.generalised_mass,
                                     "h": mode.h.tolist(), "alpha": mode.alpha.tolist(),
                                     "p": mode.p.tolist()}
            if mode.name:
                entry["name"] = mode.name
            out["modes"].append(entry)
        if self.static is not None:
            out["static"] = self.static.to_dict()
        return out

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> BridgeModel:
        """Read a bridge model file; every problem is a ``ValueError`` naming the file and key."""
        source = os.fspath(path)
        try:
            with open(source, encoding="utf-8") as handle:
                data = json.load(handle)
        except FileNotFoundError:
            raise ValueError(f"{source}: no such file") from None
        except OSError as exc:
            raise ValueError(f"{source}: cannot read it: {exc.strerror or exc}") from None
        except UnicodeDecodeError as exc:
            raise ValueError(f"{source}: not a text (UTF-8) file: {exc.reason}") from None
        except json.JSONDecodeError as exc:
            raise ValueError(f"{source}: not valid JSON ({exc.msg}, line {exc.lineno} column "
                             f"{exc.colno})") from None
        try:
            bridge = cls.from_dict(data, default_name=os.path.splitext(os.path.basename(source))[0],
                                   source=source)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None
        return bridge

    @classmethod
    def from_dict(cls, data: Any, *, default_name: str = "bridge", source: str = "",
                  mode_sources: list[str] | None = None) -> BridgeModel:
        """Build and validate a bridge from the bridge model file's JSON object.

        Parameters
        ----------
        data : mapping
            The JSON object.
        default_name : str
            The name if ``data`` has none.
        source : str
            The file ``data`` came from, named in :attr:`defaults` and :attr:`warnings`.
        mode_sources : list of str, optional
            The file each mode came from (mode tables), named instead of ``modes[r]``.

        Raises
        ------
        ValueError
            One message per problem, naming the key (``modes[2].alpha``): a missing or unknown
            key, a value that is not a number, a size that does not match ``nodes_x``, nodes
            that do not increase, a unit that cannot be right (``rho`` outside 0.5 to 2 kg/m^3,
            a damping ratio of 1 or more), a drag coefficient below zero, a mode that does not
            move the deck.
        """
        if not isinstance(data, Mapping):
            raise ValueError("expected a JSON object with B, nodes_x and modes (DESIGN's bridge "
                             "model file)")
        unknown = sorted(set(data) - _TOP_KEYS)
        if unknown:
            raise ValueError(f"unknown key(s) {unknown}; allowed: {', '.join(sorted(_TOP_KEYS))}")
        missing = [k for k in ("B", "nodes_x", "modes") if k not in data]
        if missing:
            raise ValueError(f"missing key(s) {missing}")
        name = data.get("name", default_name)
        if not isinstance(name, str):
            raise ValueError(f"name must be a string, got {name!r}")
        B = _number("B", data["B"])
        if not 0.0 < B <= 200.0:
            raise ValueError(f"B = {B:g}: the deck width in m must be > 0 and at most 200")
        where = f"{source}: " if source else ""
        defaults: list[str] = []
        if "rho" not in data:
            defaults.append(f"{where}no air density rho: taken as {DEFAULT_RHO} kg/m^3 (ISA sea "
                            "level)")
        rho = _number("rho", data.get("rho", DEFAULT_RHO))
        if not _RHO_RANGE[0] <= rho <= _RHO_RANGE[1]:
            raise ValueError(f"rho = {rho:g}: the air density in kg/m^3 must be in "
                             f"{_RHO_RANGE[0]} to {_RHO_RANGE[1]}")
        x = _vector("nodes_x", data["nodes_x"])
        if x.size < 2:
            raise ValueError(f"nodes_x needs at least 2 deck nodes, got {x.size}")
        bad = np.flatnonzero(np.diff(x) <= 0.0)
        if bad.size:
            j = int(bad[0]) + 1
            raise ValueError(f"nodes_x must be strictly increasing (m along the span), but "
                             f"nodes_x[{j}] = {x[j]:g} follows {x[j - 1]:g}")
        modes_data = data["modes"]
        if not isinstance(modes_data, list) or not modes_data:
            raise ValueError("modes must be a non-empty list of mode objects")
        if mode_sources is not None and len(mode_sources) != len(modes_data):
            raise ValueError(f"{len(mode_sources)} mode sources for {len(modes_data)} modes")
        labels = [mode_sources[r] if mode_sources is not None else f"{where}modes[{r}]"
                  for r in range(len(modes_data))]
        warnings: list[str] = []
        modes = tuple(_mode(f"modes[{r}]" if mode_sources is None else mode_sources[r], entry,
                            x.size, labels[r], defaults, warnings)
                      for r, entry in enumerate(modes_data))
        warnings += mass_warnings(modes, labels, B, x, defaults)
        warnings += deck_mass_ratio_warning(modes, B, rho, x, where)
        static = None
        if data.get("static") is not None:
            static = _static(data["static"])
        x.flags.writeable = False
        return cls(name=name, B=B, rho=rho, nodes_x=x, modes=modes, static=static,
                   given=frozenset(data), defaults=tuple(defaults), warnings=tuple(warnings))


def _number(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{key} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f"{key} must be finite, got {value!r}")
    return out


def _vector(key: str, value: Any) -> FloatArray:
    if not isinstance(value, list):
        raise ValueError(f"{key} must be a list of numbers, got {type(value).__name__}")
    return np.array([_number(f"{key}[{i}]", item) for i, item in enumerate(value)], dtype=float)


def _mode(key: str, entry: Any, n_nodes: int, label: str, defaults: list[str],
          warnings: list[str]) -> Mode:
    """Validate one mode; append a line to ``defaults`` for each default taken.

    ``key`` prefixes errors (``modes[2]``, or a mode table's file); ``label`` names the mode in
    the defaults and in ``warnings`` (an implausible damping ratio), with the bridge file.
    """
    if not isinstance(entry, Mapping):
        raise ValueError(f"{key} must be an object with frequency, damping and h/alpha/p")
    unknown = sorted(set(entry) - _MODE_KEYS)
    if unknown:
        raise ValueError(f"{key}: unknown key(s) {unknown}; allowed: "
                         f"{', '.join(sorted(_MODE_KEYS))}")
    missing = [k for k in ("frequency",) if k not in entry]
    if missing:
        raise ValueError(f"{key}: missing key(s) {missing}")
    if not any(k in entry for k in SHAPE_NAMES):
        raise ValueError(f"{key}: no shape: give at least one of h (m), alpha (rad), p (m) at "
                         "the deck nodes")
    frequency = _number(f"{key}.frequency", entry["frequency"])
    if frequency <= 0.0:
        raise ValueError(f"{key}.frequency = {frequency:g}: must be > 0 Hz")
    named = entry.get("name")
    label = f"{label} ({named})" if isinstance(named, str) and named else label
    if "damping" not in entry:
        defaults.append(f"{label}: no damping: taken as {DEFAULT_DAMPING} (ratio; a welded steel "
                        "deck's)")
    damping = _number(f"{key}.damping", entry.get("damping", DEFAULT_DAMPING))
    if not 0.0 <= damping < 1.0:
        hint = (f" (a percentage? {damping:g} % is {damping / 100:g})" if damping >= 1.0 else "")
        raise ValueError(f"{key}.damping = {damping:g}: the damping ratio must be in [0, 1)"
                         f"{hint}")
    warnings += damping_warning(label, damping)
    if "generalised_mass" not in entry:
        defaults.append(f"{label}: no generalised_mass: taken as {DEFAULT_MASS:g} kg (shapes "
                        "normalised to a unit modal mass)")
    mass = _number(f"{key}.generalised_mass", entry.get("generalised_mass", DEFAULT_MASS))
    if mass <= 0.0:
        raise ValueError(f"{key}.generalised_mass = {mass:g}: must be > 0 kg")
    shapes = {}
    for name in SHAPE_NAMES:
        if name in entry:
            vec = _vector(f"{key}.{name}", entry[name])
            if vec.size != n_nodes:
                raise ValueError(f"{key}.{name} has {vec.size} values for {n_nodes} nodes_x "
                                 f"({_SHAPE_UNITS[name]} at each deck node)")
        else:
            vec = np.zeros(n_nodes)
        vec.flags.writeable = False
        shapes[name] = vec
    name = entry.get("name", "")
    if not isinstance(name, str):
        raise ValueError(f"{key}.name must be a string, got {name!r}")
    if not any(np.any(vec) for vec in shapes.values()):
        raise ValueError(f"{key}{f' ({name})' if name else ''}: no deck motion: h, alpha and p "
                         "are zero at every deck node, so the wind cannot act on this mode "
                         "(remove it, or check its shape columns)")
    return Mode(frequency=frequency, damping=damping, generalised_mass=mass, name=name,
                **shapes)


def _static(value: Any) -> StaticCoefficients:
    if not isinstance(value, Mapping):
        raise ValueError("static must be an object of C_D, C_L, C_M, dC_D, dC_L, dC_M")
    names = ("C_D", "C_L", "C_M", "dC_D", "dC_L", "dC_M")
    unknown = sorted(set(value) - set(names))
    if unknown:
        raise ValueError(f"static: unknown key(s) {unknown}; allowed: {', '.join(names)}")
    missing = [k for k in names if k not in value]
    if missing:
        raise ValueError(f"static: missing key(s) {missing} (per radian for the slopes)")
    numbers = {k: _number(f"static.{k}", value[k]) for k in names}
    if numbers["C_D"] < 0.0:
        raise ValueError(f"static.C_D = {numbers['C_D']:g}: drag is positive downwind, a deck's "
                         "C_D is >= 0")
    return StaticCoefficients(**numbers)
