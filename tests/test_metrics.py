"""watflex_sim.metrics against closed forms: step_metrics, nrmse, correlation."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from watflex_sim.metrics import correlation, nrmse, step_metrics

DT = 1e-5  # s, sample spacing of the test signals


def second_order(t, zeta, wn):
    """Unit step response of wn^2 / (s^2 + 2 zeta wn s + wn^2), 0 < zeta < 1, t >= 0 (s)."""
    wd = wn * math.sqrt(1 - zeta**2)
    return 1 - np.exp(-zeta * wn * t) / math.sqrt(1 - zeta**2) * np.sin(wd * t + math.acos(zeta))


def second_order_truth(zeta, wn, band=0.02):
    """Overshoot (%) by the closed form; 10-90 % rise and band settling time (s) as roots of
    the closed form. The extrema are at t_k = k pi / wd with |y - 1| = exp(-zeta wn t_k), so
    the response leaves the band for the last time between the last extremum outside it and
    the next one."""
    wd = wn * math.sqrt(1 - zeta**2)
    t_peak = math.pi / wd
    overshoot = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    rise = (brentq(lambda t: second_order(t, zeta, wn) - 0.9, 0, t_peak, xtol=1e-14)
            - brentq(lambda t: second_order(t, zeta, wn) - 0.1, 0, t_peak, xtol=1e-14))
    k = math.floor(math.log(1 / band) / (zeta * wn) / t_peak)  # last k with exp(-zeta wn t_k) > band
    sign = 1.0 if k % 2 else -1.0  # odd extrema overshoot
    settling = brentq(lambda t: sign * (second_order(t, zeta, wn) - 1) - band, k * t_peak, (k + 1) * t_peak, xtol=1e-14)
    return rise, settling, overshoot


@pytest.mark.parametrize("zeta, wn", [(0.2, 30.0), (0.5, 27.6), (0.7, 10.0)])
@pytest.mark.parametrize("initial, final", [(0.0, 1.0), (2.0, -0.5)])
def test_step_metrics_second_order(zeta, wn, initial, final):
    """Rise, settling and overshoot of a sampled second-order step of either sign, started at
    t_step, within one sample of the closed form."""
    t_step = 0.1
    t = np.arange(0.0, t_step + 20.0 / (zeta * wn), DT)  # tail envelope e^-20 at the end
    y = initial + (final - initial) * np.where(t >= t_step, second_order(np.maximum(t - t_step, 0), zeta, wn), 0.0)
    rise, settling, overshoot = second_order_truth(zeta, wn)
    m = step_metrics(t, y, t_step=t_step, initial=initial, final=final)
    assert m["rise_time_s"] == pytest.approx(rise, abs=2 * DT)
    assert m["settling_time_s"] == pytest.approx(settling, abs=2 * DT)
    assert m["overshoot_pct"] == pytest.approx(overshoot, abs=1e-6)
    assert m["steady_state_error"] == pytest.approx(0.0, abs=1e-6 * abs(final - initial))


def test_overshoot_formula_at_a_textbook_point():
    """zeta = 0.5: 16.3 % overshoot (exp(-pi/sqrt(3)))."""
    assert second_order_truth(0.5, 1.0)[2] == pytest.approx(16.303, abs=1e-3)


def test_step_metrics_first_order():
    """y = 1 - exp(-t/tau): rise tau ln 9, settling (2 %) tau ln 50, no overshoot; an offset
    of the tail is the steady-state error."""
    tau, t = 0.05, np.arange(0.0, 1.0, DT)
    m = step_metrics(t, 1 - np.exp(-t / tau), t_step=0.0, initial=0.0, final=1.0)
    assert m["rise_time_s"] == pytest.approx(tau * math.log(9), abs=2 * DT)
    assert m["settling_time_s"] == pytest.approx(tau * math.log(50), abs=2 * DT)
    assert m["overshoot_pct"] == 0.0
    m = step_metrics(t, 0.97 * (1 - np.exp(-t / tau)), t_step=0.0, initial=0.0, final=1.0)
    assert m["steady_state_error"] == pytest.approx(0.03, abs=1e-7)  # tail mean over 0.9-1 s: 0.97 e^-18 left
    assert np.isnan(m["settling_time_s"])  # ends outside the 2 % band


def test_step_metrics_never_reaching_a_level_is_nan():
    t = np.linspace(0, 1, 1001)
    m = step_metrics(t, 0.5 * t, t_step=0.0, initial=0.0, final=1.0)  # reaches 50 % only
    assert np.isnan(m["rise_time_s"]) and np.isnan(m["settling_time_s"])


def test_nrmse_known_cases():
    t = np.linspace(0, 1, 10001)[:-1]  # whole periods
    m = np.sin(2 * np.pi * 5 * t)
    assert nrmse(m, m) == 0.0
    assert nrmse(m, m + 0.1) == pytest.approx(0.1 * math.sqrt(2), rel=1e-9)  # RMS(sin) = 1/sqrt(2)
    assert nrmse(m, np.zeros_like(m)) == pytest.approx(1.0, rel=1e-9)  # predicting the mean: 1
    s = m + 0.1
    s[::7] = np.nan  # NaN samples ignored
    m2 = m.copy()
    m2[3] = np.nan
    ok = np.isfinite(s) & np.isfinite(m2)
    expect = np.sqrt(np.mean((m[ok] - s[ok]) ** 2)) / np.std(m[ok])
    assert nrmse(m2, s) == pytest.approx(expect, rel=1e-12)
    assert np.isnan(nrmse(np.ones(10), np.zeros(10)))  # no spread
    # constant to within rounding: np.full(7, 0.1)'s spread computes as 1.4e-17, which made an NRMSE of ~1e15
    assert np.isnan(nrmse(np.full(7, 0.1), np.zeros(7)))


def test_correlation_known_cases():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    y = np.array([2.0, 4.0, 5.0, 4.0, 5.0])
    assert correlation(x, y) == pytest.approx(math.sqrt(0.6), rel=1e-12)  # Sxy 6, Sxx 10, Syy 6
    assert correlation(x, 3 * x - 2) == pytest.approx(1.0)
    assert correlation(x, -0.5 * x + 7) == pytest.approx(-1.0)
    t = np.linspace(0, 1, 4001)[:-1]
    assert correlation(np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)) == pytest.approx(0.0, abs=1e-12)
    assert correlation(np.append(x, np.nan), np.append(y, 1.0)) == pytest.approx(math.sqrt(0.6), rel=1e-12)
