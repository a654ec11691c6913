"""Where the mismatch is: residual windows per channel that stand out of the noise, with the regime
the rig was in, and (for what stays unexplained) the residual's dominant frequency.

Contract: `locate(data, sims)` returns the windows, largest first: recording, channel, times (s),
regime (direction of motion, rest, reversal, saturation, steady state), score (RMS residual in the
window / channel spread), noise_ratio (RMS residual in the window / channel noise) and the dominant
frequency of the residual there (Hz). `local_excess(data, sims)` returns the windows where the residual
stands LOCAL_MARGIN x above what noise and discretisation leave *there* (a misfit at one transient, small on the
whole), and `local_ratio` scores a model on such windows.
"""
from __future__ import annotations

import numpy as np

from ..recording import Recording
from ..rigdesc import RigDescription
from .data import DISCRETISATION_COUNT, Data
from .motion import motion_channel, motions

WINDOW_S = 0.05  # s, moving-RMS window of the residual
LOCAL_WINDOW_S = 0.1  # s, window of the local test (local_excess)
LOCAL_MARGIN = 4.0  # a window this far above its local null is a misfit, whatever the whole recording's ratio


def regimes(rec: Recording, rig: RigDescription, i0: int, i1: int, motion: tuple[str, np.ndarray] | None = None) -> str:
    """Words for what the rig was doing in samples i0..i1: direction, rest, reversal, saturation. `motion`: what
    moves (motion.motions: its name and positions), else the recording's motion_channel."""
    words = []
    if motion is None and (channel := motion_channel(rec, rig)):
        motion = channel, rec.channels[channel]
    if motion:
        what, q = motion
        dt = float(np.median(np.diff(rec.time)))
        velocity = np.gradient(q, dt)
        v = velocity[i0:i1]
        span = float(np.nanmax(np.abs(velocity))) or 1.0
        moving = np.abs(v) > 0.05 * span
        if moving.mean() < 0.2:
            words.append(f"near zero velocity ({what} at rest)")
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
    for rec, sim, name, chans, scale, noise, moves in zip(data.recordings, sims, data.names, data.channels,
                                                          data.scale, data.noise, motions(data)):
        dt = float(np.median(np.diff(rec.time)))
        width = max(3, int(WINDOW_S / dt))
        for c in chans:
            raw = np.nan_to_num(sim.channels[c] - rec.channels[c])
            r = raw / scale[c]
            rms = np.sqrt(_moving_mean(r**2, width))
            threshold = max(3 * noise[c] / scale[c], 0.5 * float(np.sqrt(np.mean(r**2))), 1e-3)
            hot = rms > threshold
            edges = np.flatnonzero(np.diff(np.r_[0, hot.astype(int), 0]))
            for i0, i1 in zip(edges[::2], edges[1::2]):
                if i1 - i0 < width:
                    continue
                found.append({"recording": name, "channel": c, "t_start": float(rec.time[i0]),
                              "t_end": float(rec.time[i1 - 1]), "regime": regimes(rec, data.rig, i0, i1, moves),
                              "score": float(np.sqrt(np.mean(r[i0:i1] ** 2))),
                              "noise_ratio": float(np.sqrt(np.mean(raw[i0:i1] ** 2))) / noise[c],
                              "frequency_hz": dominant_frequency(raw[i0:i1], dt)})
    found.sort(key=lambda w: -w["score"])
    return found[:top]


def _moving_mean(x: np.ndarray, width: int) -> np.ndarray:
    return np.convolve(x, np.ones(width) / width, mode="same")


def _local_width(rec: Recording) -> int:
    """Samples in a LOCAL_WINDOW_S window of `rec`."""
    return max(3, int(round(LOCAL_WINDOW_S / float(np.median(np.diff(rec.time))))))


