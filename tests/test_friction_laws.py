"""Friction laws of thesis chapter 4 (watflex_sim.friction) against their closed forms.

Numbers: rigs.md §2 friction table (= thesis table 4.3 shoulder, table A.2 elbow).
"""
import math

import numpy as np
import pytest

from watflex_sim.friction import (
    bliman_sorine1_step, bliman_sorine2_step, classical, coulomb, dahl_step, dwell_breakaway,
    exponential, karnopp, lugre_step, position_torque, slope_limited, steady_state_map, viscous,
)
from watflex_sim.joint_friction import JointFriction
from watflex_sim.params import WATFLEX

S_POS, S_NEG = WATFLEX.shoulder_friction
E_POS, E_NEG = WATFLEX.elbow_friction


def test_coulomb_and_viscous_values():
    """Eq. 4.1: F = F_C sgn(v), F(0) = 0, a magnitude per direction; eq. 4.2's F_v v."""
    assert coulomb(0.3, 4.0) == 4.0 and coulomb(-0.3, 4.0) == -4.0 and coulomb(0.0, 4.0) == 0.0
    assert coulomb(-1e-9, 4.0, 5.0) == -5.0 and coulomb(1e-9, 4.0, 5.0) == 4.0
    assert viscous(-0.2, 1.5) == pytest.approx(-0.3, rel=1e-15)


@pytest.mark.parametrize("v0, fc_pos, fc_neg", [(0.3, E_POS.alpha0, E_NEG.alpha0), (-0.3, E_POS.alpha0, E_NEG.alpha0)])
def test_coulomb_stopping_distance(v0, fc_pos, fc_neg):
    """J dv/dt = -F_C sgn(v) from v0 stops after theta = J v0^2 / (2 F_C) at t = J |v0| / F_C."""
    J, dt = WATFLEX.elbow.inertia, 1e-5  # kg m^2, s
    v, theta, t = v0, 0.0, 0.0
    while v != 0.0:
        v_new = v - coulomb(v, fc_pos, fc_neg) / J * dt
        if v_new * v <= 0:  # the sign would flip: friction stops the joint within this step
            theta += v * dt / 2  # to first order, the step's remaining travel
            v_new = 0.0
        else:
            theta += v_new * dt
        v, t = v_new, t + dt
    fc = fc_pos if v0 > 0 else fc_neg
    assert theta == pytest.approx(math.copysign(J * v0**2 / (2 * fc), v0), rel=1e-3)  # 0.01134 / -0.01034 rad
    assert t == pytest.approx(J * abs(v0) / fc, rel=1e-3)


def test_classical_at_rest_saturates_the_external_torque():
    """Eq. 4.4/4.5: at v = 0 F = F_e below F_S, F_S sgn(F_e) beyond; sliding: eq. 4.2."""
    assert classical(0.0, 3.0, fc=5.0, fv=1.0, fs=6.0) == 3.0
    assert classical(0.0, 7.0, fc=5.0, fv=1.0, fs=6.0) == 6.0
    assert classical(0.0, -7.0, fc=5.0, fv=1.0, fs=6.0) == -6.0
    assert classical(-0.1, 3.0, fc=5.0, fv=1.0, fs=6.0) == pytest.approx(-5.1, rel=1e-15)


def test_karnopp_band_and_outside():
    """Karnopp (thesis 4.3.1): inside |v| < DV F_e saturated at alpha0 + alpha1 of the push
    direction (elbow: 5.4821 / 5.9948 N m); outside the exponential map."""
    assert karnopp(0.005, 10.0, 0.01, E_POS, E_NEG) == pytest.approx(4.9589 + 0.5232, rel=1e-12)
    assert karnopp(-0.005, -10.0, 0.01, E_POS, E_NEG) == pytest.approx(-(5.4392 + 0.5556), rel=1e-12)
    assert karnopp(0.0, 2.0, 0.01, E_POS, E_NEG) == 2.0
    assert karnopp(0.05, -10.0, 0.01, E_POS, E_NEG) == exponential(0.05, E_POS, E_NEG)


def test_exponential_is_asymmetric_with_table_4_3():
    """Eq. 4.6, shoulder, by hand: F(+0.1) = 7.9707 + 1.4476 e^-(0.1/0.0363)^2 + 0.49349
    = 8.464922 N m; F(-0.1) = -(7.7538 + 0.8626 e^-(0.1/0.0221)^2) - 0.43267 = -8.186470 N m."""
    assert exponential(0.1, S_POS, S_NEG) == pytest.approx(8.464922, abs=1e-6)
    assert exponential(-0.1, S_POS, S_NEG) == pytest.approx(-8.186470, abs=1e-6)
    assert exponential(0.0, S_POS, S_NEG) == 0.0
    assert steady_state_map(0.1, S_POS, S_NEG) == exponential(0.1, S_POS, S_NEG)  # eq. 4.21 = eq. 4.6


