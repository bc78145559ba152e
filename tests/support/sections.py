"""The section models the tests share.

``FLAT_PLATE`` is the light flat-plate section of the simulated rig's examples: chord 0.3 m,
3 kg/m and 0.03 kg m^2/m, heave 2 Hz and pitch 4 Hz, both damped 0.5 % of critical. It is frozen
(``SectionModel`` is a frozen dataclass), so one instance serves every test.
"""

from __future__ import annotations

from ident.model.section import SectionModel

#: The flat plate of most identification tests (B m, m kg/m, I kg m^2/m, fh and fa Hz, zeta -).
FLAT_PLATE = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