def local_null(data: Data, i: int, channel: str, width: int) -> np.ndarray:
    """Per sample of recording i, the variance (unit^2) a model with nothing missing leaves on `channel` over a
    window of `width` samples: the sensor noise or, where larger, what the rig's noise leaves in closed loop there,
    plus DISCRETISATION_COUNT^2 x what a finer discretisation changes there (both from floors.calibrate_noise; the
    whole recording's noise spreads them evenly, but they gather at transients). The discretisation change counts
    twice: against twice as fine is a lower bound of our own error (4 x finer: 1.3 x more), and recordings
    from another implementation of the datasheet carry that one's own."""
    n = data.recordings[i].time.size
    floor = np.full(n, data.sensor_noise[i][channel] ** 2 if data.sensor_noise else data.noise[i][channel] ** 2)
    closed = data.closed_loop_sq[i].get(channel) if data.closed_loop_sq else None
    if closed is not None:
        floor = np.maximum(floor, _moving_mean(closed, width))
    finer = data.discretisation_sq[i].get(channel) if data.discretisation_sq else None
    return floor + (DISCRETISATION_COUNT**2 * _moving_mean(finer, width) if finer is not None else 0.0)


def local_excess(data: Data, sims: list[Recording]) -> list[dict]:
    """Windows of LOCAL_WINDOW_S where the residual's RMS is LOCAL_MARGIN x above its local_null, largest first:
    recording (its index and name), channel, first and last sample, times (s), regime and ratio. Measured on the
    refit nominal model of 15 benchmark cases (seeds 59-61, windows of 0.1 s): the 12 clean ones at most 2.2 x,
    two dwell-time stictions called `nothing_missing` (0.92-1.0 x the noise on the whole) 5.6 x and 6.3 x after the
    dwell, a laser motor current outside the catalogue (1.14 x on the whole, called `nothing_missing`) 4.9 x."""
    found = []
    for i, (rec, sim, name, chans, moves) in enumerate(zip(data.recordings, sims, data.names, data.channels, motions(data))):
        width = _local_width(rec)
        for c in chans:
            r = np.nan_to_num(rec.channels[c] - sim.channels[c])
            ratio = np.sqrt(_moving_mean(r**2, width) / local_null(data, i, c, width))
            hot = ratio > LOCAL_MARGIN
            edges = np.flatnonzero(np.diff(np.r_[0, hot.astype(int), 0]))
            for i0, i1 in zip(edges[::2], edges[1::2]):
                j = i0 + int(np.argmax(ratio[i0:i1]))
                a, b = max(0, j - width // 2), min(rec.time.size, j + width // 2 + 1)
                found.append({"recording": name, "index": i, "channel": c, "first": int(a), "last": int(b),
                              "t_start": float(rec.time[a]), "t_end": float(rec.time[b - 1]),
                              "regime": regimes(rec, data.rig, a, b, moves), "ratio": float(ratio[j])})
    found.sort(key=lambda w: -w["ratio"])
    return found


def local_ratio(data: Data, sims: list[Recording] | None, windows: list[dict]) -> float:
    """RMS over the `windows`' samples (local_excess, every channel's in its own local-null units) of a model's
    residual: 1 = what noise and discretisation leave there; inf if the model diverged."""
    if sims is None:
        return float("inf")
    total, count = 0.0, 0
    for w in windows:
        i, c, a, b = w["index"], w["channel"], w["first"], w["last"]
        null = local_null(data, i, c, _local_width(data.recordings[i]))[a:b]
        r = np.nan_to_num(data.recordings[i].channels[c][a:b] - sims[i].channels[c][a:b])
        total += float(np.sum(r**2 / null))
        count += b - a
    return float(np.sqrt(total / count)) if count else 1.0


def local_gain(data: Data, windows: list[dict], before: list[Recording], after: list[Recording] | None) -> float:
    """Share of the windows' local excess (local_ratio - 1) that the model simulated as `after` removes from
    the one simulated as `before`."""
    now = local_ratio(data, before, windows)
    return (now - local_ratio(data, after, windows)) / max(now - 1.0, 1e-9)
