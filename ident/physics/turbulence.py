"""Turbulent flow and the buffeting forces it exerts on a bridge-deck section (pure numerics).

Model (``docs/reference/conventions.md``, "Static coefficients and buffeting"; SI units):

- Gusts ``u`` (along-wind, positive downwind) and ``w`` (vertical, **positive upward**), zero-mean,
  independent of each other, with von Karman one-sided spectra (m^2/s^2 per Hz) at mean speed
  ``U``, ``n = f L / U``::

      f S_u / sigma_u^2 = 4 n / (1 + 70.8 n^2)^(5/6)
      f S_w / sigma_w^2 = 4 n (1 + 755.2 n^2) / (1 + 283.2 n^2)^(11/6)

  with ``sigma_u = Iu U``, ``sigma_w = Iw U`` and the integral scales ``Lux``, ``Lwx``.
- Quasi-steady buffeting forces per unit span from the static coefficients
  (:class:`StaticCoefficients`, windrig's signs: lift positive downward, drag downwind, moment
  nose-up), ``qd = rho U^2 / 2``::

      L_b = qd B   [2 C_L u/U + (dC_L - C_D) w/U]
      D_b = qd B   [2 C_D u/U + (dC_D + C_L) w/U]
      M_b = qd B^2 [2 C_M u/U + dC_M w/U]

  Derivation: the relative wind has speed ``|V|^2 = (U + u)^2 + w^2 ~ U^2 (1 + 2 u/U)`` and comes
  from below at ``phi = w/U``, which raises the effective nose-up angle of attack by ``phi``.
  In wind axes the lift ``L_w = qd (1 + 2u/U) B (C_L + dC_L phi)`` acts perpendicular to the
  relative wind and the drag ``D_w`` along it; the drag axis is tilted up by ``phi``, so in body
  axes (down, downwind) ``L = L_w cos(phi) - D_w sin(phi)`` and ``D = D_w cos(phi) + L_w
  sin(phi)``; keeping first-order terms gives the three lines above. With lift positive upward
  (``C_L^up = -C_L``, ``C_L'^up = -dC_L``) the lift line becomes Davenport's and Scanlan's
  ``L_up = qd B [2 C_L^up u/U + (C_L'^up + C_D) w/U]`` (Simiu and Scanlan, 1996, ch. 6).
- Aerodynamic admittance ``chi`` (none, or Davenport's ``chi(x) = 2 (x - 1 + e^-x) / x^2`` with
  ``x = c f B / U``) multiplies the force amplitude, so the force spectrum by ``chi^2``.
- Span-wise coherence ``exp(-C f dy / U)`` (``Cuy`` for u, ``Cwy`` for w): the force averaged over
  a section model of span ``s`` has the point spectrum times the joint acceptance
  ``J^2 = 2 (a - 1 + e^-a) / a^2``, ``a = C f s / U`` (the closed form of
  ``(1/s^2) int int exp(-C f |y1 - y2| / U) dy1 dy2``; the same function as Davenport's).

So the span-averaged generalised buffeting force ``[L_b B, M_b, D_b B]`` (N m/m) is a linear
combination (:func:`buffeting_gain`) of two independent *effective gusts* with spectra
``chi^2 J^2 S_u`` and ``chi^2 J^2 S_w``. Every factor depends on ``f`` only through the wavenumber
``f / U`` (cycles/m), so the effective gusts divided by ``U`` are one field of the distance
``x = U t`` the air has travelled past the model (Taylor's frozen turbulence):
:class:`GustField` generates it once (spectral representation with Gaussian Fourier
coefficients) and any mean speed samples it.

Gusts near the ground, behind a grid or in a city are not Gaussian: their peaks are larger
(kurtosis above 3) and often skewed. A spec with ``skewness`` or ``kurtosis`` set passes each
effective gust through Winterstein's cubic Hermite transform of a standard Gaussian ``z``,
``x = kappa [z + h3 (z^2 - 1) + h4 (z^3 - 3 z)]`` with ``h4 = (sqrt(1 + 1.5 (K - 3)) - 1) / 18``,
``h3 = S / (4 + 2 sqrt(1 + 1.5 (K - 3)))`` and ``kappa = (1 + 2 h3^2 + 6 h4^2)^(-1/2)`` (mean 0 and
variance 1 exactly; skewness and kurtosis close to ``S`` and ``K`` for moderate values). The
transform keeps the variance but moves a little power to harmonics of the spectrum (a few per
cent at ``K = 4.5``): the spectra above are then those of the Gaussian field before it.

References
----------
T. von Karman, "Progress in the statistical theory of turbulence", PNAS 34, 1948.
A. G. Davenport, "The response of slender, line-like structures to a gusty wind", Proc. ICE 23,
1962. E. Simiu and R. H. Scanlan, "Wind Effects on Structures", 3rd ed., Wiley, 1996.
M. Shinozuka and G. Deodatis, "Simulation of stochastic processes by spectral representation",
Appl. Mech. Rev. 44, 1991. S. R. Winterstein, "Nonlinear vibration models for extremes and
fatigue", J. Eng. Mech. 114, 1988.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.model.quasi_steady import StaticCoefficients
from ident.numerics import validate as v

__all__ = [
    "GustField",
    "TurbulenceSpec",
    "WindLoad",
    "buffeting_force_spectrum",
    "buffeting_forces",
    "buffeting_gain",
    "davenport_function",
    "joint_acceptance",
    "mean_wind_load",
    "von_karman_u",
    "von_karman_w",
]

FloatArray = npt.NDArray[np.float64]

#: Admittance forms of :class:`TurbulenceSpec`.
ADMITTANCES: tuple[str, ...] = ("none", "davenport")


def davenport_function(x: Any) -> FloatArray:
    """Return ``2 (x - 1 + exp(-x)) / x^2`` (1 at ``x = 0``), for ``x >= 0``.

    Both Davenport's admittance ``chi`` (``x = c f B / U``) and the joint acceptance ``J^2`` of an
    exponential coherence (``x = C f s / U``) have this form. Below ``x = 1e-2`` a series is used
    (the direct form loses ``2 eps / x`` to cancellation; the series' truncation error there is
    below ``x^5 / 2520 < 4e-14``).

    Examples
    --------
    >>> davenport_function([0.0, 1.0]).round(6).tolist()
    [1.0, 0.735759]
    """
    x_arr = np.asarray(x, dtype=float)
    small = x_arr < 1e-2
    xs = np.where(small, 1.0, x_arr)  # no division by zero in the branch not taken
    direct = 2.0 * (xs + np.expm1(-xs)) / xs**2
    series = 1.0 - x_arr / 3.0 + x_arr**2 / 12.0 - x_arr**3 / 60.0 + x_arr**4 / 360.0
    return np.asarray(np.where(small, series, direct), dtype=float)


def joint_acceptance(f: Any, U: float, C: float, span: float) -> FloatArray:
    """Span-averaging factor ``J^2(f)`` of a force with coherence ``exp(-C f dy / U)``.

    Parameters
    ----------
    f : array_like
        Frequencies, Hz, >= 0.
    U : float
        Mean wind speed, m/s, > 0.
    C : float
        Decay constant of the coherence, >= 0 (0: fully coherent, ``J^2 = 1``).
    span : float
        Span of the section model, m, > 0.

    Returns
    -------
    ndarray
        ``J^2``, non-dimensional, in (0, 1].
    """
    return davenport_function(C * np.asarray(f, dtype=float) * span / U)


def von_karman_u(f: Any, U: float, sigma: float, L: float) -> FloatArray:
    """Von Karman one-sided spectrum of the along-wind gust ``u``, m^2/s^2 per Hz.

    ``S_u(f) = sigma^2 (4 L / U) / (1 + 70.8 n^2)^(5/6)``, ``n = f L / U``; integrates to
    ``sigma^2`` over ``f`` in [0, inf).

    Parameters
    ----------
    f : array_like
        Frequencies, Hz, >= 0.
    U : float
        Mean wind speed, m/s, > 0.
    sigma : float
        Standard deviation of u, m/s.
    L : float
        Integral length scale ``Lux``, m.
    """
    n = np.asarray(f, dtype=float) * L / U
    return np.asarray(sigma**2 * (4.0 * L / U) / (1.0 + 70.8 * n**2) ** (5.0 / 6.0), dtype=float)


def von_karman_w(f: Any, U: float, sigma: float, L: float) -> FloatArray:
    """Von Karman one-sided spectrum of the vertical gust ``w``, m^2/s^2 per Hz.

    ``S_w(f) = sigma^2 (4 L / U) (1 + 755.2 n^2) / (1 + 283.2 n^2)^(11/6)``, ``n = f L / U``;
    integrates to ``sigma^2``. Parameters as :func:`von_karman_u` (``L = Lwx``).
    """
    n = np.asarray(f, dtype=float) * L / U
    shape = (1.0 + 755.2 * n**2) / (1.0 + 283.2 * n**2) ** (11.0 / 6.0)
    return np.asarray(sigma**2 * (4.0 * L / U) * shape, dtype=float)


@dataclass(frozen=True)
class TurbulenceSpec:
    """Statistics of the oncoming turbulence and how it loads a section.

    Parameters
    ----------
    Iu, Iw : float
        Turbulence intensities ``sigma_u / U``, ``sigma_w / U`` (fractions), >= 0.
    Lux, Lwx : float
        Integral length scales of u and w, m, > 0.
    Cuy, Cwy : float
        Span-wise decay constants of the coherence ``exp(-C f dy / U)`` of u and w, >= 0.
    admittance : {"none", "davenport"}
        Aerodynamic admittance: none (``chi = 1``, quasi-steady) or Davenport's form.
    decay : float
        Davenport's decay constant ``c`` (``chi(x)``, ``x = c f B / U``), > 0; used only with
        ``admittance="davenport"``. Default 7, a value often used for lift.
    skewness, kurtosis : float
        Marginal skewness and kurtosis of the effective gusts (Winterstein's Hermite transform,
        module docstring); ``|skewness| <= 1`` and ``3 <= kurtosis <= 8``, where the transform
        is monotonic and its moments close to the targets. Default 0 and 3: Gaussian.

    Examples
    --------
    >>> spec = TurbulenceSpec(Iu=0.1, Iw=0.05, Lux=0.5, Lwx=0.2, Cuy=10.0, Cwy=8.0)
    >>> TurbulenceSpec.from_dict(spec.to_dict()) == spec
    True
    >>> TurbulenceSpec(Iu=0.1, Iw=0.05, Lux=0.5, Lwx=0.2, Cuy=10.0, Cwy=8.0, admittance="sears")
    Traceback (most recent call last):
    ...
    ValueError: admittance must be one of ('none', 'davenport'), got 'sears'
    """

    Iu: float
    Iw: float
    Lux: float
    Lwx: float
    Cuy: float
    Cwy: float
    admittance: str = "none"
    decay: float = 7.0
    skewness: float = 0.0
    kurtosis: float = 3.0

    def __post_init__(self) -> None:
        for name in ("Iu", "Iw", "Cuy", "Cwy"):
            x = v.finite(name, getattr(self, name))
            if x < 0.0:
                raise ValueError(f"{name} must be >= 0, got {x!r}")
            object.__setattr__(self, name, x)
        for name in ("Lux", "Lwx", "decay"):
            object.__setattr__(self, name, v.positive(name, getattr(self, name)))
        if self.admittance not in ADMITTANCES:
            raise ValueError(f"admittance must be one of {ADMITTANCES}, got {self.admittance!r}")
        skewness, kurtosis = v.finite("skewness", self.skewness), v.finite("kurtosis",
                                                                           self.kurtosis)
        if abs(skewness) > 1.0 or not 3.0 <= kurtosis <= 8.0:
            raise ValueError("gusts need |skewness| <= 1 and 3 <= kurtosis <= 8 (the range "
                             f"where the Hermite transform holds), got {skewness!r} and "
                             f"{kurtosis!r}")
        object.__setattr__(self, "skewness", skewness)
        object.__setattr__(self, "kurtosis", kurtosis)

    @property
    def gaussian(self) -> bool:
        """Whether the gusts are Gaussian (skewness 0, kurtosis 3)."""
        return self.skewness == 0.0 and self.kurtosis == 3.0

    def marginal(self, z: Any) -> FloatArray:
        """Map standard Gaussian values ``z`` to gusts of this spec's skewness and kurtosis.

        Winterstein's cubic Hermite transform (module docstring): mean 0 and variance 1 are
        kept exactly for a standard Gaussian ``z``; the identity for Gaussian gusts.
        """
        z_arr = np.asarray(z, dtype=float)
        if self.gaussian:
            return z_arr
        root = np.sqrt(1.0 + 1.5 * (self.kurtosis - 3.0))
        h4 = (root - 1.0) / 18.0
        h3 = self.skewness / (4.0 + 2.0 * root)
        kappa = 1.0 / np.sqrt(1.0 + 2.0 * h3**2 + 6.0 * h4**2)
        return np.asarray(kappa * (z_arr + h3 * (z_arr**2 - 1.0) + h4 * (z_arr**3 - 3.0 * z_arr)),
                          dtype=float)

    def admittance_squared(self, f: Any, U: float, B: float) -> FloatArray:
        """``chi^2`` at frequencies ``f`` (Hz) for mean speed ``U`` (m/s) and width ``B`` (m)."""
        f_arr = np.asarray(f, dtype=float)
        if self.admittance == "none":
            return np.ones_like(f_arr)
        return davenport_function(self.decay * f_arr * B / U) ** 2

    def gust_spectra(self, f: Any, U: float) -> tuple[FloatArray, FloatArray]:
        """Point spectra ``S_u, S_w`` (m^2/s^2 per Hz) at frequencies ``f`` (Hz), speed ``U``."""
        return (von_karman_u(f, U, self.Iu * U, self.Lux),
                von_karman_w(f, U, self.Iw * U, self.Lwx))

    def effective_spectra(
        self, f: Any, U: float, B: float, span: float
    ) -> tuple[FloatArray, FloatArray]:
        """Spectra of the effective gusts ``chi^2 J^2 S`` (m^2/s^2 per Hz) that load the section.

        Parameters
        ----------
        f : array_like
            Frequencies, Hz, >= 0.
        U : float
            Mean wind speed, m/s, > 0.
        B : float
            Deck width, m (admittance).
        span : float
            Span of the section model, m (coherence).
        """
        S_u, S_w = self.gust_spectra(f, U)
        chi2 = self.admittance_squared(f, U, B)
        return (S_u * chi2 * joint_acceptance(f, U, self.Cuy, span),
                S_w * chi2 * joint_acceptance(f, U, self.Cwy, span))

    def to_dict(self) -> dict[str, Any]:
        """Return the fields as a JSON-ready dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TurbulenceSpec:
        """Build a spec from :meth:`to_dict` output; unknown keys raise ``TypeError``."""
        return cls(**v.checked_keys(cls, data))


