"""Friction laws of thesis chapter 4 as pure functions of velocity (and their own state).

Convention: a law returns the friction torque F (N m) with the sign of the motion, as the
thesis writes it (F = F_C sgn(v)); the joint feels -F. Velocities in rad/s, angles in rad,
times in s. Direction-dependent laws take a `Friction` parameter set per direction
(params.Friction: alpha0, alpha1 in N m, alpha2 in N m s/rad, v_s in rad/s).
Scalar code: they run inside MuJoCo's per-step callbacks. The Stribeck level does its arithmetic as
numpy does on arrays (joint_friction.BatchFriction, the lockstep driver), so both drivers agree bit for bit.
"""
from __future__ import annotations

import math

import numpy as np

from .params import Friction


def stribeck_level(speed: float, p: Friction, delta: float = 2.0) -> float:
    """Sliding friction magnitude alpha0 + alpha1 exp(-(|v|/v_s)^delta) (N m) at speed |v| (rad/s).

    numpy's exp, and x * x for delta 2 (what numpy's `** 2.0` computes on an array): math.exp differs
    from numpy's in the last bit for ~5 % of arguments, a float's `** 2.0` from x * x for ~0.1 %."""
    x = speed / p.v_s
    return p.alpha0 + p.alpha1 * float(np.exp(-(x * x if delta == 2.0 else x**delta)))


def exponential(v: float, positive: Friction, negative: Friction, delta: float = 2.0) -> float:
    """Exponential model, thesis eq. 4.6 (delta = 2 in rigs.md), parameters per direction:
    F(v) = (alpha0 + alpha1 exp(-(|v|/v_s)^delta)) sgn(v) + alpha2 v; F(0) = 0."""
    if v > 0:
        return stribeck_level(v, positive, delta) + positive.alpha2 * v
    if v < 0:
        return -stribeck_level(-v, negative, delta) + negative.alpha2 * v
    return 0.0


def lugre_step(v: float, z: float, dt: float, sigma0: float, sigma1: float,
               positive: Friction, negative: Friction, delta: float = 2.0) -> tuple[float, float]:
    """LuGre model, thesis eq. 4.20, advanced by dt at constant v: returns (F in N m, new z in rad).

    dz/dt = v - sigma0 |v| z / g(v), g(v) = alpha0 + alpha1 exp(-(v/v_s)^delta) (per direction),
    F = sigma0 z + sigma1 dz/dt + alpha2 v. z is integrated exactly for constant v
    (z -> z_ss + (z - z_ss) exp(-sigma0 |v| dt / g)), so stiff bristles stay stable.
    sigma0 in N m/rad, sigma1 in N m s/rad.
    """
    p = positive if v >= 0 else negative
    g = stribeck_level(abs(v), p, delta)
    if g <= 0.0:  # no dry friction: no bristles to deflect
        return p.alpha2 * v, 0.0
    rate = sigma0 * abs(v) / g  # 1/s
    if rate * dt > 1e-12:
        z_ss = g / sigma0 * (1.0 if v > 0 else -1.0)
        z_new = z_ss + (z - z_ss) * math.exp(-rate * dt)
        dz = (z_new - z) / dt
    else:
        z_new, dz = z + v * dt, v
    return sigma0 * z_new + sigma1 * dz + p.alpha2 * v, z_new


def _sgn(x: float) -> float:
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


def coulomb(v: float, fc_pos: float, fc_neg: float | None = None) -> float:
    """Coulomb friction, thesis eq. 4.1: F = F_C sgn(v) (N m), F(0) = 0.

    fc_pos is the level (N m) for v > 0, fc_neg the magnitude (N m, >= 0) for v < 0
    (defaults to fc_pos); v in rad/s.
    """
    if v > 0:
        return fc_pos
    if v < 0:
        return -(fc_pos if fc_neg is None else fc_neg)
    return 0.0


def viscous(v: float, fv: float) -> float:
    """Viscous friction, the F_v v term of thesis eq. 4.2 (N m); fv in N m s/rad, v in rad/s."""
    return fv * v


