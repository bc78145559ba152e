"""The full bridge in the wind: multimode flutter and buffeting from section aerodynamics.

Strip theory takes a deck section's self-excited forces (a rational-function model from E2RFC or
a flutter-derivative table) to the whole structure's still-air modes (DESIGN, "Full-bridge
flutter and buffeting"):

- :mod:`~ident.bridge.model`: :class:`~ident.bridge.model.BridgeModel`, the bridge model file
  (deck nodes, modes, static coefficients), its validation, and the integrals of mode-shape
  products along the deck that give the modal aerodynamic matrices;
- :mod:`~ident.bridge.mode_checks`: the modes' plausibility (masses and damping no deck has,
  named by the unit slip that explains them);
- :mod:`~ident.bridge.statespace`: the modal state-space model with modal lag states, whose
  matrix depends explicitly on U;
- :mod:`~ident.bridge.flutter`: multimode flutter without iteration (state space), the
  multimode frequency-domain check from flutter derivatives, and every mode's in-wind frequency
  and damping against U;
- :mod:`~ident.bridge.fast_flutter`: many-mode flutter without a dense sweep: the lag states
  eliminated exactly (an ``n x n`` rational eigenproblem), the branches that can flutter
  followed in U, the flutter point solved by Newton and certified by two dense solves;
- :mod:`~ident.bridge.fast_flutter_fd`: the frequency-domain check the same way (its quadratic
  problem followed in 1/K);
- :mod:`~ident.bridge.routes`: the bridge's flutter by both routes, compared as a section's are
  (:mod:`ident.tables.flutter_routes`);
- :mod:`~ident.bridge.uncertainty`: the section's uncertainty carried to the flutter speed
  (delta method from the flutter point's null vectors; Monte Carlo over a model's covariance
  or a table's std columns, as picklable tasks);
- :mod:`~ident.bridge.aero`: the section aerodynamics for a bridge: an RFC model or a
  Roger-fitted flutter-derivative table (with its relative error at every tabulated K);
- :mod:`~ident.bridge.mode_tables`: plain CSV tables of mode shapes (one per mode, as exported
  from a finite-element program) to the bridge model file;
- :mod:`~ident.bridge.wind`: the wind file (WIND.toml: turbulence intensities, length scales,
  span-wise coherence, admittance) and the coherence of the gusts between deck nodes;
- :mod:`~ident.bridge.buffeting`: buffeting in turbulent wind in the frequency domain (modal gust
  forces with coherence and admittance, response spectra and RMS along the deck);
- :mod:`~ident.bridge.buffeting_eigen`: its fast route: one eigen decomposition of the modal
  state space, pole products in partial fractions, the load matrices splined in frequency;
- :mod:`~ident.bridge.buffeting_time`: buffeting in the time domain (a simulated multi-point
  turbulence field through the modal state space).
"""
