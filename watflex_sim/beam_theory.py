"""Closed forms of Euler-Bernoulli beam theory that the models are checked against."""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq


def _frequencies(beam, f, n_modes: int) -> np.ndarray:
    """The first `n_modes` roots lambda of the frequency equation f(lambda, lib) = 0 (lib: math for a
    number, numpy for the grid the roots are bracketed on), as natural frequencies
    omega = lambda^2 sqrt(EI / (rho L^4)) (rad/s)."""
    roots, grid = [], np.linspace(1e-3, 4 * (n_modes + 1), 4000 * (n_modes + 1))
    values = f(grid, np)
    for k in np.flatnonzero(values[:-1] * values[1:] < 0)[:n_modes]:
        roots.append(brentq(f, grid[k], grid[k + 1], args=(math,), xtol=1e-14))
    lam = np.array(roots)
    return lam**2 * math.sqrt(beam.EI / (beam.mass_per_length * beam.length**4))


def clamped_free_frequencies(beam, tip_mass: float, n_modes: int = 3, tip_offset: float = 0.0) -> np.ndarray:
    """First `n_modes` natural frequencies (rad/s) of a clamped-free beam with a point mass `tip_mass` (kg) on a rigid
    arm `tip_offset` (m) beyond its free end (0: at the end).

    Frequency equation at the end (e.g. Blevins, *Formulas for natural frequency and mode shape*, table 8-1;
    Laura et al. 1974): 1 + cos(l) cosh(l) + mu l (cos(l) sinh(l) - sin(l) cosh(l)) = 0 with
    mu = m_tip / (rho L), and omega = l^2 sqrt(EI / (rho L^4)). Rotary inertia of the tip mass
    is neglected. On an arm, the end's conditions from Hamilton's principle with W = w(L) + c w'(L) the mass's
    deflection: EI w'''(L) = -m omega^2 W, EI w''(L) = m omega^2 c W; with w = A (cos - cosh) + B (sin - sinh) of
    beta x (clamped root), their 2 x 2 determinant in (A, B) vanishes.
    """
    mu = tip_mass / (beam.mass_per_length * beam.length)
    gamma = tip_offset / beam.length

    def at_end(lam, lib):
        c, s, ch, sh = lib.cos(lam), lib.sin(lam), lib.cosh(lam), lib.sinh(lam)
        # divided by cosh to keep the function O(1) for large lambda
        return (1.0 + c * ch + mu * lam * (c * sh - s * ch)) / ch

    def on_arm(lam, lib):
        c, s, ch, sh = lib.cos(lam), lib.sin(lam), lib.cosh(lam), lib.sinh(lam)
        rows = []
        for u, du, ddu, dddu in ((c - ch, -s - sh, -c - ch, s - sh), (s - sh, c - ch, -s - sh, -c - ch)):
            mass = u + gamma * lam * du  # W over the amplitude
            rows.append((dddu + lam * mu * mass, ddu - lam**2 * mu * gamma * mass))
        (a1, b1), (a2, b2) = rows
        return (a1 * b2 - a2 * b1) / ch**2

    return _frequencies(beam, on_arm if tip_offset else at_end, n_modes)


def tip_deflection(beam, force: float) -> float:
    """Static tip deflection (m) of a clamped-free beam under a tip force (N): F L^3 / (3 EI)."""
    return force * beam.length**3 / (3.0 * beam.EI)


def gauge_strain(beam, x_gauge: float, tip_deflection_m: float) -> float:
    """Surface strain at `x_gauge` (m from the root) for a tip deflection (m), thesis eq. 3.3.

    eps = 3 t / (2 l^3) (x_s - l) w: negative on the side that is stretched when the beam
    bends towards positive w (rigs.md: eps = -(t/2) w'').
    """
    t, L = beam.thickness, beam.length
    return 3.0 * t / (2.0 * L**3) * (x_gauge - L) * tip_deflection_m


def clamped_tip_body_frequencies(beam, mass: float, offset: float, n_modes: int = 3) -> np.ndarray:
    """First `n_modes` natural frequencies (rad/s) of a clamped beam whose free end carries a rigid,
    massless extension of length `offset` (m) with a point mass `mass` (kg) at its end.

    Euler-Bernoulli, w = A (cos bx - cosh bx) + B (sin bx - sinh bx) (clamped root); the mass moves
    u = w(L) + e w'(L), so Hamilton's principle gives at x = L: EI w''' = -m w^2 u (shear) and
    EI w'' = m w^2 e u (moment of the inertia force about the beam end): Blevins' tip-mass case
    (*Formulas for natural frequency and mode shape*, table 8-1) with the mass offset. In lambda = bL,
    mu = m / (rho L), eps = e / L: det [[L^2 w'' - mu eps lambda^4 u], [L^3 w''' + mu lambda^4 u]] = 0.
    `offset` = 0 is clamped_free_frequencies' equation. Rotary inertia of the mass itself is neglected.
    """
    mu, eps = mass / (beam.mass_per_length * beam.length), offset / beam.length

    def f(lam, lib):
        c, s, ch, sh = lib.cos(lam), lib.sin(lam), lib.cosh(lam), lib.sinh(lam)
        # columns: coefficients of A and B in w, L w', L^2 w'', L^3 w''' at x = L
        w = (c - ch, s - sh)
        w1 = (lam * (-s - sh), lam * (c - ch))
        w2 = (lam**2 * (-c - ch), lam**2 * (-s - sh))
        w3 = (lam**3 * (s - sh), lam**3 * (-c - ch))
        u = [w[i] + eps * w1[i] for i in range(2)]
        row1 = [w2[i] - mu * eps * lam**4 * u[i] for i in range(2)]
        row2 = [w3[i] + mu * lam**4 * u[i] for i in range(2)]
        return (row1[0] * row2[1] - row1[1] * row2[0]) / (ch * ch * (1.0 + mu * lam**4))  # kept O(1)

    return _frequencies(beam, f, n_modes)
