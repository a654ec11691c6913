"""A logger's glitches: one or two samples of one channel far off the line their neighbours lie on, which nothing
sampled at the loop's rate does; and a slower sensor's values a logger held between its samples.

Contract: `without_glitches(rec, measured, commands, noise)` returns the recording with every glitch of a measured
channel made empty cells (NaN: compared nowhere, as a logger's missing samples) and how many samples it emptied on
each channel; a recording without one is returned as it is. A glitch (`glitch_samples`) moves one sample, or two
neighbours alike, by more than GLITCH x the channel's noise, and each sample from two before it to two after it is
off the mean of its own neighbours as that alone makes it (RUNS, within GLITCH_SHAPE): the samples around it lie on
a line. A step (a current at a voltage step) is off by a half at two samples in opposite senses, a corner (a cusp)
leaves its neighbours on their lines, a fast oscillation (a beam mode near the sampling rate) is off at every
sample: none is a glitch. One that a command of the recording has within a sample (a controller's kick through a
derivative, its answer to a sensor's spike) is the rig's and kept; one that only other measured channels share is a
logger's (a row written wrong). Seed 94's clean laser case with six single samples a recording moved by 30 x the
noise on the tip sensor and the motor current (0.1 % of the samples) came out `unexplained` (motor current 1.47 x
its noise, the residual's windows the glitches) in 265 s; docs/diagnosis.md, "A logger's glitches".

`without_held(rec, channels)` returns the recording with the repeats of a channel whose values a logger wrote in
every row between a slower sensor's samples (held_samples) made empty cells: the sensor's value compared once, at
the sample it came. Seed 97's clean two-joint case with its 25 Hz camera so held through the 1 kHz log was read as a
29,980 N m/rad elbow compliance; docs/diagnosis.md, "A slower sensor a logger held".
"""
from __future__ import annotations

import numpy as np

from ..recording import Recording

GLITCH = 10.0  # x the channel's noise: a glitch moves its samples this far (white noise: a single sample's offset
# from its neighbours' mean this large is 8 sd of it, ~1e-15 a sample) ...
GLITCH_SHAPE = 0.2  # ... and every sample from two before it to two after it is off its neighbours' mean as RUNS
# says, within this x how far it moved them


RUNS = {1: (0.0, -0.5, 1.0, -0.5, 0.0), 2: (0.0, -0.5, 0.5, 0.5, -0.5, 0.0)}  # samples in a glitch -> how far
# each sample from two before it to two after it is off its neighbours' mean, per unit the glitch moves them
HELD_SHARE = 0.8  # held_samples: of a channel's runs of one repeated value (its first and last aside), this share
# within a sample of their median length
HELD_RUNS = 5  # ... and at least this many such runs


def glitch_samples(values: np.ndarray, noise: float) -> np.ndarray:
    """Mask of the samples of `values` in glitches (see the module: one or two samples, RUNS), judged on its finite
    samples in order (a slower sensor's empty cells between them skipped); `noise` in the values' unit (0: none is)."""
    out = np.zeros(values.shape, bool)
    finite = np.flatnonzero(np.isfinite(values))
    if finite.size < 8 or noise <= 0.0:
        return out
    x = values[finite]
    off = x[1:-1] - 0.5 * (x[:-2] + x[2:])  # off[k]: sample k + 1 off its neighbours' mean
    for run, shape in RUNS.items():
        width = len(shape)
        windows = np.lib.stride_tricks.sliding_window_view(off, width)  # row k: samples k + 1 .. k + width
        moved = windows[:, 2:2 + run].sum(axis=1)  # how far the glitch moved its samples
        fits = np.all(np.abs(windows - np.outer(moved, shape)) < GLITCH_SHAPE * np.abs(moved)[:, None], axis=1)
        for k in np.flatnonzero(fits & (np.abs(moved) > GLITCH * noise)):
            out[finite[k + 3:k + 3 + run]] = True
    return out


def without_glitches(rec: Recording, measured: list[str], commands: list[str], noise: dict[str, float]
                     ) -> tuple[Recording, dict[str, int]]:
    """`rec` with the glitches of its `measured` channels that none of its `commands` has within a sample made NaN,
    and the samples emptied on each channel; `noise`: channel -> its noise (its unit)."""
    kicks = np.zeros(rec.time.shape, bool)
    for c in commands:
        kicks |= glitch_samples(np.asarray(rec.channels[c], float), noise[c])
    kicks |= np.roll(kicks, 1) | np.roll(kicks, -1)
    return emptied(rec, {c: glitch_samples(np.asarray(rec.channels[c], float), noise[c]) & ~kicks for c in measured})


def without_held(rec: Recording, channels: list[str]) -> tuple[Recording, dict[str, int]]:
    """`rec` with the held repeats (held_samples) of its `channels` made NaN, and the samples emptied on each."""
    return emptied(rec, {c: held_samples(np.asarray(rec.channels[c], float)) for c in channels})


def emptied(rec: Recording, masks: dict[str, np.ndarray]) -> tuple[Recording, dict[str, int]]:
    """`rec` with each channel's `masks` samples made NaN and how many on each channel that has any; `rec` itself
    where none has."""
    changed, counts = dict(rec.channels), {}
    for c, mask in masks.items():
        if mask.any():
            changed[c] = np.where(mask, np.nan, rec.channels[c])
            counts[c] = int(mask.sum())
    return (Recording(rec.time, changed, rec.meta), counts) if counts else (rec, {})


def held_samples(values: np.ndarray) -> np.ndarray:
    """Mask of the samples of `values` that repeat the one before them exactly where a logger wrote a slower
    sensor's last value in every row (a 25 Hz camera held through a 1 kHz log): the finite values come in runs of one
    value of a common length (HELD_SHARE of the runs within a sample of their median length, at least 2, and
    HELD_RUNS runs or more). The first sample of each run is the sensor's and is not in the mask. The caller asks it
    of channels not on a grid coarse against their noise (an encoder at a steady speed repeats its counts as evenly)."""
    out = np.zeros(values.shape, bool)
    finite = np.flatnonzero(np.isfinite(values))
    x = values[finite]
    repeats = np.zeros(x.shape, bool)
    repeats[1:] = x[1:] == x[:-1]
    lengths = np.diff(np.append(np.flatnonzero(~repeats), x.size))[1:-1]  # the runs, the first and last aside
    if lengths.size < HELD_RUNS:
        return out
    common = float(np.median(lengths))
    if common >= 2 and np.mean(np.abs(lengths - common) <= 1) >= HELD_SHARE:
        out[finite[repeats]] = True
    return out
