"""windrig driver plugin for a Scanivalve DSA3217-class 16-channel Ethernet pressure scanner.

- :mod:`~windrig_dsa3217.settings`: the ``[scanner]`` table of a rig config, validated;
- :mod:`~windrig_dsa3217.packets`: the binary "Scan EU with Time" packet, decoded;
- :mod:`~windrig_dsa3217.driver`: the driver (the scanner role of windrig's docs/guides/drivers.md);
- :mod:`~windrig_dsa3217.simulator`: a simulated DSA3217 serving its bytes on 127.0.0.1.
"""
