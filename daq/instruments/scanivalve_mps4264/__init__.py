"""The Scanivalve MPS4264-class pressure scanner.

- :mod:`.settings`: the ``[scanner]`` table (modules, rate, ports, Pitot channel, batching);
- :mod:`.frames`: the binary packets (0x6D, legacy 0x0A) and their pure, vectorised decoder;
- :mod:`.streams`: one module's data connection state: bytes, decoder, merge keys;
- :mod:`.merge`: the modules' frames merged into blocks, counters, gaps and clock steps;
- :mod:`.blocks`: the frames of one scan's read (:class:`ScanBlock`, :class:`ClockStep`);
- :mod:`.continuity`: the scans of a stream as one: counters and frame times continued
  across a restart (a lost connection, a CALZ), the restart's gap measured where it can be;
- :mod:`.driver`: :class:`ScanivalveMps4264`, the commands, the scan, reconnects, batching;
  its ``read()`` returns a :class:`~daq.instruments.reading.Reading`.
"""