@pytest.mark.parametrize("v", [-0.5, -0.1, -0.02, -0.001, 0.001, 0.02, 0.1, 0.5])
def test_lugre_steady_state_is_eq_4_21(v):
    """LuGre (eq. 4.20) at constant v settles (dz/dt = 0) on tau_ss of eq. 4.21, within 1e-6."""
    z, g = 0.0, S_POS.alpha0 + S_POS.alpha1
    dt = 0.5 * g / (259.0 * abs(v))  # half a bristle time constant per step (exact integration)
    for _ in range(200):
        F, z = lugre_step(v, z, dt, 259.0, 10.0, S_POS, S_NEG)
    assert F == pytest.approx(steady_state_map(v, S_POS, S_NEG), rel=1e-6)


def sinusoid_run(step, state, amplitude=2e-3, cycles=3, n=6000):
    """Drive a law by x = A sin(2 pi t), t in s; return arrays x (rad), F (N m)."""
    dt = cycles / n
    xs, fs = np.empty(n), np.empty(n)
    for k in range(n):
        t = (k + 0.5) * dt
        v = amplitude * 2 * math.pi * math.cos(2 * math.pi * t)  # midpoint speed of the step
        state = step(v, state, dt)
        xs[k], fs[k] = amplitude * math.sin(2 * math.pi * (k + 1) * dt), state
    return xs, fs


def test_dahl_and_bliman_sorine1_hysteresis_bounded_and_equal():
    """Dahl (eq. 4.8) never exceeds F_C from inside; BS1 with f1 = F_C, eps_f = f1/sigma is the
    same model (remark after eq. 4.13); the loop is a hysteresis: F at x = 0 differs by direction."""
    fc, sigma = 5.0, 1e4  # N m, N m/rad: sigma A / fc = 4, the loop nearly saturates
    x, fd = sinusoid_run(lambda v, F, dt: dahl_step(v, F, dt, sigma, fc), 0.0)
    _, fb = sinusoid_run(lambda v, F, dt: bliman_sorine1_step(v, F, dt, fc, fc / sigma), 0.0)
    assert np.abs(fd).max() <= fc and np.abs(fd).max() > 0.95 * fc
    assert np.abs(fb).max() <= fc
    np.testing.assert_allclose(fb, fd, rtol=0, atol=1e-12)
    # periodic loop (alpha = 1): branch F(x) = +-[fc - (fc + Fm) e^(-sigma (A +- x) / fc)] with peak
    # Fm = fc (1 - e^-8) / (1 + e^-8); at x = 0 (t = 2 s up, 2.5 s down): +-[fc - (fc + Fm) e^-4]
    fm = fc * (1 - math.exp(-8)) / (1 + math.exp(-8))
    f0 = fc - (fc + fm) * math.exp(-4)  # 4.817 N m
    up, down = 3999, 4999  # x[k] = A sin(2 pi (k + 1) dt), dt = 0.5 ms
    assert abs(x[up]) < 1e-15 and abs(x[down]) < 1e-15
    assert fd[up] == pytest.approx(f0, rel=1e-5) and fd[down] == pytest.approx(-f0, rel=1e-5)
    assert np.abs(fd[4000:]).max() == pytest.approx(fm, rel=1e-5)


@pytest.mark.parametrize("alpha, closed_form", [
    (1.0, lambda y: 1 - math.exp(-y)),  # F/F_C = 1 - e^-y
    (2.0, lambda y: y / (1 + y)),  # w = 1/(1 + y)
    (0.5, lambda y: 1 - max(1 - y / 2, 0.0) ** 2),  # w = (1 - y/2)^2, F = F_C from y = 2 on
])
def test_dahl_from_rest_follows_the_displacement_closed_form(alpha, closed_form):
    """Eq. 4.7 from F = 0: dw/dy = -w^alpha, y = sigma x / F_C; rate independent (any step split)."""
    fc, sigma = 5.0, 1e4
    for x in (1e-4, 5e-4, 2e-3):
        y = sigma * x / fc
        one = dahl_step(0.01, 0.0, x / 0.01, sigma, fc, alpha)
        F = 0.0
        for _ in range(100):
            F = dahl_step(0.3, F, x / 0.3 / 100, sigma, fc, alpha)  # 100 steps, 30x the speed
        assert one == pytest.approx(fc * closed_form(y), rel=1e-9, abs=1e-12)
        assert F == pytest.approx(one, rel=1e-9, abs=1e-12)
        assert dahl_step(-0.01, 0.0, x / 0.01, sigma, fc, alpha) == pytest.approx(-one, rel=1e-12)


