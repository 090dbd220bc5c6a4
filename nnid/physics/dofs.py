"""The names of the six degrees of freedom and of their generalized forces (Fossen's order).

Body velocities ``u v w p q r`` (surge, sway, heave, roll, pitch, yaw) and the forces and
moments ``X Y Z K M N`` that act along them (SNAME 1950; Weiss eq. 11; McCarter ch. 2).
"""

from __future__ import annotations

DOFS = ("u", "v", "w", "p", "q", "r")
FORCES = ("X", "Y", "Z", "K", "M", "N")
#: each DOF in words, as reports and messages name it
DOF_WORD = dict(zip(DOFS, ("surge", "sway", "heave", "roll", "pitch", "yaw"), strict=True))
