"""Identification from releases: E2RFC, modal fits, the indirect route and a campaign's analysis.

- :mod:`~ident.identification.e2rfc`: ``identify``, E2RFC from releases at a few wind speeds;
- :mod:`~ident.identification.results`: what it returns (``IdentifiedModel``, diagnostics);
- :mod:`~ident.identification.uncertainty`: the flutter speed's uncertainty and its parts;
- :mod:`~ident.identification.covariance`: the parameter covariance as ``windrig identify
  --json`` writes it, and models sampled from it;
- :mod:`~ident.identification.modal`: modal identification of free decays;
- :mod:`~ident.identification.fd_method`: the indirect route (flutter derivatives, Roger fit);
- :mod:`~ident.identification.innovations`: a release in turbulence as a discrete state-space
  model (buffeting through a shaping filter, sensor noise) and its exact likelihood from a
  Kalman filter's innovations;
- :mod:`~ident.identification.channels`: a release's channels in the order the closed-loop
  model reads them, and their scales to the generalised coordinates and forces;
- :mod:`~ident.identification.steady_predictor`: the steady-state Kalman predictor, its
  likelihood and its first-order changes;
- :mod:`~ident.identification.closed_loop_ml`: closed-loop maximum likelihood of releases in
  turbulence (the turbulence branch's default);
- :mod:`~ident.identification.innovation_checks`: whether a fit's innovations, pooled over
  its records, are white;
- :mod:`~ident.identification.campaign`: one campaign's analysis for the front ends.

E2RFC's private machinery: ``_regressors`` (per-release regressors), ``_e2rfc_problem`` (the
stacked problem and its structure search), ``_stacked`` and ``_full_rows`` (its residuals,
Jacobians and Gram matrices), ``_turbulent_fit`` (the refined-IV turbulence branch);
``_closed_loop_parameters`` (the closed-loop fit's records, parameter layout and start),
``_closed_loop_starts`` (more starts when its first maximum contradicts the releases).
"""