def mean_wind_load(static: StaticCoefficients, U: float, B: float, rho: float) -> FloatArray:
    """Mean generalised wind load ``qd B^2 [C_L, C_M, C_D]`` = ``[L B, M, D B]``, N m/m."""
    qd = 0.5 * rho * U**2
    return qd * B**2 * np.array([static.C_L, static.C_M, static.C_D])


def buffeting_gain(static: StaticCoefficients, U: float, B: float, rho: float) -> FloatArray:
    """Matrix ``G`` with ``[L_b B, M_b, D_b B] = G [u, w]`` (N m/m per m/s), shape (3, 2).

    Quasi-steady, windrig's signs, ``w`` positive upward (see the module docstring)::

        G = qd B^2 / U [[2 C_L, dC_L - C_D], [2 C_M, dC_M], [2 C_D, dC_D + C_L]]

    ``U`` must be > 0.
    """
    U = v.positive("U", U)
    s = static
    qd = 0.5 * rho * U**2
    return (qd * B**2 / U) * np.array([[2.0 * s.C_L, s.dC_L - s.C_D],
                                       [2.0 * s.C_M, s.dC_M],
                                       [2.0 * s.C_D, s.dC_D + s.C_L]])


def buffeting_force_spectrum(
    spec: TurbulenceSpec, static: StaticCoefficients, f: Any, *, U: float, B: float,
    span: float, rho: float,
) -> FloatArray:
    """One-sided cross-spectral matrix of the span-averaged ``[L_b B, M_b, D_b B]``.

    Parameters
    ----------
    spec : TurbulenceSpec
    static : StaticCoefficients
    f : array_like, shape (k,)
        Frequencies, Hz, >= 0.
    U, B, span, rho : float
        Mean wind speed (m/s, > 0), deck width (m), section span (m), air density (kg/m^3).

    Returns
    -------
    ndarray, shape (k, 3, 3)
        ``S_F(f)``, (N m/m)^2 per Hz; real (u and w are independent, and each force is in phase
        with its gust).
    """
    G = buffeting_gain(static, U, B, rho)
    G_u, G_w = spec.effective_spectra(np.atleast_1d(f), U, B, span)
    return np.asarray(G_u[:, None, None] * np.outer(G[:, 0], G[:, 0])
                      + G_w[:, None, None] * np.outer(G[:, 1], G[:, 1]), dtype=float)


