"""Joint PD for the Watflex arm (rigs.md §2 'Single-joint elbow experiment')."""
from __future__ import annotations

from typing import Mapping, Sequence

from watflex_sim.params import CONTROL_PERIOD

from .filters import Butterworth2


class PDJoint:
    """tau_j = Kp_j (theta_ref_j - theta_j) - Kd_j dtheta_j  (N m) for each joint in `joints`.

    dtheta is the encoder's backward difference (rad/s) through a 2nd-order Butterworth at
    `filter_hz` (Hz). kp in N m/rad, kd in N m s/rad. Torque limits are the rig's converter's.
    """

    def __init__(self, joints: Sequence[str] = ("elbow",), kp: Sequence[float] = (60.0,),
                 kd: Sequence[float] = (12.0,), filter_hz: float = 10.0, period: float = CONTROL_PERIOD):
        if not (len(joints) == len(kp) == len(kd)):
            raise ValueError("pd_joint: 'joints', 'kp' and 'kd' must have the same length")
        self.joints, self.kp, self.kd = list(joints), [float(k) for k in kp], [float(k) for k in kd]
        self.period = float(period)
        self.filters = [Butterworth2(filter_hz, 1.0 / period) for _ in self.joints]
        self.reset()

    def reset(self) -> None:
        self._previous = [None] * len(self.joints)
        for f in self.filters:
            f.reset()

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        out = {}
        for i, j in enumerate(self.joints):
            theta = obs[f"{j}_angle"]
            prev = self._previous[i]
            rate = self.filters[i](0.0 if prev is None else (theta - prev) / self.period)
            self._previous[i] = theta
            out[f"{j}_torque_cmd"] = self.kp[i] * (obs[f"{j}_reference"] - theta) - self.kd[i] * rate
        return out
