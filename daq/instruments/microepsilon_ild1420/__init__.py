"""The Micro-Epsilon optoNCDT ILD1420-class laser displacement sensor.

- :mod:`.settings`: the ``[[lasers]]`` table (range, rate, output values, position, line);
- :mod:`.decoder`: the 3-byte words of the binary stream into samples (pure, resynchronising);
- :mod:`.sequencer`: counter and timestamp unwrapping, gaps and restarts;
- :mod:`.driver`: :class:`MicroEpsilonIld1420`, the ASCII commands, the stream, reconnects;
  its ``read()`` returns a :class:`~daq.instruments.reading.Reading`.
"""