@dataclass(frozen=True, eq=False)
class GustField:
    """Normalised effective gusts ``[u_eff/U, w_eff/U]`` along the distance ``x = U t``.

    One period of a periodic, Gaussian, zero-mean field sampled every ``dx`` metres; its
    wavenumber spectra are those of :meth:`TurbulenceSpec.effective_spectra` divided by ``U``
    (they depend on ``f/U`` only). Made by :meth:`generate`.

    Attributes
    ----------
    spec : TurbulenceSpec
    B, span : float
        Deck width and section span it was generated for, m.
    dx : float
        Sample spacing, m.
    values : ndarray, shape (n, 2)
        ``u_eff / U`` and ``w_eff / U`` at ``x = k dx`` (non-dimensional).
    x0 : float
        Position in the field at ``t = 0``, m (see :meth:`shifted`).
    """

    spec: TurbulenceSpec
    B: float
    span: float
    dx: float
    values: FloatArray = field(repr=False)
    x0: float = 0.0

    @classmethod
    def generate(
        cls, spec: TurbulenceSpec, *, B: float, span: float, n: int, dx: float, rng: Any,
    ) -> GustField:
        """Generate a field of ``n`` points every ``dx`` m by the spectral representation.

        Fourier coefficient ``k`` (wavenumber ``k / (n dx)``, cycles/m) of each component is a
        complex Gaussian with ``E|X_k|^2`` matching ``G(k / (n dx)) / (n dx)``; ``k = 0`` (mean)
        and the Nyquist term are zero. u and w use independent coefficients. Gaussian
        coefficients (rather than random phases with fixed amplitudes) make the field a Gaussian
        process whose periodogram has the usual chi-square spread.

        Parameters
        ----------
        spec : TurbulenceSpec
        B, span : float
            Deck width and section span, m, > 0.
        n : int
            Number of points, >= 2; the field is periodic with period ``n dx``.
        dx : float
            Spacing, m, > 0.
        rng : numpy.random.Generator or int
            Random source or seed (required: every simulation is reproducible).
        """
        B = v.positive("B", B)
        span = v.positive("span", span)
        dx = v.positive("dx", dx)
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
            raise ValueError(f"n must be an integer >= 2, got {n!r}")
        generator = _generator(rng)
        n = int(n)
        n_half = n // 2 + 1
        kappa = np.arange(n_half) / (n * dx)  # cycles/m: the frequency at U = 1 m/s
        G = np.stack(spec.effective_spectra(kappa, 1.0, B, span))  # (2, n_half), per cycle/m
        amp = 0.5 * n * np.sqrt(G / (n * dx))
        amp[:, 0] = 0.0
        if n % 2 == 0:
            amp[:, -1] = 0.0
        z = generator.standard_normal((2, n_half, 2))
        X = amp * (z[..., 0] + 1j * z[..., 1])
        values = np.fft.irfft(X, n=n, axis=1).T.copy()
        if not spec.gaussian:
            # Each component through the marginal transform at its own scale: the field's
            # expected std (from the spectrum), not the sample's, so that the draw stays honest.
            # (The irfft of coefficients amp (z1 + i z2) has the variance 4 sum(amp^2) / n^2.)
            scale = 2.0 * np.sqrt(np.sum(amp[:, 1:] ** 2, axis=1)) / n
            scale[scale == 0.0] = 1.0
            values = spec.marginal(values / scale) * scale
        values.flags.writeable = False
        return cls(spec=spec, B=B, span=span, dx=dx, values=values)

    @property
    def length(self) -> float:
        """Period of the field, m."""
        return float(self.values.shape[0] * self.dx)

    def shifted(self, distance: float) -> GustField:
        """Return the same field with ``t = 0`` moved ``distance`` m further along it."""
        return replace(self, x0=self.x0 + v.finite("distance", distance))

    def gusts(self, U: float, t: Any) -> FloatArray:
        """Effective gusts ``[u_eff, w_eff]`` (m/s) at times ``t`` (s) for mean speed ``U``.

        The field is interpolated linearly at ``x = x0 + U t`` (periodically), so samples at
        ``t = k dx / U`` are exact. Returns shape ``(len(t), 2)``; zeros when ``U = 0``.
        """
        t_arr = np.atleast_1d(np.asarray(t, dtype=float))
        x = self.x0 + U * t_arr
        n = self.values.shape[0]
        # Linear interpolation on the uniform grid by index: O(len(t)). (np.interp over the
        # whole period cost ~12 ms per call on a 2**20-point field, whatever the length of t:
        # the simulated instruments, which sample the tunnel in small blocks hundreds of times
        # a second, then starved each other and their clocks drifted off by milliseconds.)
        s = np.mod(x, self.length) / self.dx
        i = np.minimum(np.floor(s).astype(np.intp), n - 1)
        frac = (s - i)[:, None]
        out = self.values[i] * (1.0 - frac) + self.values[(i + 1) % n] * frac
        return np.asarray(U * out, dtype=float)


