"""A disturbance outside the catalogue: a steady spectral line in a channel's residual.

Contract: `steady_lines(data, sims)` lists the channels whose final residual (measured - simulated, in noise units)
carries one sinusoid, at the same frequency in most recordings, steady over each recording and phase-continuous, that
the simulation does not carry near that frequency: mains hum on a bridge amplifier, a fan, a pump, a loop's limit
cycle the model does not have. No catalogue effect makes one, so `validate.verdict_of` calls such a case `unexplained`.

Measured on the final models of seeds 86-88 (44 cases) and the off-catalogue probes of docs/diagnosis.md (a 50 Hz hum
of 5 x the noise added to a laser tip sensor and to a Watflex strain bridge): the hums 782 and 35,891 x chance,
steady 0.97-0.99, the simulation carrying 0.02-0.21 of their amplitude near 50 Hz; every other channel's strongest
line at most 71 x chance, and those above 25 x carried by the simulation itself (3.1-33 x their amplitude: the
model's own vibration, misfit). The Quanser 2DSFL's residual (a real rig, far from the noise) peaks at 104 x chance,
at 1.7 Hz, carried by the simulation (1.1 x): its loop's own oscillation, not a line from outside.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import find_peaks

from .data import Data

LINE_SIGNIFICANCE = 100.0  # its periodogram bin over the median of the bins beside it (white noise: an Exp(1) over
# ln 2, at most ~12 in 3,000 bins by chance)
LINE_VARIANCE = 0.05  # ... taking at least this many noise variances (an amplitude of 0.32 noise sd)
LINE_STEADY = 0.5  # ... its amplitude in the recording's weakest window at least this share of its strongest
LINE_WINDOW_CYCLES = 5.0  # windows of at least this many cycles, 4 to 16 of them (a ring after each step decays)
LINE_COHERENT = 0.8  # ... one phase over the whole recording: its amplitude there this share of the windows' mean
# (a step response rings with a new phase at each step and decays)
LINE_SIMULATED = 0.5  # ... the simulation's own line within +-20 % of its frequency at most this share of its amplitude
LINE_PEAKS = 5  # the residual periodogram's peaks asked, in turn, highest over the simulation's own (a hum can be
# smaller than a misfit at the model's vibration, which the simulation carries too)
LINE_CYCLES = 10.0  # the lowest frequency asked: this many cycles in the recording (below it: a drift, not a line)


def _sinusoid(t: np.ndarray, r: np.ndarray, f: float) -> tuple[float, np.ndarray, float]:
    """(variance a sinusoid at `f` Hz takes from `r` beyond an offset and a trend, what is left, its amplitude)."""
    base = np.column_stack([np.ones_like(t), t - t.mean()])
    full = np.column_stack([base, np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    before = r - base @ np.linalg.lstsq(base, r, rcond=None)[0]
    coef = np.linalg.lstsq(full, r, rcond=None)[0]
    left = r - full @ coef
    return float(np.mean(before**2) - np.mean(left**2)), left, float(np.hypot(coef[2], coef[3]))


def _periodogram(t: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies in Hz, power) of `r`, detrended, Hann-windowed."""
    x = r - np.polyval(np.polyfit(t - t.mean(), r, 1), t - t.mean())
    return np.fft.rfftfreq(x.size, float(np.median(np.diff(t)))), np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2


def _peaks(t: np.ndarray, r: np.ndarray, low: float, high: float, count: int = 1,
           beside: np.ndarray | None = None) -> list[float]:
    """The frequencies (Hz) of `count` peaks of the periodogram of `r` in [low, high], at least three bins apart: the
    highest, or with `beside` (a signal on the same samples) those highest over what `beside` has in the same bin
    plus the band's median (a line in `r` that `beside` does not carry), first first."""
    freq, power = _periodogram(t, r)
    band = np.flatnonzero((freq >= low) & (freq <= high))
    if band.size == 0:
        return []
    tops, _ = find_peaks(np.concatenate([[-np.inf], power[band], [-np.inf]]), distance=3)
    tops = band[tops - 1]
    rank = power[tops] if beside is None else power[tops] / (_periodogram(t, beside)[1][tops] + np.median(power[band]))
    return [float(f) for f in freq[tops[np.argsort(rank)[::-1][:count]]]]


