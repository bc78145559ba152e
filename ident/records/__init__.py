"""What was measured, as identification sees it: releases, and the run files they come from.

- :mod:`~ident.records.release`: one free-vibration release (``Release``), validated;
- :mod:`~ident.records.run_file`: the one thin module through which ident reads run files;
- :mod:`~ident.records.run_layout`: what it has read against the layout the readers need (a
  column of text, a release table of plain numbers, a release listed twice), named in one line;
- :mod:`~ident.records.run_set`: what a campaign's files say together (their one section model,
  their tubing correction, the warnings they were recorded with);
- :mod:`~ident.records.release_onset`: the release instant found in the displacements alone
  (a release by hand, a file without release events);
- :mod:`~ident.records.plausibility`: guards against unit mistakes and dead channels in each
  release (a pitch in degrees, a time axis in ms, forces far beyond the wind's, an air density
  in g/m^3, a late release instant, a channel of one value), run by E2RFC;
- :mod:`~ident.records.decay_checks`: the section and the identified model against the
  measured decays (still-air frequencies in rad/s or swapped, in turbulence from the spectral
  peaks; damping in per cent; forces off by a factor, a lift of the wrong sign, a small
  displacement in a wrong unit), run by E2RFC (the frequencies and damping by the
  displacement-only route too).
"""
