"""Observer-based recursive joint control of a flexible link (thesis 5.2, Ostojic's law, eq. 5.14-5.20).

Model of one joint (eq. 5.14), motor angle theta_m (the encoder) and arm angle theta_a joined
by a torsional spring k:
    J_a theta_a'' = k (theta_m - theta_a) - b_a theta_a'
    J_m theta_m'' = tau - b_m theta_m' - k (theta_m - theta_a)
State x = [theta_m, theta_a, theta_m', theta_a'] (eq. 5.19), measurement theta_m = c^T x.

Observer (eq. 5.20): a full-order Luenberger observer with all four poles at -p (rad/s). It
runs at the 1 ms control period as the exact (zero-order-hold) discretisation of eq. 5.18 with
the discrete poles at exp(-p T), the image of -p; the correction uses the current encoder
sample (current-estimator form), so the estimation error of the linear model obeys
e[n+1] = Phi (I - M c^T) e[n] with eigenvalues exp(-p T). `thesis_gains` gives the thesis'
closed-form continuous gains K, which place eig(A - K c^T) at -p.

Control law (eq. 5.15-5.17): tau(n+1) = sat(tau(n) + gamma sigma(n)), with the error dynamics
sigma = e'''' + 4a e''' + 6a^2 e'' + 4a^3 e' + a^4 e for e = theta_d - theta_a, written in the
states and accelerations (eq. 5.17). The accelerations theta_m'', theta_a'' are the model's
(eq. 5.14) at the estimated state and the torque applied over the last period. With Ostojic's
gamma = J_a J_m / k the update solves sigma = 0 in one step, so the unsaturated loop is the
state feedback tau = gamma (a0 theta_d - a3 theta_m' - a2 theta_a'' - ...) on the estimate.

Signs: the thesis' tables list a = -10 and p = -30 as pole *locations*; here `a` and `p` are
the (positive) rates, poles at -a and -p, as eq. 5.16 requires for a decaying error.

`rigid=True` is the "observer based controller for rigid arms" of fig. 5.8 [ours: the thesis
gives no detail]: the same scheme on the rigid model (J_m + J_a) theta'' = tau - (b_m + b_a) theta',
second-order error dynamics e'' + 2a e' + a^2 e and a two-state observer with poles at -p.
"""
from __future__ import annotations

import functools
import math
from typing import Mapping, Sequence

import numpy as np
from scipy.linalg import expm

from watflex_sim.params import CONTROL_PERIOD, WATFLEX

from .passivity import compensated


def flexible_model(j_m: float, j_a: float, k: float, b_m: float = 0.0, b_a: float = 0.0):
    """(A, b, c) of eq. 5.19 for the state [theta_m, theta_a, theta_m', theta_a'] (SI units)."""
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1],
                  [-k / j_m, k / j_m, -b_m / j_m, 0], [k / j_a, -k / j_a, 0, -b_a / j_a]], float)
    return A, np.array([0, 0, 1 / j_m, 0.0]), np.array([1.0, 0, 0, 0])


def rigid_model(j: float, b: float = 0.0):
    """(A, b, c) of the rigid joint J theta'' = tau - b theta', state [theta, theta']."""
    return np.array([[0, 1], [0, -b / j]], float), np.array([0, 1 / j]), np.array([1.0, 0])


def thesis_gains(j_m: float, j_a: float, k: float, b_m: float, b_a: float, p: float) -> np.ndarray:
    """Continuous observer gains K = [k1, k2, k3, k4] placing all poles of A - K c^T at -p (thesis 5.2.3).

    From det(sI - A + K c^T) = (s + p)^4 coefficient by coefficient (our derivation; the
    general-b terms of the thesis' printed formulas are garbled in our copy of the text, with
    b_m = b_a = 0, as tables 5.1-5.2 use, they are k1 = 4p, k3 = 6p^2 - k/J_m - k/J_a,
    k2 = J_m/k (4p^3 - k1 k/J_a), k4 = J_m/k (p^4 - k3 k/J_a)).
    """
    dm, da, al, be = b_m / j_m, b_a / j_a, k / j_m, k / j_a
    k1 = 4 * p - dm - da
    k3 = 6 * p**2 - al - be - dm * da - k1 * (dm + da)
    k2 = (4 * p**3 - al * da - be * dm - k1 * be - (dm * k1 + k3) * da) / al
    k4 = (p**4 - (dm * k1 + k3) * be) / al - da * k2
    return np.array([k1, k2, k3, k4])


