"""Surface-pressure taps around a section outline, and their integration into lift, moment, drag.

A tap is a point of the outline with an outward unit normal and a tributary length. The pressure
``p`` (Pa, relative to the free-stream static pressure) acts on the surface as ``-p n ds`` per unit
span. Axes: ``x`` downstream along the chord, ``z`` downward (the direction of h), origin at the
elastic axis. Then (Scanlan's signs, ``docs/reference/conventions.md``, "Signs and coordinates")::

    L = -sum p_i nz_i ds_i              (positive downward)
    M =  sum (x_i dFz_i - z_i dFx_i)    (positive nose-up), with dF_i = -p_i n_i ds_i
    D = -sum p_i nx_i ds_i              (positive downwind: the drag of three degrees of freedom)

Only an outline with faces across the wind (a bluff deck's leading and trailing faces) carries
pressure drag; a flat plate's taps see none (:attr:`TapLayout.carries_drag`).

Nose-up is the rotation that takes +x towards +z here (the leading edge, at x < 0, moves to z < 0).
This module is shared by the acquisition (pressures to forces) and the simulators (forces to
pressures), so both sides use the same geometry and signs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.numerics import validate as v

__all__ = ["MAX_TAPS", "TapLayout"]

#: Most taps a generated outline may have: 32 scanner modules of 64 channels. A larger count in
#: a config is a typo, and its arrays (several per tap and sample) would not fit in memory.
MAX_TAPS = 2048


@dataclass(frozen=True, eq=False)
class TapLayout:
    """Positions, outward normals and tributary lengths of the pressure taps of a section.

    Parameters
    ----------
    x, z : array_like, shape (n,)
        Tap coordinates, m (x downstream, z downward, origin at the elastic axis).
    nx, nz : array_like, shape (n,)
        Outward unit normal of the surface at each tap (normalised within 1e-6).
    length : array_like, shape (n,)
        Tributary length of each tap along the outline, m, > 0.
    """

    x: npt.NDArray[np.float64]
    z: npt.NDArray[np.float64]
    nx: npt.NDArray[np.float64]
    nz: npt.NDArray[np.float64]
    length: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        arrays = {name: v.finite_array(name, getattr(self, name), ndim=1) for name in
                  ("x", "z", "nx", "nz", "length")}
        sizes = {a.size for a in arrays.values()}
        if len(sizes) != 1:
            lengths = {k: a.size for k, a in arrays.items()}
            raise ValueError(f"tap arrays must have equal lengths, got {lengths}")
        if arrays["x"].size < 2:
            raise ValueError("a tap layout needs at least 2 taps")
        norm = np.hypot(arrays["nx"], arrays["nz"])
        if np.any(np.abs(norm - 1.0) > 1e-6):
            worst = int(np.argmax(np.abs(norm - 1.0)))
            raise ValueError(
                f"tap normals must be unit vectors; tap {worst} has |n| = {float(norm[worst])!r}"
            )
        v.positive_array("length", arrays["length"])
        for name, arr in arrays.items():
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @property
    def n_taps(self) -> int:
        """Number of taps."""
        return int(self.x.size)

    def integration_matrix(self, drag: bool = False) -> npt.NDArray[np.float64]:
        """Matrix ``G`` with ``[L, M] = G p``, shape (2, n); L in N/m and M in N m/m for p in Pa.

        With ``drag``, a third row gives the drag ``D`` (N/m): shape (3, n).
        """
        dFx = -self.nx * self.length  # force per unit pressure, N/m per Pa
        dFz = -self.nz * self.length
        rows = [dFz, self.x * dFz - self.z * dFx] + ([dFx] if drag else [])
        return np.vstack(rows)

    @property
    def carries_drag(self) -> bool:
        """True when the taps' pressures determine a drag independently of lift and moment."""
        return bool(np.linalg.matrix_rank(self.integration_matrix(drag=True)) == 3)

    def integrate_drag(self, pressures: Any) -> npt.NDArray[np.float64]:
        """Return the pressure drag (N/m, positive downwind) of tap pressures (Pa), per sample."""
        p = np.asarray(pressures, dtype=float)
        if p.ndim != 2 or p.shape[1] != self.n_taps:
            raise ValueError(f"pressures must have shape (n_samples, {self.n_taps}), got {p.shape}")
        return np.asarray(p @ (-self.nx * self.length), dtype=float)

    def integrate(self, pressures: Any) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Lift and moment from tap pressures.

        Parameters
        ----------
        pressures : array_like, shape (n_samples, n_taps)
            Pa. A NaN at any tap makes that sample's lift and moment NaN (a marked gap, never a
            silently wrong force).

        Returns
        -------
        lift, moment : ndarray, shape (n_samples,)
            N/m and N m/m.
        """
        p = np.asarray(pressures, dtype=float)
        if p.ndim != 2 or p.shape[1] != self.n_taps:
            raise ValueError(f"pressures must have shape (n_samples, {self.n_taps}), got {p.shape}")
        forces = p @ self.integration_matrix().T  # NaN propagates through the sum
        return forces[:, 0], forces[:, 1]

    def pressures_for(
        self, lift: Any, moment: Any, mean: Any = None, drag: Any = None
    ) -> npt.NDArray[np.float64]:
        """Tap pressures that integrate exactly to the given lift and moment (and drag).

        The dynamic part is the minimum-norm distribution (pseudo-inverse of the integration
        matrix); ``mean`` adds a steady distribution with its lift and moment removed, so that
        the integral is unchanged.

        Parameters
        ----------
        lift, moment : array_like, shape (n_samples,)
            N/m and N m/m.
        mean : array_like, shape (n_taps,), optional
            Steady pressure distribution, Pa (e.g. ``qd * Cp_mean``).
        drag : array_like, shape (n_samples,), optional
            N/m; only for an outline that :attr:`carries_drag` (else ``ValueError``).

        Returns
        -------
        ndarray, shape (n_samples, n_taps)
            Pa.
        """
        columns = [v.finite_array("lift", lift, ndim=1), v.finite_array("moment", moment, ndim=1)]
        if drag is not None:
            if not self.carries_drag:
                raise ValueError("this tap outline has no faces across the wind: its pressures "
                                 "cannot carry a drag (a flat plate's taps see none)")
            columns.append(v.finite_array("drag", drag, ndim=1))
        forces = np.column_stack(columns)
        G = self.integration_matrix(drag=drag is not None)
        G_pinv = np.linalg.pinv(G)
        p = forces @ G_pinv.T
        if mean is not None:
            steady = v.finite_array("mean", mean, ndim=1)
            if steady.shape != (self.n_taps,):
                raise ValueError(f"mean must have shape ({self.n_taps},), got {steady.shape}")
            p = p + (steady - G_pinv @ (G @ steady))
        return np.asarray(p, dtype=float)

    def without(self, dead: Any) -> TapLayout:
        """Return the layout without the ``dead`` taps, the outline still covered.

        Each dead tap's tributary length goes to its nearest live neighbours on the same straight
        piece of outline (same outward normal and same distance of the line from the origin):
        half to the one before it and half to the one after it along that piece, or all of it
        to the only one at the end of a face. Half-and-half keeps the force and its line of
        action exact for a pressure that varies linearly along the face; at the end of a face
        the dead tap's share acts one tap spacing inward. A tap on a curved outline (explicit
        arrays, every tap its own normal) that has no live tap on its piece goes to the live
        taps before and after it in the layout's order (explicit layouts list their taps along
        the outline), provided their normals are within 30 degrees of its own.

        Parameters
        ----------
        dead : sequence of int
            Indices of the taps to leave out (0-based, in the layout's order; repeats ignored).

        Returns
        -------
        TapLayout
            The live taps in their order, their lengths adding up to the full outline's.

        Raises
        ------
        ValueError
            An index out of range, fewer than 2 live taps, or a dead tap with no live tap it
            could hand its length to (a whole face dead: its force cannot be estimated).
        """
        idx = sorted({int(i) for i in np.asarray(dead, dtype=np.int64).ravel()})
        n = self.n_taps
        if any(i < 0 or i >= n for i in idx):
            raise ValueError(f"dead taps must be indices in [0, {n - 1}], got {idx}")
        live = np.ones(n, dtype=bool)
        live[idx] = False
        if live.sum() < 2:
            raise ValueError(f"{len(idx)} dead taps of {n} leave fewer than 2 live taps")
        length = self.length.copy()
        offset = self.nx * self.x + self.nz * self.z  # distance of the tap's line from the origin
        along = -self.nz * self.x + self.nx * self.z  # position along that line
        for i in idx:
            same = (live & (np.abs(self.nx - self.nx[i]) < 1e-6) & (np.abs(self.nz - self.nz[i])
                    < 1e-6) & (np.abs(offset - offset[i]) < 1e-9 + 1e-6 * np.abs(offset[i])))
            before = np.flatnonzero(same & (along < along[i]))
            after = np.flatnonzero(same & (along > along[i]))
            heirs = ([int(before[np.argmax(along[before])])] if before.size else []) + \
                ([int(after[np.argmin(along[after])])] if after.size else [])
            if not heirs:  # a curved outline: the neighbours in the layout's (outline) order
                order = np.flatnonzero(live)
                k = int(np.searchsorted(order, i))
                candidates = {int(order[k - 1]), int(order[k % order.size])}
                heirs = sorted(j for j in candidates
                               if self.nx[j] * self.nx[i] + self.nz[j] * self.nz[i] > math.cos(
                                   math.radians(30.0)))
            if not heirs:
                raise ValueError(f"dead tap {i} has no live tap on its face or next to it along "
                                 "the outline: that part of the surface would carry no pressure")
            length[heirs] += self.length[i] / len(heirs)
        return TapLayout(x=self.x[live], z=self.z[live], nx=self.nx[live], nz=self.nz[live],
                         length=length[live])

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> TapLayout:
        """Build a layout from a config table (e.g. ``[taps]`` of a rig TOML).

        Explicit arrays ``{x, z, nx, nz, length}``, or a generated outline: ``{shape =
        "rectangle", B, D, taps_per_face}``, ``{shape = "streamlined_deck", B, D, n_taps}`` or
        ``{shape = "polygon", vertices, n_taps}``. Unknown or missing keys raise ``ValueError``
        naming them.
        """
        shapes = {
            "rectangle": {"shape", "B", "D", "taps_per_face"},
            "streamlined_deck": {"shape", "B", "D", "n_taps"},
            "polygon": {"shape", "vertices", "n_taps"},
        }
        keys = set(table)
        if "shape" in table and table["shape"] not in shapes:
            raise ValueError(
                f"taps.shape must be one of {sorted(shapes)} (or absent), got {table['shape']!r}"
            )
        expected = shapes[table["shape"]] if "shape" in table else {"x", "z", "nx", "nz", "length"}
        if keys != expected:
            missing, unknown = sorted(expected - keys), sorted(keys - expected)
            raise ValueError(f"taps table: missing keys {missing}, unknown keys {unknown}")
        shape = table.get("shape")
        count = table.get("taps_per_face", table.get("n_taps"))
        per = 2 if shape == "rectangle" else 1  # a rectangle's count is per horizontal face
        if isinstance(count, int) and count * per > MAX_TAPS:
            name = "taps_per_face" if shape == "rectangle" else "n_taps"
            raise ValueError(f"taps.{name} = {count} is too many: at most {MAX_TAPS // per} "
                             f"(MAX_TAPS = {MAX_TAPS} taps in all)")
        if shape == "rectangle":
            return cls.rectangle(table["B"], table["D"], table["taps_per_face"])
        if shape == "streamlined_deck":
            return cls.streamlined_deck(table["B"], table["D"], table["n_taps"])
        if shape == "polygon":
            return cls.polygon(table["vertices"], table["n_taps"])
        return cls(**{name: np.asarray(table[name], dtype=float) for name in expected})

    @classmethod
    def polygon(cls, vertices: Any, n_taps: int) -> TapLayout:
        """Taps evenly spaced by arc length around a closed polygon outline.

        Parameters
        ----------
        vertices : array_like, shape (n_vertices, 2)
            Outline corners ``(x, z)`` in m, in order around the section (either direction;
            normals are made to point outward).
        n_taps : int
            Number of taps (at least one per edge), spread over the edges in proportion to their
            lengths; each tap sits mid-way along its tributary length on one edge.
        """
        xz = v.finite_array("vertices", vertices, ndim=2)
        if xz.shape[1] != 2 or xz.shape[0] < 3:
            raise ValueError(f"vertices must have shape (n >= 3, 2), got {xz.shape}")
        if not isinstance(n_taps, int) or n_taps < 3:
            raise ValueError(f"n_taps must be an integer >= 3, got {n_taps!r}")
        closed = np.vstack([xz, xz[:1]])
        edges = np.diff(closed, axis=0)
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        if np.any(lengths == 0.0):
            raise ValueError("vertices must not repeat consecutively")
        # Signed area (shoelace): positive when the outline runs counter-clockwise in (x, z).
        area = 0.5 * float(np.sum(closed[:-1, 0] * closed[1:, 1] - closed[1:, 0] * closed[:-1, 1]))
        if n_taps < edges.shape[0]:
            raise ValueError(f"n_taps must be at least the number of edges ({edges.shape[0]})")
        # Taps per edge in proportion to its length (at least one), each edge split evenly: every
        # tributary length then lies on one straight edge, so a uniform pressure integrates to
        # exactly zero force and moment on the closed outline.
        counts = np.maximum(1, np.round(n_taps * lengths / lengths.sum()).astype(int))
        while counts.sum() != n_taps:
            per_tap = lengths / counts
            if counts.sum() < n_taps:
                counts[np.argmax(per_tap)] += 1
            else:
                counts[np.argmin(np.where(counts > 1, per_tap, np.inf))] -= 1
        sign = 1.0 if area > 0 else -1.0  # counter-clockwise: outward = tangent turned clockwise
        x, z, nx, nz, ds = [], [], [], [], []
        for start, edge, length, count in zip(closed[:-1], edges, lengths, counts, strict=True):
            frac = (np.arange(count) + 0.5) / count
            x.append(start[0] + frac * edge[0])
            z.append(start[1] + frac * edge[1])
            nx.append(np.full(count, sign * edge[1] / length))
            nz.append(np.full(count, -sign * edge[0] / length))
            ds.append(np.full(count, length / count))
        return cls(x=np.concatenate(x), z=np.concatenate(z), nx=np.concatenate(nx),
                   nz=np.concatenate(nz), length=np.concatenate(ds))

    @classmethod
    def streamlined_deck(cls, B: float, D: float, n_taps: int) -> TapLayout:
        """Taps around a streamlined box-girder outline of width ``B`` and depth ``D``.

        The outline is a flat top with sloping fairings to sharp edges at mid-depth, and a
        bottom plate with inclined webs (a generic closed box girder, as on many long-span
        bridges), centred on the elastic axis.
        """
        B = v.positive("B", B)
        D = v.positive("D", D)
        fairing, web = 0.18 * B, 0.25 * B
        vertices = [
            (-B / 2, 0.0), (-B / 2 + fairing, -D / 2), (B / 2 - fairing, -D / 2), (B / 2, 0.0),
            (B / 2 - web, D / 2), (-B / 2 + web, D / 2),
        ]
        return cls.polygon(vertices, n_taps)

    @classmethod
    def rectangle(cls, B: float, D: float, taps_per_face: int) -> TapLayout:
        """Taps evenly spread on the upper and lower faces and the two ends of a B x D rectangle.

        Parameters
        ----------
        B, D : float
            Width (chord) and depth, m; the origin is the rectangle's centre.
        taps_per_face : int
            Taps on each horizontal face (>= 2); each vertical end gets
            ``max(1, taps_per_face // 8)``.
        """
        B = v.positive("B", B)
        D = v.positive("D", D)
        if not isinstance(taps_per_face, int) or taps_per_face < 2:
            raise ValueError(f"taps_per_face must be an integer >= 2, got {taps_per_face!r}")
        n_end = max(1, taps_per_face // 8)
        ds = B / taps_per_face
        xs = -B / 2 + ds * (np.arange(taps_per_face) + 0.5)
        dz = D / n_end
        zs = -D / 2 + dz * (np.arange(n_end) + 0.5)
        ones, zeros = np.ones(taps_per_face), np.zeros(taps_per_face)
        e1, e0 = np.ones(n_end), np.zeros(n_end)
        # Upper face (z = -D/2, normal -z), lower face (z = +D/2, normal +z), then the two ends.
        return cls(
            x=np.concatenate([xs, xs, -B / 2 * e1, B / 2 * e1]),
            z=np.concatenate([-D / 2 * ones, D / 2 * ones, zs, zs]),
            nx=np.concatenate([zeros, zeros, -e1, e1]),
            nz=np.concatenate([-ones, ones, e0, e0]),
            length=np.concatenate([ds * ones, ds * ones, dz * e1, dz * e1]),
        )
