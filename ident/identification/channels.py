"""The channels of a release, in the order the closed-loop model and its bound read them.

A planar release has four, ``h, alpha, lift, moment`` (m, rad, N/m, N m/m); with sway the sway
``p`` (m) and the ``drag`` (N/m) follow. The model's generalised coordinates are ``q = [h/B,
alpha(, p/B)]`` and its generalised forces ``[L B, M(, D B)]`` (N m/m): a displacement
channel is its coordinate times :func:`coordinate_scales`, a force channel its generalised
force divided by it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ident.simulation.decay import channels as channel_names

__all__ = ["columns", "coordinate_scales", "displacement_channels", "force_channels"]

FloatArray = npt.NDArray[np.float64]


def columns(record: Any) -> FloatArray:
    """Return a record's channels as columns, shape (n, 2 n_dof).

    In the order :func:`ident.simulation.decay.channels` names them; ``record`` is anything
    with ``h, alpha, lift, moment`` and ``p, drag`` (None without sway): a
    :class:`~ident.records.release.Release`, its hold, a simulated release.
    """
    n_dof = 2 if record.p is None else 3
    return np.column_stack([getattr(record, name) for name in channel_names(n_dof)])


def displacement_channels(n_dof: int) -> slice | list[int]:
    """Return the columns of the displacements ``h, alpha(, p)`` among :func:`columns`."""
    return slice(0, 2) if n_dof == 2 else [0, 1, 4]


def force_channels(n_dof: int) -> slice | list[int]:
    """Return the columns of the forces ``lift, moment(, drag)`` among :func:`columns`.

    Two degrees of freedom: a slice, so that a record's forces are a view whose statistics sum
    in the same order as its other columns' (an index list copies them, which moves a
    closed-loop fit's start in the last bit).
    """
    return slice(2, 4) if n_dof == 2 else [2, 3, 5]


def coordinate_scales(n_dof: int, B: float) -> FloatArray:
    """Return each generalised coordinate's channel per unit: ``[B, 1(, B)]``.

    ``h = B q_h``, ``alpha = q_alpha``, ``p = B q_p`` (m, rad, m); a force channel is its
    generalised force over the same (``lift = (L B) / B``, N/m; ``moment``, N m/m).
    """
    return np.array([B, 1.0, B][:n_dof])
