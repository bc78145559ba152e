"""Small numerical tools that the rest of :mod:`ident` shares (imports nothing else of ident).

- :mod:`~ident.numerics.validate`: input checks of the public constructors (one clear message);
- :mod:`~ident.numerics.lsq`: a bounded Levenberg-Marquardt solver for few-parameter searches;
- :mod:`~ident.numerics.normal_equations`: column-scaled normal equations of stacked problems;
- :mod:`~ident.numerics.selection`: choosing a model structure by held-out error (one-SE rule);
- :mod:`~ident.numerics.sampling`: decimation factors of rates that are not exactly round;
- :mod:`~ident.numerics.quadrature`: trapezoid-rule weights on an uneven grid;
- :mod:`~ident.numerics.stats`: the autocorrelation inflation of a residual's variance, and
  white noise read from third differences;
- :mod:`~ident.numerics.threads`: numerical kernels under single-threaded BLAS.
"""