def acker(A: np.ndarray, c: np.ndarray, poles: Sequence[float]) -> np.ndarray:
    """Observer gain L with eig(A - L c^T) = poles (Ackermann's formula on the dual system)."""
    n = A.shape[0]
    O = np.vstack([c @ np.linalg.matrix_power(A, i) for i in range(n)])
    phi = np.real(np.poly(poles))  # characteristic polynomial coefficients, highest first
    phiA = sum(coef * np.linalg.matrix_power(A, n - i) for i, coef in enumerate(phi))
    return phiA @ np.linalg.solve(O, np.eye(n)[:, -1])


def discrete_observer(A: np.ndarray, b: np.ndarray, c: np.ndarray, p: float, period: float):
    """(Phi, Gamma, M): ZOH discretisation and the current-estimator gain M placing the
    eigenvalues of Phi (I - M c^T) at exp(-p T) (all n of them).

    Placed in the delta domain, Phi = I + T D, for conditioning: with Phi - L c^T = I + T (D - (L/T) c^T)
    the gain L/T puts D's poles at (exp(-p T) - 1) / T; M = Phi^-1 L.
    """
    n = A.shape[0]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = A, b
    E = expm(aug * period)
    Phi, Gamma = E[:n, :n], E[:n, n]
    D = (Phi - np.eye(n)) / period
    L = period * acker(D, c, [(math.exp(-p * period) - 1) / period] * n)
    return Phi, Gamma, np.linalg.solve(Phi, L)


@functools.lru_cache(maxsize=64)
def _designed(j_m: float, j_a: float, k: float, b_m: float, b_a: float, p: float, period: float, rigid: bool) -> tuple:
    """(A, b, c, Phi, Gamma, M) of one joint's model and observer, computed once per design (read-only arrays): a
    matrix exponential costs ~6 ms, and a diagnosis sets up thousands of simulations of the same controller."""
    A, b, c = rigid_model(j_m + j_a, b_m + b_a) if rigid else flexible_model(j_m, j_a, k, b_m, b_a)
    out = (A, b, c, *discrete_observer(A, b, c, p, period))
    for array in out:
        array.flags.writeable = False
    return out


