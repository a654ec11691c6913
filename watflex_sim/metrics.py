"""Step-response and fit metrics, in the units of the signals given."""
from __future__ import annotations

import numpy as np


def step_metrics(t: np.ndarray, y: np.ndarray, t_step: float, initial: float, final: float,
                 settle_band: float = 0.02) -> dict[str, float]:
    """Rise time (10-90 %, s), settling time (into +-2 % of the step, s, from t_step),
    overshoot (% of the step) and steady-state error (mean of the last 10 % of samples, in y's unit).

    The step is `final - initial` (either sign). NaN where the response never reaches a level.
    """
    t, y = np.asarray(t, float), np.asarray(y, float)
    after = t >= t_step
    tt, s = t[after], (y[after] - initial) / (final - initial)  # normalised: 0 -> 1

    def first(level: float) -> float:
        idx = np.flatnonzero(s >= level)
        return float(tt[idx[0]]) if idx.size else np.nan

    outside = np.flatnonzero(np.abs(s - 1.0) > settle_band)
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] + 1 < tt.size:
        settling = float(tt[outside[-1] + 1] - t_step)
    else:
        settling = np.nan
    tail = y[after][-max(1, tt.size // 10):]
    return {
        "rise_time_s": first(0.9) - first(0.1),
        "settling_time_s": settling,
        "overshoot_pct": float(max(0.0, s.max() - 1.0) * 100.0),
        "steady_state_error": float(final - tail.mean()),
    }


def nrmse(measured: np.ndarray, simulated: np.ndarray) -> float:
    """RMS(measured - simulated) / RMS(measured - mean(measured)), NaN samples ignored (recordings.md); NaN
    when the measured channel is constant, as `correlation` tests it (np.ptp: the spread of identical values
    computes to rounding error, 4e-19 rad for a quantised angle at rest, which made a mean NRMSE 3.7e12)."""
    m, s = np.asarray(measured, float), np.asarray(simulated, float)
    ok = np.isfinite(m) & np.isfinite(s)
    m, s = m[ok], s[ok]
    if m.size == 0 or np.ptp(m) == 0:
        return np.nan
    return float(np.sqrt(np.mean((m - s) ** 2)) / np.sqrt(np.mean((m - m.mean()) ** 2)))


def correlation(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Pearson's correlation coefficient (laser_arm_paper eq. 26), NaN samples ignored; NaN (no
    warning) when either side is constant."""
    m, s = np.asarray(measured, float), np.asarray(simulated, float)
    ok = np.isfinite(m) & np.isfinite(s)
    m, s = m[ok], s[ok]
    if m.size < 2 or np.ptp(m) == 0 or np.ptp(s) == 0:
        return np.nan
    return float(np.corrcoef(m, s)[0, 1])
