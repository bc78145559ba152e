"""The measurement chain of a simulated decay: from the plant's states to recorded channels.

The physical channels (``h``, ``alpha``, the lift and moment per unit span, and with sway ``p``
and the drag) follow from the plant's states and accelerations (:func:`clean_channels`); the
measurement effects then act on them in the order a rig has them: a delay of the force channels
(:class:`~ident.physics.effects.ChannelDelay`), crosstalk of pitch into the heave sensor
(:class:`~ident.physics.effects.SensorCrosstalk`), and last the pneumatic tubing between the taps
and the scanner (:class:`~ident.physics.effects.TubingDistortion`) (:func:`measure`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline

from ident.physics.effects import ChannelDelay, Effect, SensorCrosstalk, TubingDistortion
from ident.simulation.plant import Plant

__all__ = ["clean_channels", "generalised_forces", "measure"]

FloatArray = npt.NDArray[np.float64]

#: Time constants of a tube's slowest pole that the held force drives it before a record starts.
_SETTLE = 25.0


def clean_channels(
    plant: Plant, z: FloatArray, qdd: FloatArray, t: FloatArray, wind: FloatArray | None,
    effects: tuple[Effect, ...], B: float,
) -> tuple[dict[str, FloatArray], Any]:
    """Return the physical channels, and the spline of the forces a channel delay needs."""
    forces = plant.forces(z, qdd, t)
    if wind is not None:
        forces = forces + wind
    clean = {
        "h": z[:, 0] * B,
        "alpha": z[:, 1].copy(),
        "lift": forces[:, 0] / B,
        "moment": forces[:, 1],
    }
    if plant.k == 3:
        clean.update(p=z[:, 2] * B, drag=forces[:, 2] / B)
    spline = None
    if any(isinstance(e, ChannelDelay) and e.delay_s > 0.0 for e in effects):
        # Smooth after the release; the release itself is a kink (the added-mass force jumps),
        # so the spline only spans t >= 0 and earlier times take the held value.
        spline = CubicSpline(t, generalised_forces(clean, B), axis=0)
    return clean, spline


def generalised_forces(clean: dict[str, FloatArray], B: float) -> FloatArray:
    """Return ``[L B, M(, D B)]`` of a record's channels, shape (n, n_dof)."""
    columns = [clean["lift"] * B, clean["moment"]] + (
        [clean["drag"] * B] if "drag" in clean else [])
    return np.column_stack(columns)