def buffeting_forces(
    spec: TurbulenceSpec, U: float, static: StaticCoefficients, *, B: float, span: float,
    rho: float, n: int, fs: float, rng: Any,
) -> FloatArray:
    """Seeded time series of the span-averaged buffeting forces ``[L_b B, M_b, D_b B]``.

    Parameters
    ----------
    spec : TurbulenceSpec
    U : float
        Mean wind speed, m/s, > 0.
    static : StaticCoefficients
    B, span, rho : float
        Deck width (m), section span (m), air density (kg/m^3).
    n : int
        Number of samples, >= 2 (one period of the periodic series).
    fs : float
        Sampling rate, Hz, > 0.
    rng : numpy.random.Generator or int
        Random source or seed (required).

    Returns
    -------
    ndarray, shape (n, 3)
        ``L_b B`` (N m/m), ``M_b`` (N m/m), ``D_b B`` (N m/m) at ``t = k / fs``; their one-sided
        spectra are those of :func:`buffeting_force_spectrum` up to ``fs / 2``.

    Examples
    --------
    >>> spec = TurbulenceSpec(Iu=0.1, Iw=0.05, Lux=0.5, Lwx=0.2, Cuy=10.0, Cwy=8.0)
    >>> F = buffeting_forces(spec, 5.0, StaticCoefficients.flat_plate(), B=0.3, span=1.0,
    ...                      rho=1.2, n=1024, fs=200.0, rng=1)
    >>> F.shape, bool(np.allclose(F, buffeting_forces(spec, 5.0, StaticCoefficients.flat_plate(),
    ...     B=0.3, span=1.0, rho=1.2, n=1024, fs=200.0, rng=1)))
    ((1024, 3), True)
    """
    U = v.positive("U", U)
    fs = v.positive("fs", fs)
    gusts = GustField.generate(spec, B=B, span=span, n=n, dx=U / fs, rng=rng)
    return np.asarray(U * gusts.values @ buffeting_gain(static, U, B, rho).T, dtype=float)


