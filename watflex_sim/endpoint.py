"""End-effector position of the Watflex arm from joint angles and strain bridges (thesis 5.1.2).

Each flexible part's shape is a polynomial w(x) in x (m) from the root clamp, with the
clamped root w(0) = w'(0) = 0 (eq. 5.3, 5.7):
  link 1: w1 = b2 x^2 + b3 x^3 + b4 x^4  (three bridges 1A, 1B, 1C fix b2..b4, eq. 5.6)
  link 2: w2 = a2 x^2 + a3 x^3           (two bridges 2A, 2B fix a2, a3)
from the surface strain eps = -(t/2) w''(x) at each bridge (eq. 5.4-5.5). The bridge reads
V = eps / K (rigs.md §2, table 3.2), so w''(x_ij) = -2 K_ij V_ij / t_i (1/m).
The deflection v_i = w_i(L_i) (m) and slope alpha_i = w_i'(L_i) (rad) at the end of each
flexible part (eq. 5.8-5.9) enter the flexible forward kinematics (eq. 5.11-5.12), which keep
each link's length constant (no foreshortening). Everything is linear in the bridge volts, so
the volts -> (v, alpha) maps are computed once.

Angles in rad, lengths in m, bridge outputs in V; the arm's plane is the table's x-y plane with
the shoulder axis at the origin and all joint angles 0 along +x (models/watflex.xml).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .params import WATFLEX, Watflex

LINK1_GAUGES = ("1A", "1B", "1C")
LINK2_GAUGES = ("2A", "2B")


@dataclass(frozen=True)
class LinkShape:
    """One flexible part: polynomial coefficients (x^2 upwards, SI), end deflection v (m), end slope alpha (rad)."""

    coefficients: tuple[float, ...]
    v: float
    alpha: float


def shape_maps(gauge_x: np.ndarray, length: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Linear maps curvature-at-gauges (1/m) -> coefficients (x^2 .. x^order) and -> (v, alpha).

    Needs order - 1 gauges (the two root conditions fix the rest). Returns (C, E) with
    coefficients = C @ w'' and (v, alpha) = E @ w''. Raises ValueError on a mismatch.
    """
    gauge_x = np.asarray(gauge_x, float)
    powers = np.arange(2, order + 1)
    if gauge_x.size != powers.size:
        raise ValueError(f"a polynomial of order {order} with w(0) = w'(0) = 0 needs {powers.size} gauges, got {gauge_x.size}")
    # w''(x) = sum n (n-1) c_n x^(n-2)  (eq. 5.5; the matrix of eq. 5.6 for order 4)
    curvature = np.array([[n * (n - 1) * x ** (n - 2) for n in powers] for x in gauge_x])
    C = np.linalg.inv(curvature)
    end = np.array([length**powers, powers * length ** (powers - 1)])  # rows v = w(L), alpha = w'(L)
    return C, end @ C