def classical(v: float, f_ext: float, fc: float, fv: float, fs: float) -> float:
    """Classical model, thesis eq. 4.2 with stiction eq. 4.4 (the eq. 4.5 form), in N m.

    Sliding (v != 0): F = fc sgn(v) + fv v. At rest (v == 0): F = f_ext if |f_ext| < fs,
    else fs sgn(f_ext), i.e. the external torque f_ext (N m) saturated at the static level fs.
    fc, fs in N m, fv in N m s/rad, v in rad/s.
    """
    if v != 0:
        return fc * _sgn(v) + fv * v
    return f_ext if abs(f_ext) < fs else fs * _sgn(f_ext)


def slope_limited(v: float, positive: Friction, negative: Friction, k_s: float = 300.0,
                  delta: float = 2.0) -> float:
    """Exponential map with a finite slope at zero, thesis eq. 4.6 times eq. 4.24 (N m):
    F(v) (1 - exp(-|v| k_s)) on each side, k_s in s/rad (300 in rigs.md §2 and section 4.5.5).

    Continuous through F(0) = 0 with slope (alpha0 + alpha1) k_s of the side. rigs.md §2: this
    belongs to the compensation map of section 4.5.5, not to the plant (a plant friction
    through zero creeps under any torque).
    """
    return exponential(v, positive, negative, delta) * (1.0 - math.exp(-abs(v) * k_s))


def slope_limited_columns(v: np.ndarray, positive: dict[str, np.ndarray], negative: dict[str, np.ndarray],
                          k_s: np.ndarray) -> np.ndarray:
    """`slope_limited` (delta 2) on arrays (B,), each member's parameters in its place (`positive`, `negative`:
    Friction's fields as arrays): the same operations in the same order and math.exp where it calls that, so
    each member gets the scalar code's number bit for bit."""
    up = v > 0
    p = {name: np.where(up, positive[name], negative[name]) for name in ("alpha0", "alpha1", "alpha2", "v_s")}
    x = np.abs(v) / p["v_s"]
    level = p["alpha0"] + p["alpha1"] * np.exp(-(x * x))
    force = np.where(up, level + p["alpha2"] * v, np.where(v < 0, -level + p["alpha2"] * v, 0.0))
    return force * (1.0 - np.array([math.exp(u) for u in (-np.abs(v) * k_s).tolist()]))


def karnopp(v: float, f_ext: float, dv: float, positive: Friction, negative: Friction,
            delta: float = 2.0) -> float:
    """Karnopp model (thesis 4.3.1), in N m: inside the zero-velocity band |v| < dv (rad/s) the
    friction is the external torque f_ext (N m) saturated at the break-away alpha0 + alpha1 of
    the direction f_ext pushes (eq. 4.4); outside it, the exponential map eq. 4.6.
    """
    if abs(v) < dv:
        p = positive if f_ext >= 0 else negative
        level = p.alpha0 + p.alpha1
        return max(-level, min(level, f_ext))
    return exponential(v, positive, negative, delta)


def dahl_step(v: float, F: float, dt: float, sigma: float, fc: float, alpha: float = 1.0) -> float:
    """Dahl model, thesis eq. 4.7 (eq. 4.8 for alpha = 1), advanced by dt (s) at constant v:
    dF/dx = sigma |1 - F sgn(v)/fc|^alpha sgn(1 - F sgn(v)/fc); returns the new F (N m).

    Integrated exactly in the displacement |dx| = |v| dt: w = 1 - F sgn(v)/fc obeys
    dw/dy = -|w|^alpha sgn(w), y = sigma |x| / fc, so for alpha = 1 F approaches fc sgn(v)
    as exp(-sigma |x| / fc) and |F| never exceeds fc if it started inside.
    sigma in N m/rad, fc in N m, v in rad/s; alpha > 0 dimensionless.
    """
    if v == 0 or dt <= 0:
        return F
    s = 1.0 if v > 0 else -1.0
    w = 1.0 - s * F / fc
    y = sigma * abs(v) * dt / fc
    if alpha == 1.0:
        w_new = w * math.exp(-y)
    else:
        m = abs(w)
        if m > 0 and alpha > 1.0:
            m = (m ** (1.0 - alpha) + (alpha - 1.0) * y) ** (-1.0 / (alpha - 1.0))
        elif m > 0:
            m = max(m ** (1.0 - alpha) - (1.0 - alpha) * y, 0.0) ** (1.0 / (1.0 - alpha))
        w_new = math.copysign(m, w)
    return s * fc * (1.0 - w_new)


