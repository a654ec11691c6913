"""Laser-arm PD on the tip sensor (rigs.md §1 'Nominal PD controller'), an instance of PID."""
from __future__ import annotations

from watflex_sim.params import CONTROL_PERIOD

from .pid import PID


class PDTip(PID):
    """u = Kp e_V + Kd (e_V(k) - e_V(k-1)) / T  (V), e_V the tip sensor (V).

    kp in V/V, kd in V s/V, period T in s. Saturation at +-24 V is the amplifier's, applied
    by the rig. Defaults are rigs.md's [choice] gains (0.127, 0). As PID: the tip sensor is the
    position with reference 0, so the gains change sign (exactly: -(-kp)(0 - e) = kp e).
    """

    def __init__(self, kp: float = 0.127, kd: float = 0.0, period: float = CONTROL_PERIOD):
        super().__init__(command="voltage_cmd", position="tip_sensor", reference="", kp=-float(kp),
                         kd=-float(kd), rate_method="difference", period=period)
