"""Where the mismatch is: residual windows per channel that stand out of the noise, with the regime
the rig was in, and (for what stays unexplained) the residual's dominant frequency.

Contract: `locate(data, sims)` returns the windows, largest first: recording, channel, times (s),
regime (direction of motion, rest, reversal, saturation, steady state), score (RMS residual in the
window / channel spread), noise_ratio (RMS residual in the window / channel noise) and the dominant
frequency of the residual there (Hz).
"""
from __future__ import annotations

import numpy as np

from ..recording import Recording
from ..rigdesc import RigDescription
from .data import Data, motion_channel

WINDOW_S = 0.05  # s, moving-RMS window of the residual


def regimes(rec: Recording, rig: RigDescription, i0: int, i1: int) -> str:
    """Words for what the rig was doing in samples i0..i1: direction, rest, reversal, saturation."""
    words = []
    motion = motion_channel(rec, rig)
    if motion:
        q = rec.channels[motion]
        dt = float(np.median(np.diff(rec.time)))
        velocity = np.gradient(q, dt)
        v = velocity[i0:i1]
        span = float(np.nanmax(np.abs(velocity))) or 1.0
        moving = np.abs(v) > 0.05 * span
        if moving.mean() < 0.2:
            words.append(f"near zero velocity ({motion} at rest)")
        else:
            up, down = (v > 0.05 * span).mean(), (v < -0.05 * span).mean()
            if up > 0.1 and down > 0.1:
                words.append("velocity reversal")
            words.append("positive motion" if up >= down else "negative motion")
    for c in rig.of_kind("command"):
        limit = rig.channels[c].get("limit")
        if c in rec.channels and limit and np.nanmax(np.abs(rec.channels[c][i0:i1])) >= 0.98 * limit:
            words.append(f"{c} saturated")
    if i1 >= 0.8 * rec.time.size:
        words.append("steady state")
    return ", ".join(words) or "transient"


def dominant_frequency(r: np.ndarray, dt: float) -> float:
    """Frequency (Hz) of the largest peak of the residual's spectrum (mean removed); 0 for a bias."""
    r = np.nan_to_num(r)
    if r.size < 8 or not np.any(r):
        return 0.0
    power = np.abs(np.fft.rfft((r - r.mean()) * np.hanning(r.size))) ** 2
    if power[1:].max() < 0.25 * float(np.sum(r.mean() ** 2) * r.size):  # mostly a constant offset
        return 0.0
    return float(np.fft.rfftfreq(r.size, dt)[1 + int(np.argmax(power[1:]))])


def locate(data: Data, sims: list[Recording], top: int = 8) -> list[dict]:
    """Windows where the residual stands out of the noise, largest first (see the module docstring)."""
    found = []
    for rec, sim, name, chans, scale, noise in zip(data.recordings, sims, data.names, data.channels,
                                                   data.scale, data.noise):
        dt = float(np.median(np.diff(rec.time)))
        width = max(3, int(WINDOW_S / dt))
        kernel = np.ones(width) / width
        for c in chans:
            raw = np.nan_to_num(sim.channels[c] - rec.channels[c])
            r = raw / scale[c]
            rms = np.sqrt(np.convolve(r**2, kernel, mode="same"))
            threshold = max(3 * noise[c] / scale[c], 0.5 * float(np.sqrt(np.mean(r**2))), 1e-3)
            hot = rms > threshold
            edges = np.flatnonzero(np.diff(np.r_[0, hot.astype(int), 0]))
            for i0, i1 in zip(edges[::2], edges[1::2]):
                if i1 - i0 < width:
                    continue
                found.append({"recording": name, "channel": c, "t_start": float(rec.time[i0]),
                              "t_end": float(rec.time[i1 - 1]), "regime": regimes(rec, data.rig, i0, i1),
                              "score": float(np.sqrt(np.mean(r[i0:i1] ** 2))),
                              "noise_ratio": float(np.sqrt(np.mean(raw[i0:i1] ** 2))) / noise[c],
                              "frequency_hz": dominant_frequency(raw[i0:i1], dt)})
    found.sort(key=lambda w: -w["score"])
    return found[:top]
