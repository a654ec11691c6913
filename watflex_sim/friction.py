"""Friction laws of thesis chapter 4 as pure functions of velocity (and their own state).

Convention: a law returns the friction torque F (N m) with the sign of the motion, as the
thesis writes it (F = F_C sgn(v)); the joint feels -F. Velocities in rad/s, angles in rad,
times in s. Direction-dependent laws take a `Friction` parameter set per direction
(params.Friction: alpha0, alpha1 in N m, alpha2 in N m s/rad, v_s in rad/s).
Written with `math`, not numpy: they run inside MuJoCo's per-step callbacks.
"""
from __future__ import annotations

import math

from .params import Friction


def stribeck_level(speed: float, p: Friction, delta: float = 2.0) -> float:
    """Sliding friction magnitude alpha0 + alpha1 exp(-(|v|/v_s)^delta) (N m) at speed |v| (rad/s)."""
    return p.alpha0 + p.alpha1 * math.exp(-((speed / p.v_s) ** delta))


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
    rate = sigma0 * abs(v) / g  # 1/s
    if rate * dt > 1e-12:
        z_ss = g / sigma0 * (1.0 if v > 0 else -1.0)
        z_new = z_ss + (z - z_ss) * math.exp(-rate * dt)
        dz = (z_new - z) / dt
    else:
        z_new, dz = z + v * dt, v
    return sigma0 * z_new + sigma1 * dz + p.alpha2 * v, z_new
