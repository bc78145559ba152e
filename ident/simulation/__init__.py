"""Simulated free decays of a section model in the wind, with the named effects.

- :mod:`~ident.simulation.decay`: ``simulate_decay``, the entry point, and its result;
- :mod:`~ident.simulation.plant`: the structure and its aerodynamics as an integrated plant;
- :mod:`~ident.simulation.measurement`: the measurement chain (forces from the motion, tubing,
  channel delay, sensor crosstalk).
"""