def measure(
    clean: dict[str, FloatArray],
    t: FloatArray,
    effects: tuple[Effect, ...],
    before: Callable[[FloatArray], FloatArray] | None,
    spline: Any,
    t_start: float,
    B: float,
    tube_start: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[dict[str, FloatArray], tuple[FloatArray, FloatArray] | None]:
    """Apply the measurement effects (delay, crosstalk, tubing) to the clean channels at ``t``.

    ``spline`` interpolates the clean generalised forces ``[L B, M(, D B)]`` from ``t_start`` on; a
    delayed sample whose source time is earlier takes ``before(t_src)`` (the held force before a
    release, the previous record for a continuation). The tubing filters the (delayed) forces
    last; it starts from ``tube_start`` (the previous record's end state and last input) or,
    without it, in the state the held force has left it in (:func:`_settled_tube`: a held
    model's force need not be steady; vortex shedding and buffeting go on while it is held).
    Returns the channels and the tubes' end state.
    """
    out, tube_end = _delay_and_crosstalk(clean, t, effects, before, spline, t_start, B), None
    for effect in effects:
        if isinstance(effect, TubingDistortion) and t.size:
            forces = generalised_forces(out, B)
            if tube_start is None:
                delay = sum(e.delay_s for e in effects if isinstance(e, ChannelDelay))
                if before is not None:
                    dt = float(t[1] - t[0]) if t.size > 1 else 0.02 / effect.frequency_hz
                    x0 = _settled_tube(effect, before, float(t[0]), delay, dt)
                else:
                    x0 = np.column_stack([forces[0], np.zeros(forces.shape[1])])
                filtered, tube_end = _tube(effect, t, forces, x0, None)
            else:
                filtered, tube_end = _tube(effect, t, forces, tube_start[0],
                                           (t_start, tube_start[1]))
            out["lift"], out["moment"] = filtered[:, 0] / B, filtered[:, 1]
            if "drag" in out:
                out["drag"] = filtered[:, 2] / B
    return out, tube_end


def _settled_tube(effect: TubingDistortion, before: Callable[[FloatArray], FloatArray],
                  t0: float, delay: float, dt: float) -> FloatArray:
    """Return the tubes' states (rows ``[y, y']``) at ``t0`` after filtering the held force.

    The tubes have filtered the force the model felt while held (``before``, seen ``delay``
    late) for long before ``t0``: they are run from rest over 25 time constants of their
    slowest pole (``_SETTLE``) before it, on the record's step ``dt`` (s), so that what is left
    of that start is ``e^-25``. A steady held force leaves them at rest at it; a harmonic one
    (vortex shedding) in their steady oscillation, which starting at rest at its value at
    ``t0`` would miss: a false transient at the release (with the realistic shedding and tube
    at 0.6 of the flat plate's flutter speed, up to 92 % of the moment's RMS in the first
    samples, 6 % over a 3 s record).
    """
    A, _ = effect.state_space()
    slowest = float(np.min(-np.linalg.eigvals(A).real))  # 1/s, > 0 (a damped tube)
    n = math.ceil(_SETTLE / (slowest * dt))
    times = np.asarray(t0 - dt * np.arange(n, -1, -1), dtype=np.float64)
    # The last input is the held force just before the (delayed) release instant.
    inputs = before(times - delay - 1e-9)
    at_rest = np.column_stack([inputs[0], np.zeros(inputs.shape[1])])
    _, (end, _) = _tube(effect, times, inputs, at_rest, None)
    return end


def _tube(effect: TubingDistortion, t: FloatArray, u: FloatArray, x0: FloatArray,
          previous: tuple[float, FloatArray] | None) -> tuple[FloatArray,
                                                               tuple[FloatArray, FloatArray]]:
    """Filter the columns of ``u`` (at times ``t``) by the tube from states ``x0`` (rows).

    The input is piecewise linear between samples (first-order hold: exact for it; a smooth
    force at ``f`` comes out ``(2 pi f / fs)^2 / 12`` too weak, 2.1e-4 at 4 Hz and 500 Hz); with
    ``previous`` = (time, input) the first interval starts from the previous record's last
    input and its output is dropped. Returns the output and (end states, last input).
    """
    from scipy.signal import lsim

    A, b = effect.state_space()
    system = (A, b[:, None], np.array([[1.0, 0.0]]), np.zeros((1, 1)))
    times, inputs = t, u
    if previous is not None:
        times = np.concatenate([[previous[0]], t])
        inputs = np.vstack([previous[1][None, :], u])
    out = np.empty_like(inputs)
    end = np.empty((u.shape[1], 2))
    for j in range(u.shape[1]):
        if times.size == 1:
            out[:, j], end[j] = x0[j, 0], x0[j]
            continue
        _, y, x = lsim(system, inputs[:, j], times - times[0], X0=x0[j], interp=True)
        out[:, j], end[j] = y, x[-1]
    if previous is not None:
        out = out[1:]
    return np.asarray(out, dtype=float), (end, np.asarray(inputs[-1], dtype=float))


def _delay_and_crosstalk(
    clean: dict[str, FloatArray],
    t: FloatArray,
    effects: tuple[Effect, ...],
    before: Callable[[FloatArray], FloatArray] | None,
    spline: Any,
    t_start: float,
    B: float,
) -> dict[str, FloatArray]:
    """Apply a channel delay and sensor crosstalk (see :func:`_measure`)."""
    out = {name: values.copy() for name, values in clean.items()}
    for effect in effects:
        if isinstance(effect, ChannelDelay) and effect.delay_s > 0.0:
            assert before is not None
            t_src = t - effect.delay_s
            delayed = np.where(
                (t_src >= t_start)[:, None],
                spline(np.clip(t_src, t_start, None)),
                before(t_src),
            )
            out["lift"], out["moment"] = delayed[:, 0] / B, delayed[:, 1]
            if "drag" in out:
                out["drag"] = delayed[:, 2] / B
        elif isinstance(effect, SensorCrosstalk):
            out["h"] = clean["h"] + effect.h_from_alpha * clean["alpha"]
            out["alpha"] = clean["alpha"] + effect.alpha_from_h * clean["h"]
    return out
