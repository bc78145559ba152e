"""How far Whittle's bound is from the exact one, on a sampled surrogate (not a test).

``flutter_crb.py`` computes the Cramer-Rao bound in the frequency domain (Whittle): the DFT's
bins independent, the random response stationary from the release. A 20 s record of a lightly
damped section is neither long against its memory nor stationary (the motion starts at rest).
At 500 Hz the exact Gaussian bound is out of reach (40 000 samples a release), so this script
builds a surrogate small enough to compute both on the same data:

- the section's state space with Roger's lag states (:class:`ident.model.statespace.
  AeroelasticSystem`), the generalised buffeting force a state of its own: each of lift and
  moment a second-order low-pass filter of white noise (corner :data:`CORNER_HZ`, damping
  :data:`CORNER_DAMPING`), its intensity ``Q`` (symmetric 2 x 2) set so that the force's spectrum
  matches the gusts' (:func:`flutter_crb.vertical_gusts`, Iw 1 and 3 %) at the flutter
  frequency; no feedthrough, so sampling it is exact;
- the channels ``[h, alpha, lift, moment]`` sampled at ``--fs`` (10 Hz: the modes are below
  4 Hz), their white noise that of block means of ``flutter_crb``'s (2 % of each channel's
  recorded RMS at 500 Hz);
- per release the nuisances ``Q`` (3), the filter's corner and damping (2), the held
  displacement (2) and, for the exact bounds, each channel's offset (4; Whittle drops the zero
  bin instead); the coefficients as ``flutter_crb``'s.

Three bounds of the flutter speed's std from the same releases (3 speeds x 2 holds, 20 s):
Whittle's; the exact Gaussian one with every state stationary at the release; and the exact one
released from rest (the aerodynamic states zero, the force's filter stationary: the wind blew
on the held model). The exact Fisher information is ``dmu^T C^-1 dmu + tr(C^-1 dC C^-1 dC) / 2``
over the whole record; its covariance ``C`` is built from the state space's Lyapunov recursion.

Run: ``.venv/bin/python benchmarks/flutter_crb_exact.py [--fs 10] [--quick] [--results DIR]``
(``--quick``: the plate alone at Iw 1 % and 8 Hz; ``--results``: also write
``DIR/flutter_crb_exact.json`` and ``.md``, :mod:`result_files`).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla

from ident import SectionModel
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.quasi_steady import StaticCoefficients
from ident.model.rfc import RationalFunctionModel
from ident.model.statespace import AeroelasticSystem
from ident.physics.turbulence import buffeting_force_spectrum
from simulators import simulate_release
from simulators.decks import BLUFF_DECK, BLUFF_DECK_STATIC, bluff_deck_model

sys.path.insert(0, str(Path(__file__).resolve().parent))
import flutter_crb  # noqa: E402 - beside this script
import result_files  # noqa: E402

#: The force filter's corner, Hz, and damping ratio: above the sections' modes, as the gusts'
#: spectrum (0.3 m scale at 5-11 m/s: a corner near 3-6 Hz).
CORNER_HZ, CORNER_DAMPING = 5.0, 0.7
#: Release length, s, and intensities of the vertical gusts (``--quick``: the first).
DURATION, INTENSITIES = 20.0, (0.01, 0.03)
#: Rate of the recorded channels, Hz, and their white noise as a share of each one's RMS (as
#: ``flutter_crb``'s).
RECORDED_FS, NOISE = 500.0, 0.02
SYMMETRIC = (np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 0.0]]),
             np.array([[0.0, 0.0], [0.0, 1.0]]))


def _augmented(section: SectionModel, model: RationalFunctionModel, U: float,
               shape: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous ``(A, B_w, C)``: states ``[section and lags, s_L, s_L', s_M, s_M']``.

    ``shape``: the logarithms of the filter's corner and damping over their nominal values.
    """
    system = AeroelasticSystem(section, model, U)
    A_aero = system.matrix()
    n = A_aero.shape[0]
    M_inv = np.linalg.inv(system.effective_mass())
    force = system.force_matrix(A_aero)
    # The added mass feels the buffeting force through the acceleration it causes.
    through = np.eye(2) + 0.5 * section.rho * section.B**4 * model.A[2] @ M_inv
    corner = 2 * np.pi * CORNER_HZ * math.exp(shape[0])
    damping = CORNER_DAMPING * math.exp(shape[1])
    A = np.zeros((n + 4, n + 4))
    A[:n, :n] = A_aero
    B_w = np.zeros((n + 4, 2))
    C = np.zeros((4, n + 4))
    C[0, 0], C[1, 1] = section.B, 1.0
    C[2, :n], C[3, :n] = force[0] / section.B, force[1]
    for c in range(2):
        i = n + 2 * c
        A[i, i + 1] = 1.0
        A[i + 1, i], A[i + 1, i + 1] = -corner**2, -2 * damping * corner
        A[2:4, i] += M_inv[:, c]
        B_w[i + 1, c] = corner**2
        C[2, i] += through[0, c] / section.B
        C[3, i] += through[1, c]
    return A, B_w, C


