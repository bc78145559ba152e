"""Full-bridge flutter and buffeting from section aerodynamics (strip theory on still-air modes).

Modules
-------
modal_system
    The bridge in modal coordinates: strip-theory projection of Roger's form, state space with
    lag states and a buffeting input.
wind
    WIND.toml (turbulence intensities, length scales, coherence, admittance) and span-wise
    coherence.
buffeting
    Modal buffeting forces (quasi-steady, coherence, admittance) and the frequency-domain
    response: spectra and RMS along the deck.
buffeting_time
    Time-domain buffeting: a simulated multi-point turbulence field through the state space.
"""
