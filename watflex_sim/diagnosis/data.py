"""The diagnosis' data: recordings of one rig in a canonical order, the channels compared, their
spreads and noise levels, and the training/validation split.

Contract: `prepare(recordings, names)` returns the same `Data` whatever order the files come in
(they are sorted by name, then content). Every recording is split into alternate time blocks:
even blocks train the fits, odd blocks validate them, so every regime the data has (directions,
payloads, rest, saturation, reversals) is judged on samples the fit did not see. Residuals are in
two units: the channel's spread (what the screening compares, `residual_vector`) and the channel's noise
(what fits minimise and verdicts judge, `unit_change`, scores.noise_ratio: 1 = the model is as close as the
noise allows).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from ..model import ConfigError
from ..recording import Recording
from ..rigdesc import RigDescription, load_rig
from .glitch import without_glitches, without_held
from .noise import measured_noise, quantised, visible_noise

FIT_SECONDS = 30.0  # s: at most this much of each recording trains the fits; the rest only validates
BLOCKS_PER_RECORDING = 60  # blocks per recording, in pairs of one training and one validation block (split_blocks):
# short enough that a transient is split
BLOCK_LIMITS_S = (0.02, 0.25)  # s: shortest and longest block
SPLIT_SEED = 20261124  # fixed: the same recording is always split the same way (salted with its content)
STRIDE = 4  # samples: residuals are taken every STRIDE samples while fitting
MIN_SPAN_S = 0.05  # s: a recording shorter than this is too short to simulate and diagnose
NO_NOISE_FLOOR = 1e-3  # x a channel's spread: its noise where neither the rig declares one nor the data show one
TICK_JITTER = 1e-3  # x the control period: time stamps further than this off the loop's ticks are moved onto them (on_ticks)
ON_GRID = 0.2  # the least mean resultant length of the stamps' phases on the loop's period for a jittered grid (on_ticks):
# uniform jitter up to +-0.4 of a period has 0.23, up to +-0.25 0.64; stamps unrelated to the loop ~1 / sqrt(samples)
DISCRETISATION_COUNT = 2.0  # a channel judged on its own (worst_channel) and a window (locate.local_null) count what a
# finer discretisation changes this many times: against twice as fine is a lower bound of our own error (4 x finer:
# 1.3 x more), and recordings from another implementation of the datasheet carry that one's own


@dataclass
class Model:
    """A candidate model: effects (catalogue entries with parameters) and refit parameter ratios."""

    effects: list[dict] = field(default_factory=list)
    parameters: dict[str, float] = field(default_factory=dict)

    def places(self) -> tuple:
        """The effects as (effect, place) pairs, in order: which physics the model has, whatever the numbers."""
        return tuple((e["effect"], e["where"]) for e in self.effects)


@dataclass
class Data:
    """The recordings of one rig (canonical order), the channels compared, their scales, their
    noise and the train/validation split."""

    recordings: list[Recording]
    names: list[str]
    rig: RigDescription
    channels: list[list[str]]  # per recording
    scale: list[dict[str, float]]  # per recording: channel -> RMS spread (its unit)
    noise: list[dict[str, float]]  # per recording: channel -> noise rms (its unit)
    train: list[np.ndarray]  # per recording: boolean mask of training samples
    how: str = ""
    idle: frozenset = frozenset()  # rig parameters these recordings do not depend on (not refit)
    discretisation: list[dict[str, float]] = field(default_factory=list)  # per recording: channel -> the
    # simulator's own discretisation error (its unit), part of `noise` (floors.add_discretisation_error)
    sensor_noise: list[dict[str, float]] = field(default_factory=list)  # per recording: channel -> the noise
    # the recording shows (declared or measured, its unit): `noise` before the closed-loop and discretisation parts
    closed_loop_sq: list[dict[str, np.ndarray]] = field(default_factory=list)  # per recording: channel -> what the
    # rig's noise leaves in closed loop, squared, per sample (its unit^2; floors.add_closed_loop_noise)
    discretisation_sq: list[dict[str, np.ndarray]] = field(default_factory=list)  # per recording: channel -> what a
    # finer discretisation changes, squared, per sample (its unit^2; floors.add_discretisation_error):
    # locate.local_excess
    motion_memo: list | None = None  # `motions`' answer, once asked
    effort_memo: float | None = None  # motion.simulated_effort's answer, once asked
    glitches: list[str] = field(default_factory=list)  # "file (channel samples, ...)": a logger's glitches left out
    held: list[str] = field(default_factory=list)  # "file (channel samples, ...)": a slower sensor's held repeats

    @property
    def noise_floor(self) -> list[dict[str, float]]:
        """Per recording: channel -> the NRMSE that noise alone leaves (noise / spread)."""
        return [{c: n[c] / s[c] for c in n} for n, s in zip(self.noise, self.scale)]

    @property
    def absorbable(self) -> float:
        """The share of the noise floor's square, mean over recordings and channels, that is not the recordings'
        own white noise (`sensor_noise`): the closed-loop response to the noise and our discretisation error,
        fixed signals in a recording that a model may partly fit (0..1)."""
        shares = [1.0 - (s[c] / n[c]) ** 2 for s, n in zip(self.sensor_noise, self.noise)
                  for c in n if n[c] > 0 and c in s]
        return float(np.clip(np.mean(shares), 0.0, 1.0)) if shares else 0.0


def _fingerprint(rec: Recording) -> str:
    h = hashlib.sha256(np.ascontiguousarray(rec.time).tobytes())
    for c in sorted(rec.channels):
        h.update(c.encode())
        h.update(np.ascontiguousarray(rec.channels[c]).tobytes())
    return h.hexdigest()


def on_ticks(rec: Recording, period: float) -> tuple[Recording, float]:
    """`rec` with its time stamps moved onto the ticks of its control loop (`period`, s) and the farthest move (s),
    or `rec` as it is and 0. The loop samples its sensors on its ticks (and the simulation gives its channels there),
    so a stamp off its tick by less than half a period is a logger's clock jitter, not a sample taken between
    ticks: compared at the stamp, the simulation was interpolated to a time the values were not taken at. Only
    where the median spacing is a whole number of periods (the loop's own log, every n-th tick), the stamps' phases
    on the period cluster (mean resultant length at least ON_GRID: samples taken between ticks and stamped exactly,
    a variable-step simulator's output, have none and are left at their stamps), some stamp is more than
    TICK_JITTER periods off the grid (the grid's phase: the stamps' circular mean) and no two stamps fall on one
    tick (a clock that drifts a period against the loop is left alone). Seed 94's clean laser and single-link
    Watflex cases with stamps jittered by up to 0.25 ms (tools/relog.py) came out `unexplained` (`nothing_missing`
    now; docs/diagnosis.md, "Time stamps a logger jittered")."""
    t = rec.time - rec.time[0]
    spacing = float(np.median(np.diff(t))) / period
    if round(spacing) < 1 or abs(spacing - round(spacing)) > 0.1:  # the median of jittered spacings strays ~2 %
        return rec, 0.0
    mean = np.mean(np.exp(2j * np.pi * t / period))
    if abs(mean) < ON_GRID:
        return rec, 0.0
    phase = float(np.angle(mean)) / (2 * np.pi) * period  # s
    ticks = np.round((t - phase) / period)
    moved = float(np.max(np.abs(t - phase - ticks * period)))
    if moved <= TICK_JITTER * period or np.any(np.diff(ticks) <= 0):
        return rec, 0.0
    return Recording(rec.time[0] + phase + ticks * period, rec.channels, rec.meta), moved


def split_blocks(time: np.ndarray, salt: int = 0) -> tuple[np.ndarray, float]:
    """Training mask of one recording and the block length (s): blocks of equal length taken in pairs, one
    block of each pair fitting and the other validating, which one a pseudo-random choice fixed by SPLIT_SEED
    and `salt`, as is where the pairs start (up to two blocks in); samples after FIT_SECONDS only validate.
    Pairs bound a run of one half to two blocks, so every stretch the rig spends in one regime (a step's
    transient, a reversal) is seen by both halves: blocks drawn one by one left 0.5-1.4 s of a Watflex step, its
    whole transient, to validation, and the refit fitted without it was 1.40 x the noise there on a clean case
    (seed 65, watflex-6b7dd386; 0.73 x paired). A random order within each pair keeps a periodic experiment
    (pulses, a triangle wave) from falling into one half, as it would with strictly alternate blocks. `prepare`
    salts each recording with its content, and the random start keeps blocks off an experiment's round times:
    recordings of one length split alike put what happens at the same time in each (a step's onset) in the same
    half (seed 58: a 2 ms laser sensor delay, seen at the steps' onset only, was fitted on every onset and
    validated on none, and rejected; pairs whose first block always fitted put every laser step's transient,
    0.1-0.2 s, in validation: seed 65's beam stiffness x2.86, found before, `unexplained`)."""
    t = time - time[0]
    block = float(np.clip(t[-1] / BLOCKS_PER_RECORDING, *BLOCK_LIMITS_S))
    rng = np.random.default_rng([SPLIT_SEED, salt])
    index = ((t + rng.uniform(0.0, 2.0 * block)) // block).astype(int)
    first = rng.integers(0, 2, int(index[-1]) // 2 + 1).astype(bool)  # per pair: whether its first block fits
    training = np.where(index % 2 == 0, first[index // 2], ~first[index // 2])
    return training & (t < FIT_SECONDS), block


def _noise(rig: RigDescription, rec: Recording, channel: str, estimate: float) -> float:
    """A channel's noise (rms, its unit): the rig's declared noise or `estimate` from the recording, the larger;
    NO_NOISE_FLOOR x the channel's spread where both are 0."""
    values = rec.channels[channel]
    return max(float(rig.channels[channel].get("noise", 0.0)), estimate) or NO_NOISE_FLOOR * float(np.nanstd(values))


def _counted(name: str, counts: dict[str, int]) -> str:
    """"file (channel samples, ...)": what prepare left out of a recording, as its progress and description say."""
    return f"{name} (" + ", ".join(f"{c} {n}" for c, n in counts.items()) + ")"


def prepare(recordings: list[Recording], names: list[str]) -> Data:
    """Check the recordings share one rig and have comparable channels; order them canonically; leave out a
    logger's glitches (glitch.without_glitches) and the repeats of a slower sensor's values it held between them
    (glitch.without_held, on channels not on a grid coarse against their noise); split each into training and
    validation blocks; take each channel's spread and noise."""
    rigs = {r.rig for r in recordings}
    if len(rigs) != 1:
        raise ConfigError(f"recordings of different rigs in one diagnosis: {', '.join(sorted(rigs))}")
    rig = load_rig(rigs.pop())
    prints = [_fingerprint(r) for r in recordings]
    order = sorted(range(len(recordings)), key=lambda i: (names[i], prints[i]))
    recordings, names, prints = [recordings[i] for i in order], [names[i] for i in order], [prints[i] for i in order]
    outputs, commands = set(rig.of_kind("measured")), set(rig.of_kind("command"))
    moved = [on_ticks(r, rig.period_of(r.meta)) for r in recordings]
    recordings = [r for r, _ in moved]
    channels, scale, noise, train, blocks, cleaned, glitched, held = [], [], [], [], [], [], [], []
    for rec, name, fingerprint in zip(recordings, names, prints):
        if rec.time[-1] - rec.time[0] < MIN_SPAN_S:
            raise ConfigError(f"{name}: recording shorter than {MIN_SPAN_S * 1e3:g} ms, too short to simulate")
        sensors, given = [c for c in rec.channels if c in outputs], [c for c in rec.channels if c in commands]
        rec, repeats = without_held(rec, [c for c in sensors if not quantised(
            rec.channels[c], _noise(rig, rec, c, measured_noise(rec.channels[c])))])
        rec, counts = without_glitches(rec, sensors, given, {  # an open loop's commands too: where a kick was
            c: _noise(rig, rec, c, measured_noise(rec.channels[c])) for c in sensors + given})
        cleaned.append(rec)
        held += [_counted(name, repeats)] if repeats else []
        glitched += [_counted(name, counts)] if counts else []
        closed = rec.meta.get("mode", "closed_loop") != "open_loop"
        wanted = outputs | (commands if closed else set())
        chans = [c for c in rec.channels if c in wanted and np.isfinite(rec.channels[c]).sum() > 10
                 and np.nanstd(rec.channels[c]) > 0]  # a constant channel (a locked joint) tells nothing
        if not chans:
            raise ConfigError(f"{name}: no measured channel of rig {rig.name} to compare")
        spread = {c: float(np.nanstd(rec.channels[c])) or 1.0 for c in chans}
        channels.append(chans)
        scale.append(spread)
        noise.append({c: _noise(rig, rec, c, visible_noise(rec.channels[c], spread[c])) for c in chans})
        mask, block = split_blocks(rec.time, int(fingerprint[:8], 16))
        train.append(mask)
        blocks.append(block)
    longer = any(r.time[-1] - r.time[0] > FIT_SECONDS for r in recordings)
    how = (f"every recording in blocks of {min(blocks):.2g}-{max(blocks):.2g} s, half of them (a pseudo-random "
           f"choice fixed by its content) fitted, the other half validate" + (f" (and all after {FIT_SECONDS:g} s)" if longer else "")
           + "; the same regimes in both, whatever the file order")
    jittered = [f"{name} by up to {m * 1e3:.2g} ms" for name, (_, m) in zip(names, moved) if m]
    if jittered:
        how += ("; time stamps moved onto the control loop's ticks (a logger's clock jitter): " + ", ".join(jittered))
    if held:
        how += f"; a slower sensor's values a logger held between its samples compared once: {', '.join(held)}"
    if glitched:
        how += f"; samples far off their neighbours' line left out (a logger's glitches): {', '.join(glitched)}"
    return Data(cleaned, names, rig, channels, scale, noise, train, how, sensor_noise=[dict(n) for n in noise],
                glitches=glitched, held=held)


def in_part(train: np.ndarray, part: str) -> np.ndarray:
    """Sample mask of a part: 'train', 'held_out' (validation) or 'all'."""
    return {"train": train, "held_out": ~train, "all": np.ones_like(train)}[part]


def residual_vector(data: Data, sims: list[Recording], part: str = "train", stride: int = STRIDE,
                    only: int | None = None, unit: str = "spread") -> np.ndarray:
    """(simulated - measured) / spread over a part, every `stride` samples (what the screening compares);
    `unit` "noise": / the channel's noise instead (what the verdict judges; the refit of the rig's
    parameters and the effect fits minimise that, `unit_change`)."""
    pieces = []
    units = data.scale if unit == "spread" else data.noise
    for i, (rec, sim, chans, scale, train) in enumerate(zip(data.recordings, sims, data.channels, units, data.train)):
        mask = in_part(train, part)
        if not mask.any() or (only is not None and i != only):
            continue
        idx = np.flatnonzero(mask)[::stride]
        for c in chans:
            r = (sim.channels[c][idx] - rec.channels[c][idx]) / scale[c]
            pieces.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(pieces) if pieces else np.zeros(0 if only is not None else 1)


def unit_change(data: Data, part: str = "train", stride: int = STRIDE, sims: list[Recording] | None = None) -> np.ndarray:
    """Per element of `residual_vector`: noise / spread, what turns a residual (or a Jacobian's row) in
    noise units into spread units. With `sims`, each channel's unit is its noise or, where larger, the
    RMS residual of `sims` there (weighted least squares with each channel's variance estimated: where
    a model is far above the noise, its own misfit, not the noise, is what a channel's residual scatters
    by; on EMPS, current at 22x its noise and position near it, noise weights put the dry-friction bias
    6.8 % from Janot's, these 4.2 %).

    Why the refit is in noise units (issue 14): in spread units every channel counts by its NRMSE, so
    the cost of a model within the noise is mostly the noise of the noisiest channels relative to their
    spread (Watflex: the 25 Hz camera's 1.7 mm), and a misfit of a precise channel (a strain bridge
    at 2 mV) hardly moves it: on a clean Watflex case the truth's parameters cost 0.13 % less than the
    refit's, below Levenberg-Marquardt's 0.1 % stopping gain, while strain_2A was at 1.52 x its noise
    against 0.93 x at the truth; the verdict judges every channel in noise units, so the refit must too."""
    pieces = []
    for i, (rec, noise, chans, scale, train) in enumerate(zip(data.recordings, data.noise, data.channels, data.scale, data.train)):
        mask = in_part(train, part)
        if not mask.any():
            continue
        n = np.flatnonzero(mask)[::stride].size
        for c in chans:
            misfit = None if sims is None else rms_residual(rec, sims[i], c, mask)
            pieces.append(np.full(n, max(noise[c], misfit or 0.0) / scale[c]))
    return np.concatenate(pieces) if pieces else np.zeros(1)


def noise_alone(data: Data, i: int, channel: str) -> float:
    """The noise (the channel's unit) recording i's `channel` is judged by on its own: its floor with our
    discretisation error counted DISCRETISATION_COUNT times instead of once."""
    step = data.discretisation[i].get(channel, 0.0) if data.discretisation else 0.0
    return float(np.sqrt(data.noise[i][channel] ** 2 + (DISCRETISATION_COUNT**2 - 1.0) * step**2))


def rms_residual(rec: Recording, sim: Recording, channel: str, mask: np.ndarray, least: int = 1) -> float | None:
    """RMS of simulated - measured on `channel` over `mask`'s finite samples (the channel's unit); None
    with fewer than `least` of them."""
    r = (sim.channels[channel] - rec.channels[channel])[mask]
    r = r[np.isfinite(r)]
    return float(np.sqrt(np.mean(r**2))) if r.size >= max(least, 1) else None