def _sampled(A: np.ndarray, B_w: np.ndarray, Q: np.ndarray, dt: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Q_d)``: the state's transition over ``dt`` and its noise (Van Loan's method)."""
    k = A.shape[0]
    M = np.zeros((2 * k, 2 * k))
    M[:k, :k], M[:k, k:], M[k:, k:] = -A, B_w @ Q @ B_w.T, A.T
    E = sla.expm(M * dt)
    Phi = E[k:, k:].T
    Q_d = Phi @ E[:k, k:]
    return Phi, 0.5 * (Q_d + Q_d.T)


def _covariance(Phi: np.ndarray, Q_d: np.ndarray, C: np.ndarray, n_aero: int, N: int,
                from_rest: bool) -> np.ndarray:
    """Covariance of the ``N`` samples of the four channels' random part, shape (4N, 4N)."""
    P = sla.solve_discrete_lyapunov(Phi, Q_d)
    if from_rest:  # the section and its lags at rest, the force's filter stationary
        P[:n_aero, :] = 0.0
        P[:, :n_aero] = 0.0
    k = Phi.shape[0]
    O = np.empty((N, 4, k))
    T = np.eye(k)
    for j in range(N):
        O[j] = C @ T
        T = Phi @ T
    cov = np.zeros((N, 4, N, 4))
    for j in range(N):
        cov[j:, :, j, :] = O[:N - j] @ (P @ C.T)
        P = Phi @ P @ Phi.T + Q_d
    lower = np.tril(cov.reshape(4 * N, 4 * N))
    return lower + lower.T - np.diag(np.diag(lower))