@dataclass(frozen=True, eq=False)
class WindLoad:
    """Mean plus buffeting generalised wind load on a section at one mean speed.

    Parameters
    ----------
    static : StaticCoefficients
        The section's static coefficients (mean load and quasi-steady gains).
    U : float
        Mean wind speed, m/s, >= 0 (0: no load).
    B, rho : float
        Deck width (m) and air density (kg/m^3).
    gusts : GustField, optional
        The effective gusts; without them only the mean load acts (smooth flow).
    """

    static: StaticCoefficients
    U: float
    B: float
    rho: float
    gusts: GustField | None = None

    def force(self, t: Any) -> FloatArray:
        """Generalised wind load ``[L B, M, D B]`` (N m/m) at times ``t`` (s), shape (k, 3)."""
        t_arr = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.zeros((t_arr.size, 3))
        if self.U <= 0.0:
            return out
        out += mean_wind_load(self.static, self.U, self.B, self.rho)
        if self.gusts is not None:
            gain = buffeting_gain(self.static, self.U, self.B, self.rho)
            out += self.gusts.gusts(self.U, t_arr) @ gain.T
        return out


def _generator(rng: Any) -> np.random.Generator:
    if rng is None or isinstance(rng, bool):
        raise ValueError("turbulence needs rng (a numpy Generator or an int seed) so that it is "
                         "reproducible")
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)):
        return np.random.default_rng(int(rng))
    raise TypeError(f"rng must be a numpy Generator or an int seed, got {type(rng).__name__}")
