"""Joint PD for the Watflex arm (rigs.md §2 'Single-joint elbow experiment'), an instance of StateFeedback."""
from __future__ import annotations

from typing import Sequence

from watflex_sim.params import CONTROL_PERIOD

from .state_feedback import StateFeedback


class PDJoint(StateFeedback):
    """tau_j = Kp_j (theta_ref_j - theta_j) - Kd_j dtheta_j  (N m) for each joint in `joints`.

    dtheta is the encoder's backward difference (rad/s) through a 2nd-order Butterworth at
    `filter_hz` (Hz). kp in N m/rad, kd in N m s/rad. Torque limits are the rig's converter's.
    """

    def __init__(self, joints: Sequence[str] = ("elbow",), kp: Sequence[float] = (60.0,),
                 kd: Sequence[float] = (12.0,), filter_hz: float = 10.0, period: float = CONTROL_PERIOD):
        if not (len(joints) == len(kp) == len(kd)):
            raise ValueError("pd_joint: 'joints', 'kp' and 'kd' must have the same length")
        states = [s for j in joints for s in (f"{j}_angle", f"rate:{j}_angle")]
        gains = [[0.0] * len(states) for _ in joints]  # block diagonal: joint i's (kp, kd)
        for i, (p, d) in enumerate(zip(kp, kd)):
            gains[i][2 * i: 2 * i + 2] = [float(p), float(d)]
        super().__init__(commands=[f"{j}_torque_cmd" for j in joints], states=states, gains=gains,
                         references={f"{j}_angle": f"{j}_reference" for j in joints}, rate_hz=filter_hz,
                         rate_method="butterworth_difference", period=period)
