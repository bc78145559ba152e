"""The virtual tunnel: section-model physics in the wind, and the simulated instruments.

:mod:`simulators.tunnel` simulates free-vibration releases; :mod:`simulators.effects` holds the
named physical effects that can be added to them; :mod:`simulators.virtual_tunnel` is the one
tunnel that every simulated instrument of :mod:`simulators.devices` samples in real time (with
:mod:`simulators.clock` for their clocks and :mod:`simulators.noise` for noise keyed to the
release and the sample). :mod:`simulators.nidaqmx_standin` stands in for the parts of NI's
``nidaqmx`` API that windrig's NI-DAQmx driver uses, reading the simulated DAQ device
:mod:`simulators.devices.ni_daqmx`. :mod:`simulators.campaigns` simulates seeded test campaigns
with hidden effects, :mod:`simulators.tunnel_campaigns` records them from the virtual tunnel
with effects of random strength (the discrepancy benchmark's data). This package may import
:mod:`ident` (for the aerodynamic model) but never :mod:`daq`.
"""

from simulators import effects, tunnel
from simulators.effects import EFFECT_NAMES
from simulators.tunnel import SimulatedRelease, simulate_release

__all__ = ["EFFECT_NAMES", "SimulatedRelease", "effects", "simulate_release", "tunnel"]