@pytest.mark.parametrize("direction", [+1, -1])
def test_bliman_sorine2_stiction_peak_from_rest(direction):
    """Eq. 4.14 from rest: F(s) = f1 (1 - e^-s/(eta eps)) - f2 (1 - e^-s/eps) peaks at
    s* = eps ln(f1/(f2 eta)) / (1/eta - 1) = 0.385 mrad with F* = 7.0309 N m, above the steady
    state f1 - f2 = 5.5 N m."""
    f1, f2, eps, eta = 8.0, 2.5, 1e-3, 0.1
    v, dt, x = direction * 0.01, 1e-4, (0.0, 0.0)  # ds = 1e-6 rad per step
    forces = []
    for _ in range(20000):  # s = 0.02 rad = 20 eps
        F, x = bliman_sorine2_step(v, x, dt, f1, f2, eps, eta)
        forces.append(F)
    forces = np.array(forces) * direction
    s_peak = eps * math.log(f1 / (f2 * eta)) / (1 / eta - 1)
    f_peak = f1 * (1 - math.exp(-s_peak / (eta * eps))) - f2 * (1 - math.exp(-s_peak / eps))
    assert forces.max() == pytest.approx(f_peak, rel=1e-6)
    assert (forces.argmax() + 1) * 1e-6 == pytest.approx(s_peak, abs=1e-6)
    assert forces[-1] == pytest.approx(f1 - f2, rel=1e-6)
    assert forces.max() - forces[-1] > 1.5


def test_slope_limited_map_limits():
    """Eq. 4.6 x eq. 4.24: = exponential once k_S |v| >> 1; -> 0 at v -> 0 with slope
    (alpha0 + alpha1) k_S per side (elbow: 5.4821 x 300 = 1644.6 and 5.9948 x 300 N m s/rad)."""
    for v in (0.2, -0.2, 0.5):  # k_S |v| >= 60
        assert slope_limited(v, E_POS, E_NEG) == pytest.approx(exponential(v, E_POS, E_NEG), rel=1e-15)
    assert slope_limited(0.0, E_POS, E_NEG) == 0.0
    h = 1e-8
    assert slope_limited(h, E_POS, E_NEG) / h == pytest.approx((E_POS.alpha0 + E_POS.alpha1) * 300.0, rel=1e-5)
    assert slope_limited(-h, E_POS, E_NEG) / -h == pytest.approx((E_NEG.alpha0 + E_NEG.alpha1) * 300.0, rel=1e-5)
    # k_S |v| = 1: the map is (1 - 1/e) of the exponential
    assert slope_limited(1 / 300, E_POS, E_NEG) == pytest.approx((1 - math.exp(-1)) * exponential(1 / 300, E_POS, E_NEG), rel=1e-12)


def test_dwell_breakaway_limits_match_joint_friction():
    """Thesis 4.1.6 / fig. 4.5: t = 0 -> break-away, t >> tau -> (1 + gain) break-away."""
    b, gain, tau = 5.4821, 1.0, 2.0
    assert dwell_breakaway(0.0, b, gain, tau) == b
    assert dwell_breakaway(100 * tau, b, gain, tau) == pytest.approx(2 * b, rel=1e-15)
    assert dwell_breakaway(tau, b, gain, tau) == pytest.approx(b * (2 - math.exp(-1)), rel=1e-15)
    law = JointFriction(E_POS, E_NEG, dwell_gain=gain, dwell_time=tau)
    b_pos = E_POS.alpha0 + E_POS.alpha1
    assert dwell_breakaway(3.0, b_pos, gain, tau) == pytest.approx(law.breakaway(+1, 3.0), rel=1e-15)


def test_position_torque_at_known_angles():
    """a sin(2 pi q / P + phase) + k q: peaks at q = P/4, zero at P/2, phase pi/6 gives a/2 at 0."""
    a, P = 0.3, 0.5
    assert position_torque(P / 4, a, P) == pytest.approx(0.3, rel=1e-15)
    assert position_torque(P / 2, a, P) == pytest.approx(0.0, abs=1e-15)
    assert position_torque(0.0, a, P, phase=math.pi / 6) == pytest.approx(0.15, rel=1e-14)
    assert position_torque(3 * P / 4, a, P, spring=2.0) == pytest.approx(-0.3 + 0.75, rel=1e-14)
