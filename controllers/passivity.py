"""Passivity-based Cartesian PD of the Watflex arm (thesis 5.1, Damaren's law, eq. 5.1-5.2).

    tau = -J_theta^T [K_d (d/dt rho_mu - v_d) + K_p (rho_mu - rho_d)]          (eq. 5.1)
    rho_mu = (1 - mu) rho_r + mu rho_f                                       (eq. 5.2)

rho_r (m) is the end effector of the rigid arm at the measured joint angles, rho_f the
flexible estimate from the strain bridges (watflex_sim.endpoint, eq. 5.3-5.12), J_theta
(m/rad) the rigid arm's Jacobian. As in thesis 5.1.3 the angles pass a 2nd-order Butterworth
at 10 Hz and the bridge voltages one at 50 Hz; rho_mu is computed from the filtered signals
and differentiated by backward difference over one control period. The thesis used pure
position control (v_d = 0, "the reason for the tracking delay"); `velocity_feedforward`
adds the trajectory's velocity. The desired point rho_d follows rest-to-rest cubic moves
(controllers.trajectory, eq. 5.13); the first move starts from rho_mu at the first call.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

from watflex_sim.endpoint import LINK1_GAUGES, LINK2_GAUGES, EndpointEstimator
from watflex_sim.params import CONTROL_PERIOD, WATFLEX

from .filters import Butterworth2
from .trajectory import MoveSequence

STRAINS = tuple(f"strain_{g}" for g in LINK1_GAUGES + LINK2_GAUGES)


class Passivity:
    """Damaren's passivity-based PD on the end effector (thesis eq. 5.1-5.2), both joints.

    mu (-) blends rigid (0) and flexible (1) endpoint; kp (N/m) and kd (N s/m) are the
    diagonals of K_p and K_d; angle_filter_hz, strain_filter_hz (Hz) the Butterworth cutoffs;
    points (m, list of [x, y]), start_s and duration_s (s) the moves of the desired point
    (MoveSequence); velocity_feedforward adds the desired velocity to the damping term.
    After each call `rho_mu`, `rho_r`, `rho_f`, `rho_d` (m) and `force` (N) hold the last values.
    Raises ValueError for mu outside [0, 1] or malformed gains or moves.
    """

    def __init__(self, mu: float = 0.6, kp: Sequence[float] = (500.0, 500.0), kd: Sequence[float] = (200.0, 200.0),
                 angle_filter_hz: float = 10.0, strain_filter_hz: float = 50.0,
                 points: Sequence[Sequence[float]] = ((0.5, 0.9),), start_s: Sequence[float] = (0.0,),
                 duration_s: Sequence[float] = (3.0,), velocity_feedforward: bool = False,
                 period: float = CONTROL_PERIOD, params=WATFLEX):
        if not 0.0 <= mu <= 1.0:
            raise ValueError(f"passivity: mu must be within [0, 1], got {mu}")
        if len(kp) != 2 or len(kd) != 2:
            raise ValueError("passivity: kp and kd are the two diagonals [x, y] of K_p (N/m) and K_d (N s/m)")
        self.mu, self.period = float(mu), float(period)
        self.kp, self.kd = [float(k) for k in kp], [float(k) for k in kd]
        self.velocity_feedforward = bool(velocity_feedforward)
        self.estimator = EndpointEstimator(params)
        rate = 1.0 / self.period
        self._angle_filters = {j: Butterworth2(angle_filter_hz, rate) for j in ("shoulder", "elbow")}
        self._strain_filters = {c: Butterworth2(strain_filter_hz, rate) for c in STRAINS}
        self.trajectory = MoveSequence(points, start_s, duration_s)
        self.reset()

    def reset(self) -> None:
        for f in (*self._angle_filters.values(), *self._strain_filters.values()):
            f.reset()
        self._previous = None
        self.trajectory.moves = []
        self.rho_mu = self.rho_r = self.rho_f = self.rho_d = (math.nan, math.nan)
        self.force = (0.0, 0.0)

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        th1 = self._angle_filters["shoulder"](obs["shoulder_angle"])
        th2 = self._angle_filters["elbow"](obs["elbow_angle"])
        volts = {c: f(obs[c]) for c, f in self._strain_filters.items() if c in obs}
        est = self.estimator
        xr, yr = est.rigid_position(th1, th2)
        xf, yf = est.flexible_position(th1, th2, *est.deflections(volts))
        mu = self.mu
        x, y = (1 - mu) * xr + mu * xf, (1 - mu) * yr + mu * yf
        if self._previous is None:
            self._previous = (x, y)
            self.trajectory.set_origin((x, y))
        vx, vy = (x - self._previous[0]) / self.period, (y - self._previous[1]) / self.period
        self._previous = (x, y)
        xd, yd = self.trajectory.position(t)
        if self.velocity_feedforward:
            vdx, vdy = self.trajectory.velocity(t)
            vx, vy = vx - vdx, vy - vdy
        fx = self.kd[0] * vx + self.kp[0] * (x - xd)
        fy = self.kd[1] * vy + self.kp[1] * (y - yd)
        (j11, j12), (j21, j22) = est.rigid_jacobian(th1, th2)
        self.rho_mu, self.rho_r, self.rho_f, self.rho_d = (x, y), (xr, yr), (xf, yf), (float(xd), float(yd))
        self.force = (-fx, -fy)
        return {"shoulder_torque_cmd": -(j11 * fx + j21 * fy), "elbow_torque_cmd": -(j12 * fx + j22 * fy)}


def compensated(controller, spec: Mapping | None, joints: Sequence[str], rig_params=WATFLEX):
    """`controller` wrapped by one friction compensation per joint (thesis 4.5.5), or as is.

    spec is a [controller.compensation]-like table without `joint` (scheme, numbers, optional
    positive/negative overrides; controllers.friction_compensation.wrap_compensation), applied
    to each of `joints` (rigs.md §2 nominal friction of that joint). The outermost wrapper is
    returned; `.inner` leads back to `controller`.
    """
    if not spec:
        return controller
    from .friction_compensation import wrap_compensation

    spec = dict(spec)
    only = spec.pop("joints", None)
    for joint in (only if only is not None else joints):
        controller = wrap_compensation(controller, {**spec, "joint": joint}, rig_params)
    return controller


def make_passivity(friction_compensation: Mapping | None = None, **kwargs):
    """Scenario factory (`type = "passivity"`): Passivity(**kwargs), with a `friction_compensation`
    table applied to both joints (see `compensated`)."""
    return compensated(Passivity(**kwargs), friction_compensation, ("shoulder", "elbow"))