class EndpointEstimator:
    """Flexible and rigid forward kinematics of the Watflex arm from measured channels.

    `params` is a params.Watflex (geometry l1a..l2c, link thicknesses, bridge positions and
    calibration K). Methods take angles in rad, volts in V and return metres / radians.
    """

    def __init__(self, params: Watflex = WATFLEX):
        p = self.p = params
        self.L1 = p.l1a + p.link1.length + p.l1c  # m, rigid link lengths (shoulder -> elbow)
        self.L2 = p.l2a + p.link2.length + p.l2c  # m, elbow -> end-effector centre
        self._maps = []
        for names, beam, order in ((LINK1_GAUGES, p.link1, 4), (LINK2_GAUGES, p.link2, 3)):
            x = np.array([p.gauges[n][1] for n in names])
            volts_to_curv = np.diag([-2.0 * p.gauges[n][2] / beam.thickness for n in names])  # 1/m per V
            C, E = shape_maps(x, beam.length, order)
            self._maps.append((tuple(f"strain_{n}" for n in names), C @ volts_to_curv, E @ volts_to_curv))
        # plain-float rows for the 1 kHz path: v = sum(ev_i V_i), alpha = sum(ea_i V_i)
        self._rows = [(ch, E[0].tolist(), E[1].tolist()) for ch, _C, E in self._maps]

    # -- link shapes ----------------------------------------------------------------------
    def link_shapes(self, volts: Mapping[str, float]) -> tuple[LinkShape, LinkShape]:
        """Both links' polynomial shapes from the bridge voltages `volts` (channel -> V)."""
        out = []
        for channels, C, E in self._maps:
            V = np.array([volts[c] for c in channels], float)
            v, alpha = E @ V
            out.append(LinkShape(tuple((C @ V).tolist()), float(v), float(alpha)))
        return out[0], out[1]

    def deflections(self, volts: Mapping[str, float]) -> tuple[float, float, float, float]:
        """(v1, alpha1, v2, alpha2) in m, rad (eq. 5.8-5.9) from the bridge voltages; a link
        whose bridges are missing (a locked, removed chain) counts as straight."""
        out = []
        for channels, ev, ea in self._rows:
            if channels[0] not in volts:
                out += [0.0, 0.0]
                continue
            V = [volts[c] for c in channels]
            out += [sum(e * x for e, x in zip(ev, V)), sum(e * x for e, x in zip(ea, V))]
        return out[0], out[1], out[2], out[3]

    # -- kinematics -----------------------------------------------------------------------
    def flexible_position(self, theta1: float, theta2: float, v1: float, alpha1: float,
                          v2: float, alpha2: float) -> tuple[float, float]:
        """End-effector (x, y) in m, thesis eq. 5.11-5.12."""
        p = self.p
        a1 = theta1
        a2 = theta1 + alpha1 + theta2
        a3 = a2 + alpha2
        r1, r2 = p.l1a + p.link1.length, p.l2a + p.link2.length
        c1, s1, c2, s2 = math.cos(a1), math.sin(a1), math.cos(a2), math.sin(a2)
        x = r1 * c1 - v1 * s1 + p.l1c * math.cos(a1 + alpha1) + r2 * c2 - v2 * s2 + p.l2c * math.cos(a3)
        y = r1 * s1 + v1 * c1 + p.l1c * math.sin(a1 + alpha1) + r2 * s2 + v2 * c2 + p.l2c * math.sin(a3)
        return x, y

    def rigid_position(self, theta1: float, theta2: float) -> tuple[float, float]:
        """(x, y) in m of the end effector if both links were rigid (rho_r of eq. 5.2)."""
        a12 = theta1 + theta2
        return (self.L1 * math.cos(theta1) + self.L2 * math.cos(a12),
                self.L1 * math.sin(theta1) + self.L2 * math.sin(a12))

    def rigid_jacobian(self, theta1: float, theta2: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """J_theta (m/rad) of the rigid two-link arm: d(x, y)/d(theta1, theta2), rows x and y."""
        a12 = theta1 + theta2
        s1, c1, s12, c12 = math.sin(theta1), math.cos(theta1), math.sin(a12), math.cos(a12)
        return ((-self.L1 * s1 - self.L2 * s12, -self.L2 * s12),
                (self.L1 * c1 + self.L2 * c12, self.L2 * c12))

    def rigid_inverse(self, x: float, y: float, elbow_sign: float = 1.0) -> tuple[float, float]:
        """Joint angles (rad) putting the rigid arm's end effector at (x, y) m; `elbow_sign`
        picks the branch (sign of theta2). Raises ValueError outside the workspace."""
        c2 = (x * x + y * y - self.L1**2 - self.L2**2) / (2 * self.L1 * self.L2)
        if abs(c2) > 1:
            raise ValueError(f"({x:.3f}, {y:.3f}) m is outside the rigid arm's reach")
        theta2 = math.copysign(math.acos(c2), elbow_sign)
        theta1 = math.atan2(y, x) - math.atan2(self.L2 * math.sin(theta2), self.L1 + self.L2 * math.cos(theta2))
        return theta1, theta2

    def estimate(self, obs: Mapping[str, float]) -> tuple[float, float]:
        """Flexible end-effector estimate (x, y) in m from a WatflexRig observation (angles, bridges)."""
        return self.flexible_position(obs["shoulder_angle"], obs["elbow_angle"], *self.deflections(obs))
