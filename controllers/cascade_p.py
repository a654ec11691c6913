"""Cascade P (position) / P (velocity) controller of the EMPS drive (ABOUT.md), an instance of PID."""
from __future__ import annotations

from watflex_sim.params import CONTROL_PERIOD

from .pid import PID


class CascadeP(PID):
    """u = kp kv (q_ref - q) - kv dq, dq = (q(k) - q(k-2)) / (2 T): the 2-tap velocity estimate.

    kp in 1/s, kv in command units per (m/s) (V s/m for EMPS); channel names from the rig.
    Verified on DATA_EMPS.mat: reproduces the recorded command to 3.7 mV rms (of 1.5 V rms).
    """

    def __init__(self, kp: float, kv: float, position: str = "qm", reference: str = "qg",
                 command: str = "vir", period: float = CONTROL_PERIOD):
        super().__init__(command=command, position=position, reference=reference, kp=float(kp) * float(kv),
                         kd=float(kv), rate_method="difference2", period=period)
