"""Noise levels measured on the data: white noise from second differences, a quantised channel's grid, noise a
sensor's filter correlated over a few samples.

Contract: `measured_noise(values)` is a channel's white noise rms from its own samples (at least its quantisation's),
`visible_noise` that or 0 where the data resolve none, `quantised` whether a channel lies on a grid coarse against a
noise, `coloured_noise(residual, dt)` the rms of noise correlated over a few samples on a model's residual (0 where
it shows none). All in the values' unit; none simulates.
"""
from __future__ import annotations

import math

import numpy as np

UNRESOLVED = 1e-6  # x a channel's spread (std): a noise estimate below this is the file's number format, not the rig's
# noise (ten significant digits round at ~1e-10 of a value); `prepare` then takes the channel as showing no noise
QUANTUM_SHARE = 0.1  # add_coloured_noise: a channel whose grid's rms step (step / sqrt(12)) is above this x its
# coloured_noise is quantised: its quantisation error, correlated where it moves slowly, levels off too (seed 97's
# two-joint encoders re-logged at 2 ms: at 3.5-4 x their step's rms against the nominal model)
NOISE_LAG_S = 8e-3  # s: the longest lag coloured_noise compares second differences at (noise correlated over up to
# about a quarter of it, a sensor's first-order anti-alias filter at 80 Hz or above, shows its whole rms there)
PLATEAU = 1.1  # coloured_noise: estimates within this factor of each other over a range of lags are level
COLOUR_LIMIT = 2.0  # coloured_noise: at most this x the lag-1 estimate (a first-order low-pass that levels off within
# NOISE_LAG_S shows at least 0.55 of its rms at lag 1; an encoder's steps, 1e5 x, are not a sensor's noise)


def second_difference_noise(values: np.ndarray, lag: int = 1) -> float:
    """White noise's rms estimated from second differences `lag` samples apart (the values' unit): their median
    absolute deviation / 0.6745 / sqrt(6). Smooth motion sampled fast contributes little (a sinusoid's second
    difference is (w lag dt)^2 of it); 0 with fewer than 2 lags + 3 finite samples."""
    x = values[np.isfinite(values)]
    if x.size < 2 * lag + 3:
        return 0.0
    d2 = x[2 * lag:] - 2.0 * x[lag:-lag] + x[:-2 * lag]
    return float(np.median(np.abs(d2 - np.median(d2)))) / 0.6745 / math.sqrt(6)


def measured_noise(values: np.ndarray) -> float:
    """Noise rms estimated from the data itself (its unit): second_difference_noise of consecutive samples,
    at least the rms of a uniform quantisation step when the values are quantised."""
    x = values[np.isfinite(values)]
    if x.size < 5:
        return 0.0
    sigma = second_difference_noise(x)
    levels = np.unique(x)
    if 1 < levels.size < 0.5 * x.size:  # quantised: an encoder, a converter
        sigma = max(sigma, float(np.median(np.diff(levels))) / math.sqrt(12))
    return sigma


def grid_step(values: np.ndarray) -> float:
    """The step of the grid the finite values lie on (their unit: an encoder's count, a converter's least bit, a
    file's last printed digit): the smallest change between consecutive samples where every change is a whole
    multiple of it (within 1 %); 0 where they lie on none or hardly change."""
    x = values[np.isfinite(values)]
    change = np.abs(np.diff(x))
    change = change[change > 0]
    if change.size < 10:
        return 0.0
    steps = change / change.min()
    return float(change.min()) if np.all(np.abs(steps - np.round(steps)) < 0.01) else 0.0


def quantised(values: np.ndarray, noise: float) -> bool:
    """Whether `values` lie on a grid coarse against `noise` (their unit): the grid's rms step (step / sqrt(12)) at
    least QUANTUM_SHARE x it (an encoder's counts, a 12-bit converter's least bit)."""
    return grid_step(values) / math.sqrt(12) >= QUANTUM_SHARE * noise


def coloured_noise(residual: np.ndarray, dt: float) -> float:
    """The rms of noise correlated over a few samples (a sensor's anti-alias filter, an amplifier's bandwidth),
    measured on a model's residual (its unit; `dt` the sample spacing, s), or 0 where the residual shows none.
    second_difference_noise estimates white noise's rms alike at every lag; noise correlated over a few samples
    shows less at lag 1 (a first-order low-pass at 100 Hz sampled at 1 kHz: 0.62 of its rms) and rises to its rms
    once the correlation has died, where a smooth misfit grows as lag^2 and a steady line (a hum) swings with the
    lag. So: the estimate at the longest lag up to NOISE_LAG_S where it is level (every lag from half that to it
    within a factor PLATEAU) and above the lag-1 estimate by more than PLATEAU, up to COLOUR_LIMIT x; else 0.
    Seed 94's clean laser case with that noise added to its tip sensor and motor current at twice their declared
    rms (docs/diagnosis.md, "Noise a sensor's filter correlated") read 0.69 x their noise at lag 1 and came out
    `unexplained`, its motor current 1.41 x that floor."""
    longest = int(round(NOISE_LAG_S / dt)) if dt > 0 else 0
    if longest < 2:
        return 0.0
    level = [second_difference_noise(residual, lag) for lag in range(longest // 2, longest + 1)]
    white = second_difference_noise(residual)
    if max(level) > PLATEAU * min(level) or not PLATEAU * white < level[-1] <= COLOUR_LIMIT * white:
        return 0.0
    return level[-1]


def visible_noise(values: np.ndarray, spread: float) -> float:
    """measured_noise (the values' unit), or 0 where it is below UNRESOLVED x `spread`: the data resolve no noise.
    A channel at rest more than half the time (a torque command holding still) has a median second difference at
    its last printed digit: seed 97's clean two-joint case (watflex-df2f6bbb) re-sampled at 2 ms measured a shoulder
    command's noise at 6e-9 N m (3e-10 of its spread; 0.019 N m on its two sister recordings), and the refit in
    noise units weighed that channel 1e9 x the others and could not move (27 x the noise where the 1 ms files'
    refit reached 0.92 x)."""
    sigma = measured_noise(values)
    return sigma if sigma > UNRESOLVED * spread else 0.0
