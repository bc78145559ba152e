"""The aeroelastic model: the section, windrig's conventions, Roger's form and flutter analysis.

- :mod:`~ident.model.conventions`: signs, coordinates, flutter derivatives <-> ``Q(iK)``,
  the naming of modes (heave, pitch, sway);
- :mod:`~ident.model.section`: the spring-mounted section model (``SectionModel``), the
  defaults a section file leaves and the check of its proportions (a unit slip);
- :mod:`~ident.model.rfc`: Roger's rational-function model (``RationalFunctionModel``);
- :mod:`~ident.model.roger`: Roger's least-squares fit of ``Q`` samples;
- :mod:`~ident.model.statespace`: the state-space equations of motion in the wind;
- :mod:`~ident.model.flutter`: the flutter speed, state space and frequency domain;
- :mod:`~ident.model.flat_plate`: the analytic truth case (Theodorsen, Jones's approximation);
- :mod:`~ident.model.quasi_steady`: static coefficients and the quasi-steady 3-DOF forces.
"""
