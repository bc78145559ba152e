"""Physics around the section model: the air, the wind, the pressure taps and the named effects.

- :mod:`~ident.physics.air`: density of moist air (CIPM-2007);
- :mod:`~ident.physics.turbulence`: turbulence spectra, coherence and buffeting forces;
- :mod:`~ident.physics.taps`: tap layouts and their integration into lift, moment and drag;
- :mod:`~ident.physics.tubing`: pneumatic tubing between taps and scanner (distortion, correction);
- :mod:`~ident.physics.effects`: the named effects the linear model leaves out (parameters only).
"""
