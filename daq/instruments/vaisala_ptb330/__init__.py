"""The Vaisala PTB330-class barometer.

- :mod:`.settings`: the ``[barometer]`` table (poll interval, reply timeout, address);
- :mod:`.decoder`: the ASCII reply lines into pressure, temperature and air density (pure);
- :mod:`.driver`: :class:`VaisalaPtb330`, the output format, polling, retries.
"""