class ObserverJoint:
    """The recursive observer-based controller of one joint (see module docstring).

    j_m, j_a (kg m^2), k (N m/rad), b_m, b_a (N m s/rad): the model (tables 5.1, 5.2);
    a (rad/s): error-dynamics poles at -a; p (rad/s): observer poles at -p; gamma: the
    recursion gain (default Ostojic's J_a J_m / k, or J for the rigid model); limit (N m):
    the torque range [-limit, limit]. After each call `estimate` holds the state estimate
    and `tau` the torque (N m). Raises ValueError for non-positive inertias, k, a or p.
    """

    def __init__(self, j_m: float, j_a: float, k: float, a: float, p: float, b_m: float = 0.0,
                 b_a: float = 0.0, gamma: float | None = None, limit: float = math.inf,
                 rigid: bool = False, period: float = CONTROL_PERIOD):
        for name, value in (("j_m", j_m), ("j_a", j_a), ("k", k), ("a", a), ("p", p)):
            if not value > 0:
                raise ValueError(f"observer: {name} must be > 0, got {value} (a, p are rates: poles at -a, -p)")
        self.j_m, self.j_a, self.k, self.b_m, self.b_a = float(j_m), float(j_a), float(k), float(b_m), float(b_a)
        self.a, self.p, self.rigid, self.limit, self.period = float(a), float(p), bool(rigid), float(limit), float(period)
        self.A, self.b, self.c, self.Phi, self.Gamma, self.M = _designed(self.j_m, self.j_a, self.k, self.b_m, self.b_a,
                                                                         self.p, self.period, self.rigid)
        self.gamma = float(gamma) if gamma is not None else (j_m + j_a if rigid else j_a * j_m / k)
        self._law = self.law()
        self.reset()

    def reset(self) -> None:
        self._predicted = None  # x^[n | n-1], floats
        self.estimate = np.zeros(self.A.shape[0])
        self.tau = 0.0

    def law(self) -> "_Law":
        """This joint's constants as `_Law` (floats): what `step` computes with."""
        jm, ja, k, bm, ba, a = self.j_m, self.j_a, self.k, self.b_m, self.b_a, self.a
        if self.rigid:  # sigma = a^2 (theta_d - th) - acc - 2 a w, acc = (tau - b w) / j
            sigma = (a * a, 2 * a, self.b_m + self.b_a, self.j_m + self.j_a)
        else:  # eq. 5.17's coefficients a0..a4
            sigma = (a**4, 4 * a**3 - 4 * a * k / ja + k * ba / ja**2, 6 * a**2 - 4 * a * ba / ja - k / ja + ba**2 / ja**2,
                     k / ja * (4 * a - ba / ja), k / ja)
        return _Law(self.rigid, sigma, (jm, ja, k, bm, ba), self.gamma, self.limit,
                    [[float(v) for v in row] for row in self.Phi], [float(v) for v in self.Gamma], [float(v) for v in self.M])

    def sigma(self, x, tau: float, theta_d: float) -> float:
        """Error dynamics sigma (rad/s^4 flexible, rad/s^2 rigid) of eq. 5.17 at state x, torque tau (N m)."""
        return self._law.sigma(list(x), tau, theta_d)

    def step(self, theta_m: float, theta_d: float) -> float:
        """One control period: encoder angle and desired angle (rad) -> torque (N m) for the next period."""
        law = self._law
        if self._predicted is None:  # start at rest at the first measurement
            self._predicted = law.at_rest(theta_m, 0.0)
        x, self.tau, self._predicted = law.step(self._predicted, self.tau, theta_m, theta_d, _clip)
        self.estimate = np.array(x)
        return self.tau

    def state(self) -> dict[str, float]:
        """The prediction the next step corrects (angles in rad, rates in rad/s) and the last torque (N m); {} before
        the first step (which starts at rest at its encoder reading)."""
        if self._predicted is None:
            return {}
        return {**dict(zip(self._state_names(), self._predicted)), "torque": self.tau}

    def _state_names(self) -> tuple[str, ...]:
        """The prediction's names, in its order (rad, rad/s)."""
        return ("theta", "rate") if self.rigid else ("theta_m", "theta_a", "rate_m", "rate_a")

    def set_state(self, values: Mapping[str, float]) -> None:
        """Set the state `state` names (every name of it; ValueError otherwise)."""
        names = self._state_names()
        if set(values) != {*names, "torque"}:
            raise ValueError(f"observer state needs {', '.join((*names, 'torque'))}, got {', '.join(values) or 'none'}")
        self._predicted, self.tau = [float(values[n]) for n in names], float(values["torque"])


def _clip(x: float, low: float, high: float) -> float:
    return min(max(x, low), high)


def _clip_columns(x: np.ndarray, low, high) -> np.ndarray:
    return np.minimum(np.maximum(x, low), high)