def bliman_sorine1_step(v: float, F: float, dt: float, f1: float, eps_f: float) -> float:
    """First-order Bliman/Sorine model, thesis eq. 4.11-4.13, advanced by dt (s); returns new F.

    In the space variable s (eq. 4.10, ds = |v| dt, rad): dF/ds = (f1 sgn(v) - F) / eps_f,
    solved exactly for constant sgn(v). f1 in N m, eps_f in rad. With f1 = F_C and
    eps_f = f1 / sigma it is the Dahl model with alpha = 1 (remark after eq. 4.13).
    """
    if v == 0 or dt <= 0:
        return F
    target = f1 * _sgn(v)
    return target + (F - target) * math.exp(-abs(v) * dt / eps_f)


def bliman_sorine2_step(v: float, x: tuple[float, float], dt: float, f1: float, f2: float,
                        eps_f: float, eta: float) -> tuple[float, tuple[float, float]]:
    """Second-order Bliman/Sorine model, thesis eq. 4.14, advanced by dt (s): returns (F, x_new).

    dx/ds = A x + B sgn(v), A = diag(-1/(eta eps_f), -1/eps_f), B = (f1/(eta eps_f), -f2/eps_f),
    F = x1 + x2 (N m): a fast Dahl-like state (length eta eps_f, towards f1 sgn v) and a slow one
    (length eps_f, towards -f2 sgn v), solved exactly in s (ds = |v| dt). Steady state
    (f1 - f2) sgn(v); from rest F peaks near f1 first (stiction peak, eta < 1).
    f1, f2 in N m; eps_f in rad; eta dimensionless; x in N m.
    """
    x1, x2 = x
    if v != 0 and dt > 0:
        s, ds = _sgn(v), abs(v) * dt
        x1 = f1 * s + (x1 - f1 * s) * math.exp(-ds / (eta * eps_f))
        x2 = -f2 * s + (x2 + f2 * s) * math.exp(-ds / eps_f)
    return x1 + x2, (x1, x2)


def dwell_breakaway(rest_time: float, breakaway: float, gain: float, time_constant: float) -> float:
    """Break-away torque after a dwell (thesis 4.1.6, fig. 4.5), in N m:
    breakaway (1 + gain (1 - exp(-rest_time / time_constant))); times in s. Same formula as
    joint_friction.JointFriction.breakaway.
    """
    return breakaway * (1.0 + gain * (1.0 - math.exp(-rest_time / time_constant)))


def position_torque(q: float, amplitude: float, period: float, phase: float = 0.0,
                    spring: float = 0.0) -> float:
    """Position-dependent torque (cable drag, ripple; thesis 4.5.1), in N m:
    amplitude sin(2 pi q / period + phase) + spring q, q and period and phase in rad,
    amplitude in N m, spring in N m/rad. The joint feels minus this (as joint_friction.py)."""
    return amplitude * math.sin(2.0 * math.pi * q / period + phase) + spring * q


def steady_state_map(v: float, positive: Friction, negative: Friction, delta: float = 2.0) -> float:
    """Steady-state friction of the LuGre model, thesis eq. 4.21 (N m), v in rad/s:
    tau_ss = (alpha0 + alpha1 exp(-(v/v_S)^delta)) sgn(v) + alpha2 v, per direction.
    Identical to the exponential model eq. 4.6 (the thesis' remark after eq. 4.21)."""
    return exponential(v, positive, negative, delta)