def _spectrum(Phi: np.ndarray, Q_d: np.ndarray, C: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Spectral matrix of the random part per sample at ``nu`` cycles per sample, (K, 4, 4)."""
    k = Phi.shape[0]
    H = np.array([C @ np.linalg.inv(z * np.eye(k) - Phi) for z in np.exp(2j * np.pi * nu)])
    return H @ Q_d @ np.conj(np.swapaxes(H, 1, 2))


def _information(cov: np.ndarray, noise: np.ndarray, d_mean: list[np.ndarray],
                 d_cov: list[np.ndarray]) -> np.ndarray:
    """Exact Gaussian Fisher information; ``d_cov`` belongs to the first ``len(d_cov)``."""
    L = np.linalg.cholesky(cov + np.diag(noise))
    V = sla.solve_triangular(L, np.array(d_mean).T, lower=True)
    F = V.T @ V
    W = [sla.solve_triangular(L, sla.solve_triangular(L, d, lower=True).T, lower=True)
         for d in d_cov]
    for i in range(len(W)):
        for j in range(i + 1):
            F[i, j] += 0.5 * np.sum(W[i] * W[j].T)
            F[j, i] = F[i, j]  # the mean's part is symmetric already
    return F


def bounds(section: SectionModel, model: RationalFunctionModel, static: StaticCoefficients,
           known_zeros: bool, Iw: float, fs: float) -> dict[str, float]:
    """Return the three bounds on the flutter speed's std, as shares of it (module doc)."""
    flutter = fl.analyze(section, model)
    U_F = flutter.speed
    theta0, with_theta, g = flutter_crb.coefficients(section, model, known_zeros, U_F,
                                                     flutter.frequency)
    n_theta, N, dt = theta0.size, int(round(DURATION * fs)), 1.0 / fs
    nu = np.arange(1, N // 2) / N
    spec = flutter_crb.vertical_gusts(Iw)
    n_aero = AeroelasticSystem(section, model, 0.0).n_states
    shape0 = np.zeros(2)
    w, corner = 2 * np.pi * flutter.frequency, 2 * np.pi * CORNER_HZ
    gain = corner**4 / ((corner**2 - w**2) ** 2 + (2 * CORNER_DAMPING * corner * w) ** 2)
    per_release: dict[str, list[np.ndarray]] = {"whittle": [], "stationary": [], "from rest": []}
    for fraction in flutter_crb.FRACTIONS:
        U = fraction * U_F
        Sb = buffeting_force_spectrum(spec, static, np.array([flutter.frequency]), U=U,
                                      B=section.B, span=1.0, rho=section.rho)[0, :2, :2]
        Q = (Sb + 1e-6 * np.trace(Sb) * np.eye(2)) / 2 / gain  # two-sided, matched at f_F

        def random_part(theta, shape, Q, U=U):
            A, B_w, C = _augmented(section, with_theta(theta), U, shape)
            Phi, Q_d = _sampled(A, B_w, Q, dt)
            return (_covariance(Phi, Q_d, C, n_aero, N, False),
                    _covariance(Phi, Q_d, C, n_aero, N, True), N * _spectrum(Phi, Q_d, C, nu))

        steps = []  # (plus, minus, width) of each parameter the random part depends on
        for p in range(n_theta):
            h = 1e-6 * max(1.0, abs(theta0[p]))
            steps.append(((theta0 + h * np.eye(n_theta)[p], shape0, Q),
                          (theta0 - h * np.eye(n_theta)[p], shape0, Q), 2 * h))
        for E in SYMMETRIC:
            h = 1e-6 * np.abs(Q).max()
            steps.append(((theta0, shape0, Q + h * E), (theta0, shape0, Q - h * E), 2 * h))
        for j in range(2):
            e = 1e-6 * np.eye(2)[j]
            steps.append(((theta0, shape0 + e, Q), (theta0, shape0 - e, Q), 2e-6))
        stationary, rest, S0 = random_part(theta0, shape0, Q)
        d_random = [[(a - b) / width for a, b in zip(random_part(*plus), random_part(*minus),
                                                     strict=True)]
                    for plus, minus, width in steps]
        n_random = len(steps)
        # The static deflection the release decays to (the wind's mean load).
        settled = simulate_release(section, model, U, 0.0, 0.0, duration=120.0, fs=100.0,
                                   static=static)
        rest_at = (float(settled.h[-3000:].mean()), float(settled.alpha[-3000:].mean()))

        def released(theta, U=U):
            """Return the channels' free response to a unit held ``(h, alpha)``, (4N, 2)."""
            A, _, C = _augmented(section, with_theta(theta), U, shape0)
            Phi = sla.expm(A * dt)
            x = np.zeros((A.shape[0], 2))
            x[0, 0], x[1, 1] = 1.0 / section.B, 1.0
            y = np.empty((N, 4, 2))
            for k in range(N):
                y[k] = C @ x
                x = Phi @ x
            return y.reshape(4 * N, 2)

        # The decay is linear in the held displacement: one response per step, for every hold.
        at_theta0 = released(theta0)
        d_released = [(released(plus[0]) - released(minus[0])) / width
                      for plus, minus, width in steps[:n_theta]]
        for hold in flutter_crb.HOLDS:
            rms = flutter_crb._recorded_rms(section, model, U, hold, int(DURATION * RECORDED_FS),
                                            RECORDED_FS, spec, static, 1.0, 0)
            noise = (NOISE * rms) ** 2 * fs / RECORDED_FS  # block means'
            amplitude = np.array([hold[0] - rest_at[0], hold[1] - rest_at[1]])
            d_mean = [d @ amplitude for d in d_released]
            d_mean += [np.zeros(4 * N)] * (n_random - n_theta)
            d_mean += [at_theta0[:, j] for j in range(2)]                # held displacement
            d_mean += [np.tile(np.eye(4)[c], N) for c in range(4)]       # offsets
            n_noise = np.tile(noise, N)
            per_release["stationary"].append(_information(
                stationary, n_noise, d_mean, [d[0] for d in d_random]))
            per_release["from rest"].append(_information(
                rest, n_noise, d_mean, [d[1] for d in d_random]))
            S_inv = np.linalg.inv(S0 + N * np.diag(noise))
            known = n_random + 2  # Whittle: no offsets (the zero bin is dropped)
            dM = np.array([np.fft.fft(d.reshape(N, 4), axis=0)[1:N // 2]
                           for d in d_mean[:known]])
            dS = np.array([d[2] for d in d_random] + [np.zeros_like(S0)] * 2)
            F = np.eye(len(d_mean))  # the offsets' rows: decoupled, unit information
            F[:known, :known] = (flutter_crb._mean_information(dM, S_inv)
                                 + flutter_crb._spectral_information(dS, S_inv))
            per_release["whittle"].append(F)
    stds = {}
    for name, informations in per_release.items():
        n_nuisance = informations[0].shape[0] - n_theta
        total = np.zeros((n_theta + n_nuisance * len(informations),) * 2)
        for r, F in enumerate(informations):
            columns = list(range(n_theta)) + list(range(n_theta + n_nuisance * r,
                                                        n_theta + n_nuisance * (r + 1)))
            total[np.ix_(columns, columns)] += F
        cov = flutter_crb._inverse(total)[:n_theta, :n_theta]
        stds[name] = math.sqrt(g @ cov @ g) / U_F
    return stds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fs", type=float, default=None,
                        help="the surrogate's sample rate, Hz (10; --quick: 8; twice the rate "
                             "is eight times slower)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    if args.fs is None:
        args.fs = 8.0 if args.quick else 10.0
    if not 8.0 <= args.fs <= 40.0:
        parser.error(f"--fs takes 8 to 40 Hz (above the modes, below a dense matrix too big "
                     f"to factor), got {args.fs:g}")
    decks = [("flat plate", flutter_crb.PLATE, flat_plate.jones_model(),
              StaticCoefficients.flat_plate(), False)]
    if not args.quick:
        decks.append(("bluff deck", BLUFF_DECK, bluff_deck_model(), BLUFF_DECK_STATIC, True))
    intensities = INTENSITIES[:1] if args.quick else INTENSITIES
    print(f"Surrogate at {args.fs:g} Hz, 3 speeds x 2 holds of {DURATION:g} s: the flutter "
          "speed's CRB std.\n")
    print(f"{'deck':<12}{'Iw':>4}{'Whittle':>9}{'exact, stationary':>19}{'exact, from rest':>18}"
          f"{'ratio':>7}{'time':>7}")
    rows = []
    for name, section, model, static, known_zeros in decks:
        for Iw in intensities:
            started = time.process_time()
            stds = bounds(section, model, static, known_zeros, Iw, args.fs)
            ratio = stds["from rest"] / stds["whittle"]
            elapsed = time.process_time() - started
            print(f"{name:<12}{100 * Iw:>3.0f}%{100 * stds['whittle']:>8.2f}%"
                  f"{100 * stds['stationary']:>18.2f}%{100 * stds['from rest']:>17.2f}%"
                  f"{ratio:>7.2f}{elapsed:>6.0f}s", flush=True)
            rows.append((name, 100 * Iw, 100 * stds["whittle"], 100 * stds["stationary"],
                         100 * stds["from rest"], ratio, elapsed))
    table = result_files.Table(
        f"Whittle's bound against the exact Gaussian bound of the same sampled releases (a "
        f"surrogate at {args.fs:g} Hz: the force a filtered state, block means' noise; 3 "
        f"speeds x 2 holds of {DURATION:g} s): the flutter speed's CRB std "
        "as a share of it, every state stationary at the release or the section released from "
        "rest, the ratio of the last to Whittle's, and the CPU time.",
        ("deck", "Iw (%)", "Whittle (%)", "exact, stationary (%)", "exact, from rest (%)",
         "from rest / Whittle", "CPU time (s)"),
        rows, formats={"Iw (%)": ".0f", "Whittle (%)": ".2f", "exact, stationary (%)": ".2f",
                       "exact, from rest (%)": ".2f", "from rest / Whittle": ".2f",
                       "CPU time (s)": ".0f"})
    result_files.write(
        "flutter_crb_exact", "Whittle's bound against the exact one (a sampled surrogate)",
        [table], results=args.results, quick=args.quick, script="flutter_crb_exact",
        parameters={"fs (Hz)": args.fs, "iw": list(intensities), "duration (s)": DURATION,
                    "corner (Hz)": CORNER_HZ, "corner damping": CORNER_DAMPING,
                    "decks": [d[0] for d in decks]},
        notes=["The surrogate is not flutter_crb's problem (a rational force spectrum for von "
               "Karman's, fewer samples): the ratio, not the stds, is what carries over."])


if __name__ == "__main__":
    main()