class _Law:
    """Eq. 5.15-5.20 of one joint, one period, on floats (ObserverJoint) or on arrays of shape (B,) with one
    member's constants in each place (ObserverColumns): the same operations in the same order, so the two give
    each member the same numbers bit for bit (Phi x written out as sums, never a BLAS product, whose order differs).
    `sigma_coefficients`: (a^2, 2a, b_m + b_a, j_m + j_a) rigid, eq. 5.17's (a0, a1, a2, a3, a4) flexible;
    `plant`: (j_m, j_a, k, b_m, b_a); Phi (rows), Gamma, M as lists."""

    def __init__(self, rigid, sigma_coefficients, plant, gamma, limit, phi, gamma_in, m):
        self.rigid, self.coefficients, self.plant = rigid, sigma_coefficients, plant
        self.gamma, self.limit, self.phi, self.gamma_in, self.m = gamma, limit, phi, gamma_in, m

    def at_rest(self, theta_m, zero):
        """The predicted state at rest at the first encoder angle (rad): angles theta_m, rates 0."""
        return [theta_m, zero] if self.rigid else [theta_m, theta_m, zero, zero]

    def sigma(self, x: list, tau, theta_d):
        if self.rigid:
            a2, two_a, b, j = self.coefficients
            th, w = x
            acc = (tau - b * w) / j
            return a2 * (theta_d - th) - acc - two_a * w
        tm, ta, wm, wa = x
        jm, ja, k, bm, ba = self.plant
        acc_m = (tau - bm * wm - k * (tm - ta)) / jm  # eq. 5.14
        acc_a = (k * (tm - ta) - ba * wa) / ja
        a0, a1, a2, a3, a4 = self.coefficients
        return a0 * theta_d - a4 * acc_m - a3 * wm - a2 * acc_a - a1 * wa - a0 * ta

    def step(self, predicted: list, tau, theta_m, theta_d, clip):
        """(estimate x[n|n], torque (N m) for the next period, prediction x[n+1|n]) from x[n|n-1], the last torque."""
        e = theta_m - predicted[0]
        x = [p + m * e for p, m in zip(predicted, self.m)]
        tau = clip(tau + self.gamma * self.sigma(x, tau, theta_d), -self.limit, self.limit)  # eq. 5.15
        ahead = []
        for row, g in zip(self.phi, self.gamma_in):
            total = row[0] * x[0]
            for r, v in zip(row[1:], x[1:]):
                total = total + r * v
            ahead.append(total + g * tau)
        return x, tau, ahead


