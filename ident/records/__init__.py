"""What was measured, as identification sees it: releases, and the run files they come from.

- :mod:`~ident.records.release`: one free-vibration release (``Release``), validated;
- :mod:`~ident.records.run_file`: the one thin module through which ident reads run files.
"""
