"""Where the identified model and the measurements disagree, and which physical effects are missing.

- :mod:`~ident.discrepancy.workflow`: ``diagnose``, the workflow from releases to a verdict;
- :mod:`~ident.discrepancy.effect_selection`: forward selection of the named effects;
- :mod:`~ident.discrepancy.gap_rule`: the rule every named effect passes (its addition shrinks
  the simulated gap by a stated margin);
- :mod:`~ident.discrepancy.residual_check`: what is left after them, and where;
- :mod:`~ident.discrepancy.coupling`: heave-pitch coupling at zero wind.

Private machinery: ``_equation_error`` (equation-error fits of the structural candidates),
``_force_fit`` (force-equation fits), ``_base_fit`` (the base-vibration candidate).
"""