def line_in(t: np.ndarray, residual: np.ndarray, simulated: np.ndarray) -> dict | None:
    """The first line in one recording's `residual` that is_line, or else the first asked (of the periodogram's
    LINE_PEAKS peaks highest over what the simulation has there: a hum beside a larger misfit), and how it scores:
    frequency (Hz), gain (noise variances), amplitude (noise sd), significance (its periodogram bin over the median
    of the bins beside it), steadiness, coherence, the simulation's own amplitude near it over the line's. None where
    the recording is too short."""
    span = float(t[-1] - t[0])
    if t.size < 200 or span <= 0.0:
        return None
    freq, power = _periodogram(t, residual)
    rows = []
    for f0 in _peaks(t, residual, LINE_CYCLES / span, 0.45 / float(np.median(np.diff(t))), LINE_PEAKS, simulated):
        grid = f0 + np.linspace(-1.0, 1.0, 21) / span  # the bin's width, refined
        f = float(grid[int(np.argmax([_sinusoid(t, residual, g)[0] for g in grid]))])
        gain, _, amplitude = _sinusoid(t, residual, f)
        k = int(np.argmin(np.abs(freq - f0)))
        width = max(10, int(0.2 * k))  # bins beside the line: +-20 % of its frequency, at least 10 bins
        beside = np.r_[power[max(1, k - width):max(1, k - 3)], power[k + 4:k + width + 1]]
        pieces = int(np.clip(span * f // LINE_WINDOW_CYCLES, 4, 16))
        windows = [_sinusoid(t[w], residual[w], f)[2] for w in np.array_split(np.arange(t.size), pieces)]
        near = _peaks(t, simulated, 0.8 * f, 1.2 * f)
        own = _sinusoid(t, simulated, near[0])[2] if near else 0.0
        row = {"frequency": f, "gain": gain, "amplitude": amplitude,
               "significance": float(power[k] / np.median(beside)) if beside.size and np.median(beside) > 0 else np.inf,
               "steady": min(windows) / max(windows) if max(windows) > 0.0 else 0.0,
               "coherent": amplitude / float(np.mean(windows)) if np.mean(windows) > 0.0 else 0.0,
               "simulated": own / amplitude if amplitude > 0.0 else np.inf}
        if is_line(row):
            return row
        rows.append(row)
    return rows[0] if rows else None


def is_line(row: dict) -> bool:
    """Whether one recording's strongest line (line_in) is a steady line the simulation does not have."""
    return (row["significance"] >= LINE_SIGNIFICANCE and row["gain"] >= LINE_VARIANCE and row["steady"] >= LINE_STEADY
            and row["coherent"] >= LINE_COHERENT and row["simulated"] <= LINE_SIMULATED)


def steady_lines(data: Data, sims: list) -> list[dict]:
    """Channels with a steady line (is_line) in at least half their recordings, at one frequency (within two bins of
    the shortest): channel, frequency (Hz), amplitude (the channel's unit and noise sd), significance, recordings."""
    rows: dict[str, list[tuple[dict, float, float]]] = {}  # channel -> (line, its noise, the recording's span)
    for rec, sim, chans, noise in zip(data.recordings, sims, data.channels, data.noise):
        for c in chans:
            ok = np.isfinite(rec.channels[c]) & np.isfinite(sim.channels[c])
            if noise[c] <= 0.0 or ok.sum() < 200:
                continue
            t = rec.time[ok]
            row = line_in(t, (rec.channels[c] - sim.channels[c])[ok] / noise[c], sim.channels[c][ok] / noise[c])
            if row is not None:
                rows.setdefault(c, []).append((row, noise[c], float(t[-1] - t[0])))
    units = data.rig.units()
    out = []
    for c, found in rows.items():
        lines = [(row, n, span) for row, n, span in found if is_line(row)]
        if 2 * len(lines) < len(found):
            continue
        f = float(np.median([row["frequency"] for row, _, _ in lines]))
        if any(abs(row["frequency"] - f) > 2.0 / span for row, _, span in lines):
            continue
        out.append({"channel": c, "frequency_hz": f, "unit": units.get(c, ""),
                    "amplitude": float(np.median([row["amplitude"] * n for row, n, _ in lines])),
                    "noise_sd": float(np.median([row["amplitude"] for row, _, _ in lines])),
                    "significance": float(np.median([row["significance"] for row, _, _ in lines])),
                    "recordings": f"{len(lines)} of {len(found)}"})
    return out
