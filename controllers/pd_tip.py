"""Laser-arm PD on the tip sensor (rigs.md §1 'Nominal PD controller')."""
from __future__ import annotations

from typing import Mapping

from watflex_sim.params import CONTROL_PERIOD


class PDTip:
    """u = Kp e_V + Kd (e_V(k) - e_V(k-1)) / T  (V), e_V the tip sensor (V).

    kp in V/V, kd in V s/V, period T in s. Saturation at +-24 V is the amplifier's, applied
    by the rig. Defaults are rigs.md's [choice] gains (0.127, 0).
    """

    def __init__(self, kp: float = 0.127, kd: float = 0.0, period: float = CONTROL_PERIOD):
        self.kp, self.kd, self.period = float(kp), float(kd), float(period)
        self.reset()

    def reset(self) -> None:
        self._previous = None

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        e = obs["tip_sensor"]
        de = 0.0 if self._previous is None else (e - self._previous) / self.period
        self._previous = e
        return {"voltage_cmd": self.kp * e + self.kd * de}