class Observer:
    """Independent joint control (thesis 5.2.5): one ObserverJoint per joint in `joints`.

    Lists j_m, j_a, k, a, p, b_m, b_a (one value per joint; units as ObserverJoint) default to
    tables 5.1 (elbow) and 5.2 (shoulder); `rigid` selects the rigid-model controller;
    `limits` (N m) default to the rig's converter ranges. The desired angle of a joint is
    its `{joint}_reference` channel.
    """

    TABLES = {  # thesis tables 5.1 (elbow, link 2) and 5.2 (shoulder, link 1); a, p as rates
        "elbow": dict(j_m=1.25, j_a=3.5, k=200.0, b_m=0.0, b_a=0.0, a=10.0, p=30.0),
        "shoulder": dict(j_m=3.41, j_a=8.0, k=400.0, b_m=0.0, b_a=0.0, a=10.0, p=30.0),
    }

    def __init__(self, joints: Sequence[str] = ("elbow",), rigid: bool = False,
                 limits: Sequence[float] | None = None, period: float = CONTROL_PERIOD, **lists):
        unknown = set(lists) - {"j_m", "j_a", "k", "a", "p", "b_m", "b_a"}
        if unknown:
            raise ValueError(f"observer: unknown parameter(s) {', '.join(sorted(unknown))}")
        for name, values in lists.items():
            if len(values) != len(joints):
                raise ValueError(f"observer: '{name}' needs one value per joint ({len(joints)})")
        self.joints = list(joints)
        self.channels = [f"{j}_torque_cmd" for j in self.joints]
        self.units = []
        for i, j in enumerate(self.joints):
            if j not in self.TABLES:
                raise ValueError(f"observer: unknown joint {j!r} (known: {', '.join(self.TABLES)})")
            kw = dict(self.TABLES[j]) | {name: float(v[i]) for name, v in lists.items()}
            limit = limits[i] if limits is not None else getattr(WATFLEX, j).torque_limit
            self.units.append(ObserverJoint(**kw, limit=limit, rigid=rigid, period=period))
        self.reset()

    def reset(self) -> None:
        for u in self.units:
            u.reset()

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        return {ch: u.step(obs[f"{j}_angle"], obs[f"{j}_reference"])
                for j, ch, u in zip(self.joints, self.channels, self.units)}

    def state(self) -> dict[str, float]:
        """Each joint's ObserverJoint.state, its names prefixed `{joint}_`."""
        return {f"{j}_{name}": v for j, u in zip(self.joints, self.units) for name, v in u.state().items()}

    def set_state(self, values: Mapping[str, float]) -> None:
        """Set each joint's state from the values named `{joint}_...` (ValueError for a name of no joint)."""
        unknown = [n for n in values if not any(n.startswith(f"{j}_") for j in self.joints)]
        if unknown:
            raise ValueError(f"observer state: {', '.join(unknown)} name no joint of {', '.join(self.joints)}")
        for j, u in zip(self.joints, self.units):
            u.set_state({n.removeprefix(f"{j}_"): v for n, v in values.items() if n.startswith(f"{j}_")})

    @classmethod
    def columns(cls, members: list["Observer"], times: np.ndarray) -> "ObserverColumns | None":
        """The members' law on arrays (lockstep's columns), or None unless they share its form and have not run."""
        first = members[0]
        if any(type(m).__call__ is not Observer.__call__ or m.joints != first.joints
               or any(u.rigid != v.rigid or u._predicted is not None or u.tau != 0.0 for u, v in zip(m.units, first.units))
               for m in members):
            return None
        return ObserverColumns(members)


class ObserverColumns:
    """Observer of B members at once, on arrays of shape (B,): each joint's `_Law` with the members' constants
    as arrays, the same arithmetic, member by member."""

    def __init__(self, members: list[Observer]):
        first = members[0]
        self.joints, self.channels = first.joints, first.channels
        self.laws = [_stacked([m.units[i]._law for m in members]) for i in range(len(self.joints))]
        self.predicted = [None] * len(self.joints)
        self.tau = [np.zeros(len(members)) for _ in self.joints]  # N m

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for i, (j, channel, law) in enumerate(zip(self.joints, self.channels, self.laws)):
            theta = obs[f"{j}_angle"]
            if self.predicted[i] is None:
                self.predicted[i] = law.at_rest(theta, np.zeros(len(self.tau[i])))
            _, self.tau[i], self.predicted[i] = law.step(self.predicted[i], self.tau[i], theta, obs[f"{j}_reference"],
                                                         _clip_columns)
            out[channel] = self.tau[i]
        return out


def _stacked(laws: list[_Law]) -> _Law:
    """One `_Law` whose every constant is the array (B,) of the members' (same form: rigid or not)."""
    column = lambda values: np.array(values, dtype=float)  # noqa: E731
    first = laws[0]
    return _Law(first.rigid, tuple(column(v) for v in zip(*(law.coefficients for law in laws))),
                tuple(column(v) for v in zip(*(law.plant for law in laws))),
                column([law.gamma for law in laws]), column([law.limit for law in laws]),
                [[column([law.phi[r][c] for law in laws]) for c in range(len(first.phi))] for r in range(len(first.phi))],
                [column(v) for v in zip(*(law.gamma_in for law in laws))], [column(v) for v in zip(*(law.m for law in laws))])


def make_observer(friction_compensation: Mapping | None = None, **kwargs):
    """Scenario factory (`type = "observer"`): Observer(**kwargs), with a `friction_compensation`
    table applied to each controlled joint (passivity.compensated)."""
    controller = Observer(**kwargs)
    return compensated(controller, friction_compensation, controller.joints)
