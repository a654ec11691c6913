"""Diagnosis: where simulation and recordings differ, which physics is missing, fitted and shown.

Stages (each in the report): re-simulate every recording with the nominal model; refit the
rig's parameters within their tolerances (rig description); locate the mismatch (channel,
window, regime); fit the catalogue effects the rig allows, in parallel processes, on the
training part of the data; keep the one that improves the held-out part most, if it beats the
noise and a complexity penalty; try a second one on top; explain.
"""
from __future__ import annotations

import logging
import math
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear

from .effects import CATALOGUE
from .engine import SimulationError
from .interrupts import stop_pool, worker_init
from .metrics import correlation, nrmse
from .model import ConfigError
from .recording import Recording
from .resim import resimulate
from .rigdesc import RigDescription, load_rig

log = logging.getLogger(__name__)

MIN_GAIN = 0.02  # training NRMSE must fall by this fraction per fitted parameter, at least
MIN_HELD_GAIN = 0.01  # and the held-out NRMSE must fall by this fraction (data the fit did not see)
NOISE_MARGIN = 1.3  # a fit within this factor of the noise floor leaves nothing to explain
BLOCK_S = 0.5  # s: held-out time blocks when there is a single recording
FIT_SECONDS = 30.0  # s: at most this much of each training recording is fitted; the rest is held out
STRIDE = 4  # samples: residuals are taken every STRIDE samples while fitting


@dataclass
class Model:
    """A candidate model: effects (catalogue entries with parameters) and refit parameter ratios."""

    effects: list[dict] = field(default_factory=list)
    parameters: dict[str, float] = field(default_factory=dict)


@dataclass
class Data:
    """The recordings of one rig, the channels compared, their scales and the train/held-out split."""

    recordings: list[Recording]
    names: list[str]
    rig: RigDescription
    channels: list[list[str]]  # per recording
    scale: list[dict[str, float]]  # per recording: channel -> RMS spread (its unit)
    noise_floor: list[dict[str, float]]  # per recording: channel -> NRMSE noise alone gives
    train: list[np.ndarray]  # per recording: boolean mask of training samples
    how: str = ""


def prepare(recordings: list[Recording], names: list[str]) -> Data:
    """Check the recordings share one rig and have comparable channels; split train/held-out."""
    rigs = {r.rig for r in recordings}
    if len(rigs) != 1:
        raise ConfigError(f"recordings of different rigs in one diagnosis: {', '.join(sorted(rigs))}")
    rig = load_rig(rigs.pop())
    outputs = set(rig.of_kind("measured"))
    channels, scale, floor, train = [], [], [], []
    for rec, name in zip(recordings, names):
        closed = rec.meta.get("mode", "closed_loop") != "open_loop"
        wanted = outputs | (set(rig.of_kind("command")) if closed else set())
        chans = [c for c in rec.channels if c in wanted and np.isfinite(rec.channels[c]).sum() > 10
                 and np.nanstd(rec.channels[c]) > 0]  # a constant channel (a locked joint) tells nothing
        if not chans:
            raise ConfigError(f"{name}: no measured channel of rig {rig.name} to compare")
        if rec.time[-1] - rec.time[0] < 0.05:
            raise ConfigError(f"{name}: recording shorter than 50 ms, too short to simulate")
        spread = {c: float(np.nanstd(rec.channels[c])) or 1.0 for c in chans}
        channels.append(chans)
        scale.append(spread)
        floor.append({c: float(rig.channels[c].get("noise", 0.0)) / spread[c] for c in chans})
    if len(recordings) >= 2:  # the last recording is held out, so every other condition is fitted
        last = len(recordings) - 1
        for i, rec in enumerate(recordings):
            train.append((rec.time - rec.time[0] < FIT_SECONDS) & (i != last))
        longer = any(r.time[-1] - r.time[0] > FIT_SECONDS for r in recordings[:-1])
        how = (f"fit on {', '.join(names[:-1])}" + (f" (their first {FIT_SECONDS:g} s)" if longer else "")
               + f"; judged on {names[-1]}" + (" and the rest of the others" if longer else ""))
    else:
        t = recordings[0].time - recordings[0].time[0]
        train.append((t // BLOCK_S) % 2 == 0)
        how = f"fit on alternate {BLOCK_S:g} s blocks, judged on the blocks in between"
    return Data(recordings, names, rig, channels, scale, floor, train, how)


def simulate_all(data: Data, model: Model, part: str = "all") -> list[Recording] | None:
    """The recordings re-simulated with `model` (those with samples in `part`; the others are left
    as the measurement itself, contributing nothing); None if a simulation diverged."""
    try:
        return [resimulate(r, model.effects, model.parameters, until=_last_time(r, t, part)) if _in_part(t, part).any() else r
                for r, t in zip(data.recordings, data.train)]
    except SimulationError as exc:
        log.info("model %s diverged: %s", model, exc)
        return None


def _last_time(rec: Recording, train: np.ndarray, part: str) -> float | None:
    """Time (s from the start) after which no sample of `part` is needed: the simulation may stop."""
    if part != "train":
        return None
    return float(rec.time[np.flatnonzero(train)[-1]] - rec.time[0])


def _in_part(train: np.ndarray, part: str) -> np.ndarray:
    return {"train": train, "held_out": ~train, "all": np.ones_like(train)}[part]


def residual_vector(data: Data, sims: list[Recording], part: str = "train", stride: int = STRIDE,
                    _only: int | None = None) -> np.ndarray:
    """(simulated - measured) / spread over the chosen part ('train', 'held_out', 'all')."""
    pieces = []
    for i, (rec, sim, chans, scale, train) in enumerate(zip(data.recordings, sims, data.channels, data.scale, data.train)):
        mask = _in_part(train, part)
        if not mask.any() or (_only is not None and i != _only):
            continue
        idx = np.flatnonzero(mask)[::stride]
        for c in chans:
            r = (sim.channels[c][idx] - rec.channels[c][idx]) / scale[c]
            pieces.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(pieces) if pieces else np.zeros(0 if _only is not None else 1)


def fit_scores(data: Data, sims: list[Recording] | None, part: str = "all") -> dict:
    """Mean NRMSE and correlation over channels and recordings (recordings.md), on a part."""
    if sims is None:
        return {"nrmse": math.inf, "correlation": 0.0}
    errors, corrs = [], []
    for rec, sim, chans, train in zip(data.recordings, sims, data.channels, data.train):
        mask = _in_part(train, part)
        if mask.sum() < 10:
            continue
        for c in chans:
            errors.append(nrmse(rec.channels[c][mask], sim.channels[c][mask]))
            corrs.append(correlation(rec.channels[c][mask], sim.channels[c][mask]))
    return {"nrmse": float(np.nanmean(errors)), "correlation": float(np.nanmean(corrs))}


def noise_cost(data: Data) -> float:
    """Expected squared training residual (residual_vector) that measurement noise alone leaves."""
    return float(sum(len(np.flatnonzero(t)[::STRIDE]) * sum(f[c] ** 2 for c in chans)
                     for t, chans, f in zip(data.train, data.channels, data.noise_floor)))


def noise_nrmse(data: Data, part: str = "all") -> float:
    """Mean NRMSE that measurement noise alone leaves (rig description noise levels) on a part,
    averaged like fit_scores."""
    floors = [v for floor, train in zip(data.noise_floor, data.train) if _in_part(train, part).sum() >= 10
              for v in floor.values()]
    return float(np.mean(floors)) if floors else 0.0


# --- running simulations: in a process pool, on the data each worker holds ------------------

_DATA: Data | None = None  # the diagnosis' data in this process (set by `Runner`)


def _hold(data: Data) -> None:
    global _DATA
    _DATA = data


def _train_residual(model: Model) -> np.ndarray | None:
    """Training residual vector of `model` on this process' data; None if it diverged."""
    sims = simulate_all(_DATA, model, "train")
    return None if sims is None else residual_vector(_DATA, sims)


def _train_piece(job: tuple[Model, int]) -> np.ndarray | None:
    """The training residual of recording i alone (a piece of _train_residual)."""
    model, i = job
    rec, train = _DATA.recordings[i], _DATA.train[i]
    if not train.any():
        return np.zeros(0)
    try:
        sim = resimulate(rec, model.effects, model.parameters, until=_last_time(rec, train, "train"))
    except SimulationError:
        return None
    sims = [sim if j == i else r for j, r in enumerate(_DATA.recordings)]  # the others give zeros
    return residual_vector(_DATA, sims, _only=i)


def _simulate_one(job: tuple[Model, int]) -> Recording | None:
    model, i = job
    try:
        return resimulate(_DATA.recordings[i], model.effects, model.parameters)
    except SimulationError:
        return None


class Runner:
    """Simulation jobs on one diagnosis' data, in `workers` processes (MuJoCo callbacks are
    process-global: one simulation per process at a time) or here when workers <= 1."""

    def __init__(self, data: Data, workers: int, jobs_done=None):
        _hold(data)
        self.data = data
        self.jobs_done = jobs_done or (lambda done, total: None)  # progress: (jobs done, jobs in this batch)
        self.jobs = 0  # simulation jobs run so far (a job: one recording, or a model's training part)
        self.pool = (ProcessPoolExecutor(workers, initializer=worker_init, initargs=(_hold, data))  # workers ignore Ctrl-C
                     if workers > 1 else None)

    def map(self, fn, jobs: list) -> list:
        """fn over jobs, in order; reports progress as jobs finish."""
        self.jobs += len(jobs)
        if self.pool is None or len(jobs) <= 1:
            out = []
            for job in jobs:
                out.append(fn(job))
                self.jobs_done(len(out), len(jobs))
            return out
        futures = [self.pool.submit(fn, j) for j in jobs]
        for done, _ in enumerate(as_completed(futures), 1):
            self.jobs_done(done, len(jobs))
        return [f.result() for f in futures]

    def simulate(self, model: Model) -> list[Recording] | None:
        """Every recording re-simulated with `model` (one job per recording); None if one diverged."""
        sims = self.map(_simulate_one, [(model, i) for i in range(len(self.data.recordings))])
        return None if any(s is None for s in sims) else sims

    def close(self, abort: bool = False) -> None:
        if self.pool is not None:
            stop_pool(self.pool) if abort else self.pool.shutdown(cancel_futures=True)  # abort: Ctrl-C, error

    def __enter__(self) -> "Runner":
        return self

    def __exit__(self, *exc) -> None:
        self.close(abort=exc[0] is not None)


# --- fitting: Levenberg-Marquardt on bounded slots, Jacobian from signatures + Broyden ------


@dataclass
class Slot:
    """One fitted number: where it goes in a Model, its bounds and whether it is fitted in log."""

    where: tuple  # ("param", name) or ("effect", index, name | tuple of names tied together)
    low: float
    high: float
    log: bool = False

    def to_internal(self, x: float) -> float:
        return math.log(x) if self.log else x

    def to_value(self, u: float) -> float:
        return math.exp(u) if self.log else u

    def span(self) -> float:
        return math.log(self.high / self.low) if self.log else self.high - self.low


def _unpack(x, free: list[Slot], base: Model) -> Model:
    """Values (physical units) of the free slots -> Model."""
    model = Model([dict(e) for e in base.effects], dict(base.parameters))
    for value, slot in zip(x, free):
        if slot.where[0] == "param":
            model.parameters[slot.where[1]] = float(value)
        else:
            names = slot.where[2] if isinstance(slot.where[2], tuple) else (slot.where[2],)
            for name in names:
                model.effects[slot.where[1]][name] = float(value)
    return model


def _value(model: Model, slot: Slot) -> float:
    if slot.where[0] == "param":
        return model.parameters.get(slot.where[1], 1.0)
    name = slot.where[2][0] if isinstance(slot.where[2], tuple) else slot.where[2]
    return model.effects[slot.where[1]][name]


def rig_slots(data: Data) -> list[Slot]:
    """The rig's refit parameters as slots: ratios within 1 +- tolerance (rigs.md section 4)."""
    return [Slot(("param", n), 1 - p["tolerance"], 1 + p["tolerance"]) for n, p in data.rig.parameters.items()]


def _fd_step(slot: Slot, u: float) -> float:
    """Finite-difference step in internal units: large enough to see through stick-slip."""
    h = 0.1 if slot.log else 0.05 * slot.span()
    hi = slot.to_internal(slot.high)
    return h if u + h <= hi else -h


def jacobian(evaluate, base: Model, free: list[Slot], u: np.ndarray, r: np.ndarray,
             known: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """Columns d(residual)/d(internal value) at u; `known` columns (by slot index) are reused.
    `evaluate(models)` returns the residual vectors (None where a model diverged)."""
    known = dict(known or {})
    todo = [i for i in range(len(free)) if i not in known]
    steps, models = {}, []
    for i in todo:
        steps[i] = _fd_step(free[i], u[i])
        v = u.copy()
        v[i] += steps[i]
        models.append(_unpack([s.to_value(x) for s, x in zip(free, v)], free, base))
    for i, rv in zip(todo, evaluate(models)):
        known[i] = np.zeros_like(r) if rv is None else (rv - r) / steps[i]
    return np.column_stack([known[i] for i in range(len(free))])


def levenberg(evaluate, base: Model, free: list[Slot], x0, J: np.ndarray | None = None,
              iters: int = 6, r0: np.ndarray | None = None, floor: float = 0.0) -> tuple[Model, float, np.ndarray]:
    """Bounded Levenberg-Marquardt on the training residual: the Jacobian is given (signatures)
    or taken by finite differences once, then kept current by Broyden updates, so each
    iteration costs one simulation of the training data. Stops early once the squared residual
    is within 1.2 x `floor` (what noise alone leaves). Returns (model, cost, J)."""
    lo = np.array([s.to_internal(s.low) for s in free])
    hi = np.array([s.to_internal(s.high) for s in free])
    u = np.clip([s.to_internal(x) for s, x in zip(free, x0)], lo, hi)
    model = _unpack([s.to_value(x) for s, x in zip(free, u)], free, base)
    r = r0 if r0 is not None else evaluate([model])[0]
    if r is None:
        raise SimulationError("the starting model diverges")
    if J is None:
        J = jacobian(evaluate, base, free, u, r)
    span = hi - lo
    cost, lam = float(r @ r), 1e-3
    for _ in range(iters):
        if cost <= 1.2 * floor:
            break
        A = J * span
        scale = float(np.mean(np.sum(A * A, axis=0))) or 1.0
        M = np.vstack([A, math.sqrt(lam * scale) * np.eye(len(free))])
        z = lsq_linear(M, np.concatenate([-r, np.zeros(len(free))]), bounds=((lo - u) / span, (hi - u) / span)).x
        step = z * span
        if np.max(np.abs(z)) < 1e-5:
            break
        trial = _unpack([s.to_value(x) for s, x in zip(free, u + step)], free, base)
        r_new = evaluate([trial])[0]
        if r_new is None:
            lam *= 10
            continue
        J = J + np.outer(r_new - r - J @ step, step) / float(step @ step)  # Broyden: the secant we saw
        new = float(r_new @ r_new)
        log.debug("LM: cost %.6g -> %.6g (lambda %.2g, step %s)", cost, new, lam, np.round(z, 4))
        if new < cost:
            u, r, model, gained, cost = u + step, r_new, trial, (cost - new) / cost, new
            lam = max(lam / 5, 1e-6)
            if gained < 1e-3:
                break
        else:
            lam *= 5
    return model, 0.5 * cost, J


def evaluator(runner: Runner | None):
    """models -> training residual vectors: in the pool (one job per model and recording) or in
    this process."""
    if runner is None:
        return lambda models: [_train_residual(m) for m in models]

    def evaluate(models):
        n = len(runner.data.recordings)
        pieces = runner.map(_train_piece, [(m, i) for m in models for i in range(n)])
        out = []
        for k in range(len(models)):
            mine = pieces[k * n:(k + 1) * n]
            out.append(None if any(p is None for p in mine) else np.concatenate(mine))
        return out
    return evaluate


def refit_parameters(data: Data, base: Model, runner: Runner | None = None, J: np.ndarray | None = None,
                     iters: int = 4) -> Model:
    """Refit the rig's parameters within their tolerances (rigs.md section 4) on the training data."""
    free = rig_slots(data)
    if not free:
        return base
    if runner is None:
        _hold(data)
    model, _, _ = levenberg(evaluator(runner), base, free, [_value(base, s) for s in free], J, iters)
    return model


def candidates(rig: RigDescription, have: list[dict]) -> list[tuple[str, str]]:
    """(effect, where) pairs the rig allows and the model does not have yet."""
    taken = {(e["effect"], e["where"]) for e in have}
    return [(effect, where) for effect, places in rig.effects.items() for where in places
            if (effect, where) not in taken]


def _peak(x: np.ndarray) -> float:
    """Robust peak |x| (99.5th percentile, NaN ignored): what a signal reaches, not its outliers."""
    x = np.abs(x[np.isfinite(x)])
    return float(np.percentile(x, 99.5)) if x.size else 0.0


def scale_of(data: Data, param, where: str) -> float:
    """The size a scaled catalogue parameter is measured in (effects.Param.scale), from the data:
    "effort" the peak actuator force or torque, "effort/speed" that over the peak speed,
    "command" the peak of command channel `where`, "channel" the spread of channel `where`,
    "motion" the range of the motion channel."""
    if not param.scale:
        return 1.0
    efforts, speeds, values, ranges = [], [], [], []
    for rec in data.recordings:
        for c in data.rig.of_kind("command"):
            if c in rec.channels:
                efforts.append(_peak(rec.channels[c]) * data.rig.channels[c].get("gain", 1.0))
        motion = _motion_channel(rec, data.rig)
        if motion:
            speeds.append(_peak(np.gradient(rec.channels[motion], rec.time)))
            ranges.append(float(np.nanmax(rec.channels[motion]) - np.nanmin(rec.channels[motion])))
        if where in rec.channels:
            values.append(_peak(rec.channels[where]) if param.scale == "command" else float(np.nanstd(rec.channels[where])))
    effort = max(efforts, default=1.0) or 1.0
    if param.scale == "motion":
        return max(ranges, default=1.0) or 1.0
    if param.scale == "effort":
        return effort
    if param.scale == "effort/speed":
        return effort / (max(speeds, default=1.0) or 1.0)
    return max(values, default=1.0) or 1.0


SWITCH_LEVELS = (1.0, 0.1, 0.01)  # x start of a switch candidate's log-scaled size (width, stiffness, ...)
LARGE_PROBE = 4.0  # x (start - neutral): friction-like levels and `wide` parameters are probed
# small and large, since a small dry friction can move a closed loop the other way from a large
# one (stick-slip is not linear) and a mode frequency goes with the square root of a stiffness


@dataclass
class Candidate:
    """A catalogue effect at one place: its parameters (physical units) with slots, and its
    signature: the change of the training residual per unit of each parameter that has a
    neutral value, or (a 'switch') the change the whole effect at its start values makes.
    Effort-scaled and `wide` parameters are probed at two levels (start and LARGE_PROBE x start)."""

    effect: str
    where: str
    start: dict[str, float]
    slots: dict[str, Slot]
    neutral: dict[str, float]  # parameters with a value at which the effect vanishes
    levels: tuple[float, ...] = (1.0,)
    signature: dict[float, dict[str, np.ndarray]] = field(default_factory=dict)  # level -> parameter -> column
    estimate: dict[str, float] = field(default_factory=dict)  # linear estimate from the best signature
    gain: float = 0.0  # screening: fraction of the training cost the signature explains
    quanta: dict[str, float] = field(default_factory=dict)  # parameters acting in whole steps: the step

    def model(self, base: Model, values: dict[str, float]) -> Model:
        return Model(base.effects + [dict(effect=self.effect, where=self.where, **values)], dict(base.parameters))

    def probes(self) -> dict[tuple[float, str], dict[str, float]]:
        """Parameter sets to simulate: (level, parameter) -> values, one per neutral parameter
        and level, or (1, "switch") with every parameter at its start."""
        if not self.neutral:  # a log-scaled size is probed over two decades below its start
            first = next(iter(self.start))
            levels = SWITCH_LEVELS if self.slots[first].log else (1.0,)
            return {(level, "switch"): {**self.start, first: self.start[first] * level} for level in levels}
        at_zero = {**self.start, **self.neutral}
        return {(level, name): {**at_zero, name: self.probe(name, level)} for level in self.levels for name in self.neutral}

    def probe(self, name: str, level: float = 1.0) -> float:
        """The value a neutral parameter is probed at: level x its start (or 2 % of its range)
        off neutral, within its bounds."""
        slot = self.slots[name]
        step = self.start[name] - self.neutral[name] or 0.02 * (slot.high - slot.low)
        return float(np.clip(self.neutral[name] + level * step, slot.low, slot.high))


def make_candidate(data: Data, effect: str, where: str) -> Candidate:
    _, params, _ = CATALOGUE[effect]
    start, slots, neutral = {}, {}, {}
    for p in params:
        size = scale_of(data, p, where)
        start[p.name] = p.start * size
        slots[p.name] = Slot(("effect", -1, p.name), p.low * size, p.high * size, p.log)
        if p.neutral is not None:
            neutral[p.name] = p.neutral * size
    levels = (1.0, LARGE_PROBE) if any(p.scale == "effort" or p.wide for p in params) else (1.0,)
    quanta = {p.name: p.quantum for p in params if p.quantum > 0}
    return Candidate(effect, where, start, slots, neutral, levels, quanta=quanta)


# --- signatures: which candidate's fingerprint the residual carries ----------------------------


class _Reads(dict):
    """A dict that notes which keys were read (the channels a controller feeds back)."""

    def __init__(self, *args):
        super().__init__(*args)
        self.read = set()

    def __getitem__(self, key):
        self.read.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.read.add(key)
        return super().get(key, default)


def fed_back(data: Data) -> set[str]:
    """Channels some recording's controller reads: a sensor effect there changes the motion."""
    from .engine import ControlLoop
    from .resim import scenario_from_recording

    channels = set()
    for rec in data.recordings:
        scenario = scenario_from_recording(rec)
        scenario["duration_s"] = 0.002
        loop = ControlLoop(scenario, data.rig.parameter_knobs())
        with loop:
            obs = _Reads(loop.rig.observe(loop.references[0]))
            loop.controller(0.0, obs)
        channels |= obs.read
    return channels


def _layout(data: Data, sims: list[Recording], channel: str, stride: int = STRIDE) -> tuple[np.ndarray, np.ndarray]:
    """(entries of the training residual vector that belong to `channel`, simulated value / spread there)."""
    mask, values = [], []
    for rec, sim, chans, scale, train in zip(data.recordings, sims, data.channels, data.scale, data.train):
        idx = np.flatnonzero(train)[::stride]
        if not idx.size:
            continue
        for c in chans:
            mask.append(np.full(idx.size, c == channel))
            values.append(np.nan_to_num(sim.channels[c][idx] / scale[c]) if c == channel else np.zeros(idx.size))
    return np.concatenate(mask), np.concatenate(values)


def sensor_signature(data: Data, sims: list[Recording], cand: Candidate) -> dict[str, np.ndarray]:
    """Signature of a gain or offset on a channel no controller reads, without simulating."""
    mask, values = _layout(data, sims, cand.where)
    if cand.effect == "sensor_offset":
        scale = {c: s for sc in data.scale for c, s in sc.items()}[cand.where]
        return {"offset": mask / scale}
    return {"ratio": values}


def signatures(data: Data, runner: Runner | None, base: Model, sims: list[Recording], r0: np.ndarray,
               cands: list[Candidate]) -> None:
    """Fill each candidate's signature columns: one simulation per probe, in parallel."""
    looped = fed_back(data)
    jobs, owners = [], []
    for cand in cands:
        if cand.effect in ("sensor_gain", "sensor_offset") and cand.where not in looped:
            cand.signature = {1.0: sensor_signature(data, sims, cand)}
            continue
        for key, values in cand.probes().items():
            jobs.append(cand.model(base, values))
            owners.append((cand, key))
    for (cand, (level, name)), r in zip(owners, evaluator(runner)(jobs)):
        if r is None:
            continue  # this probe diverges: no signature at this level
        step = 1.0 if name == "switch" else cand.probe(name, level) - cand.neutral[name]
        cand.signature.setdefault(level, {})[name] = (r - r0) / step


def screen(cands: list[Candidate], rig_columns: np.ndarray, free: list[Slot], at: np.ndarray,
           r0: np.ndarray) -> None:
    """Score each candidate by how much of the training residual its signature explains beyond
    what refitting the rig's parameters explains (bounded linear least squares), and keep the
    linear estimate of its parameters as the start of its fit."""
    cost0 = float(r0 @ r0) or 1.0
    lo = np.array([s.low for s in free]) - at
    hi = np.array([s.high for s in free]) - at

    def solve(columns, low, high):
        norms = np.linalg.norm(columns, axis=0)
        norms[norms == 0] = 1.0
        result = lsq_linear(columns / norms, -r0, bounds=(low * norms, high * norms))
        return float(np.sum((r0 + columns @ (result.x / norms)) ** 2)), result.x / norms

    cost_rig = solve(rig_columns, lo, hi)[0] if free else cost0
    for cand in cands:
        cand.gain, cand.estimate = -math.inf, dict(cand.start)
        for level, columns in cand.signature.items():
            names = list(columns)
            cols = np.column_stack([rig_columns] + [columns[n][:, None] for n in names])
            low = [cand.slots[n].low - cand.neutral[n] if n != "switch" else 0.0 for n in names]
            high = [cand.slots[n].high - cand.neutral[n] if n != "switch" else 3.0 for n in names]
            cost, x = solve(cols, np.r_[lo, low], np.r_[hi, high])
            if (cost_rig - cost) / cost0 <= cand.gain:
                continue
            cand.gain = (cost_rig - cost) / cost0
            cand.estimate = dict(cand.probes()[(level, "switch")]) if "switch" in columns else dict(cand.start)
            for n, a in zip(names, x[len(free):]):
                if n != "switch":
                    slot = cand.slots[n]
                    value = float(np.clip(cand.neutral[n] + a, slot.low, slot.high))
                    cand.estimate[n] = value if value > 0 or not slot.log else cand.start[n]


def effect_slots_of(data: Data, model: Model) -> list[Slot]:
    """Slots of every parameter of the model's effects (catalogue bounds scaled to the data), the
    value clamped inside them."""
    slots = []
    for i, effect in enumerate(model.effects):
        for p in CATALOGUE[effect["effect"]][1]:
            if p.name in effect and not p.quantum:  # a quantised one keeps the step it was found at
                size = scale_of(data, p, effect["where"])
                low, high = min(p.low * size, effect[p.name]), max(p.high * size, effect[p.name])
                slots.append(Slot(("effect", i, p.name), low, high, p.log))
    return slots


QUANTUM_STEPS = 2  # a quantised parameter tries its rounded estimate and this many steps either side


def step_search(evaluate, cand: Candidate, base: Model) -> dict[str, float]:
    """The candidate's start values: its linear estimate, with each quantised parameter (a delay
    in whole control periods has no gradient) set to the best of the rounded estimate and its
    neighbours, never the neutral 0 steps."""
    values = dict(cand.estimate)
    for name, quantum in cand.quanta.items():
        slot, k0 = cand.slots[name], round(values[name] / quantum)
        grid = [k * quantum for k in range(k0 - QUANTUM_STEPS, k0 + QUANTUM_STEPS + 1)
                if k >= 1 and slot.low <= k * quantum <= slot.high]
        if grid:
            costs = [math.inf if r is None else float(r @ r)
                     for r in evaluate([cand.model(base, {**values, name: v}) for v in grid])]
            values[name] = grid[int(np.argmin(costs))]
    return values


def fit_candidate(args) -> dict:
    """Fit one candidate on top of `base` together with the rig's parameters (worker process):
    start at its linear estimate, Jacobian columns of the rig's parameters from the signatures,
    of its own parameters by finite differences there; return its scores."""
    base, cand, rig_columns, iters = args
    data = _DATA
    evaluate = evaluator(None)
    values = step_search(evaluate, cand, base)
    trial = cand.model(base, values)
    index = len(trial.effects) - 1
    fitted_names = [n for n in cand.slots if n not in cand.quanta]  # a quantised one stays at its step
    effect_slots = [Slot(("effect", index, n), cand.slots[n].low, cand.slots[n].high, cand.slots[n].log) for n in fitted_names]
    earlier = effect_slots_of(data, base)  # the effects found before are refit with it
    free = effect_slots + earlier + rig_slots(data)
    x0 = [values[n] for n in fitted_names] + [_value(base, s) for s in earlier + rig_slots(data)]
    try:
        lo = np.array([s.to_internal(s.low) for s in free])
        u0 = np.clip([s.to_internal(x) for s, x in zip(free, x0)], lo, [s.to_internal(s.high) for s in free])
        r = evaluate([_unpack([s.to_value(x) for s, x in zip(free, u0)], free, trial)])[0]
        if r is None:
            return {"effect": cand.effect, "where": cand.where, "error": "diverges at its starting values"}
        known = {len(effect_slots) + len(earlier) + i: rig_columns[:, i] for i in range(rig_columns.shape[1])}
        J = jacobian(evaluate, trial, free, u0, r, known)
        model, cost, J = levenberg(evaluate, trial, free, [s.to_value(x) for s, x in zip(free, u0)], J, iters, r,
                                   noise_cost(data))
    except Exception as exc:  # noqa: BLE001 - a candidate that fails is dropped and reported, never fatal
        return {"effect": cand.effect, "where": cand.where, "error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"}
    sims = simulate_all(data, model)
    if sims is None:
        return {"effect": cand.effect, "where": cand.where, "error": "the fitted model diverges"}
    return {"effect": cand.effect, "where": cand.where, "model": model, "n_params": len(cand.slots), "cost": cost,
            "train": fit_scores(data, sims, "train"), "held_out": fit_scores(data, sims, "held_out"),
            "all": fit_scores(data, sims, "all"), "sims": sims, "screen_gain": cand.gain, "free": free, "J": J}


def offset_alternative(data: Data, runner: Runner | None, base: Model, result: dict, train_now: float,
                       held: float) -> dict | None:
    """Asymmetric Coulomb levels a (positive) != b (negative) are also symmetric friction plus a
    constant actuator bias f = (b - a)/2 pushing the positive way: the two cannot be told apart
    in steady sliding, only at rest. Fit that alternative (as many parameters) jointly with the
    rig's parameters and return it scored like a candidate, or None if it does not apply."""
    if result["effect"] != "coulomb_friction":
        return None
    found = result["model"].effects[-1]
    a, b, where = found["torque_positive"], found["torque_negative"], found["where"]
    channel = next((c for c in data.rig.effects.get("actuator_offset", [])
                    if data.rig.channels.get(c, {}).get("joint") == where), None)
    if channel is None or abs(a - b) <= 0.05 * (a + b) / 2:
        return None
    gain = data.rig.channels[channel].get("gain", 1.0)
    trial = Model(base.effects + [dict(effect="coulomb_friction", where=where, torque_positive=(a + b) / 2, torque_negative=(a + b) / 2),
                                  dict(effect="actuator_offset", where=channel, offset=(b - a) / 2 / gain)],
                  dict(result["model"].parameters))
    i = len(trial.effects) - 2
    free = [Slot(("effect", i, ("torque_positive", "torque_negative")), 0.0, 2 * max(a, b)),
            Slot(("effect", i + 1, "offset"), -2 * abs(a - b) / gain, 2 * abs(a - b) / gain)] + rig_slots(data)
    x0 = [(a + b) / 2, (b - a) / 2 / gain] + [_value(trial, s) for s in rig_slots(data)]
    try:
        model, _, _ = levenberg(evaluator(runner), trial, free, x0, iters=12, floor=noise_cost(data))
    except SimulationError:
        return None
    sims = runner.simulate(model) if runner else simulate_all(data, model)
    if sims is None:
        return None
    train, held_out = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    out = {"effect": "coulomb_friction", "where": where, "model": model, "n_params": 2, "train": train,
           "held_out": held_out, "train_gain": (train_now - train["nrmse"]) / train_now,
           "held_gain": (held - held_out["nrmse"]) / held, "sims": sims}
    out["score"] = out["train_gain"] + out["held_gain"] - MIN_GAIN * 2
    return out


# --- where the mismatch is -------------------------------------------------------------------

WINDOW_S = 0.05  # s, moving-RMS window of the residual


def _motion_channel(rec: Recording, rig: RigDescription) -> str | None:
    """The measured joint position (rad or m) that moves most in the recording: what 'motion' means."""
    positions = [c for c in rig.of_kind("measured") if c in rec.channels
                 and rig.channels[c]["unit"] in ("rad", "m") and not c.startswith("tip_")]
    return max(positions, key=lambda c: float(np.nanstd(rec.channels[c])), default=None)


def regimes(rec: Recording, rig: RigDescription, i0: int, i1: int) -> str:
    """Words for what the rig was doing in samples i0..i1: direction, rest, reversal, saturation."""
    words = []
    motion = _motion_channel(rec, rig)
    if motion:
        q = rec.channels[motion]
        dt = float(np.median(np.diff(rec.time)))
        v = np.gradient(q, dt)[i0:i1]
        span = float(np.nanmax(np.abs(np.gradient(q, dt)))) or 1.0
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


def locate(data: Data, sims: list[Recording], top: int = 8) -> list[dict]:
    """Windows where the residual stands out of the noise: recording, channel, times (s), regime, score.

    score = RMS residual in the window / channel spread (a local NRMSE)."""
    found = []
    for rec, sim, name, chans, scale, floor in zip(data.recordings, sims, data.names, data.channels,
                                                   data.scale, data.noise_floor):
        dt = float(np.median(np.diff(rec.time)))
        width = max(3, int(WINDOW_S / dt))
        kernel = np.ones(width) / width
        for c in chans:
            r = np.nan_to_num((sim.channels[c] - rec.channels[c]) / scale[c])
            rms = np.sqrt(np.convolve(r**2, kernel, mode="same"))
            threshold = max(3 * floor[c], 0.5 * float(np.sqrt(np.mean(r**2))), 1e-3)
            hot = rms > threshold
            edges = np.flatnonzero(np.diff(np.r_[0, hot.astype(int), 0]))
            for i0, i1 in zip(edges[::2], edges[1::2]):
                if i1 - i0 < width:
                    continue
                found.append({"recording": name, "channel": c, "t_start": float(rec.time[i0]),
                              "t_end": float(rec.time[i1 - 1]), "regime": regimes(rec, data.rig, i0, i1),
                              "score": float(np.sqrt(np.mean(r[i0:i1] ** 2)))})
    found.sort(key=lambda w: -w["score"])
    return found[:top]


# --- the whole diagnosis ---------------------------------------------------------------------

EXPLAIN = {
    "coulomb_friction": "dry friction at {where}: the joint sticks below {torque_positive:.3g} (positive) / {torque_negative:.3g} (negative) and slides against that level",
    "stribeck_friction": "break-away at {where} above the sliding level by {breakaway_positive:.3g} / {breakaway_negative:.3g}, decaying with speed (v_s {v_s:.3g})",
    "viscous_friction": "extra viscous friction at {where}: {coefficient:.4g} (positive) / {coefficient_negative:.4g} (negative motion) per unit speed",
    "presliding": "elastic pre-sliding at {where} (bristle stiffness {sigma0:.3g}, damping {sigma1:.3g})",
    "dwell_time_stiction": "break-away at {where} grows with time at rest (gain {gain:.3g}, time constant {time_constant:.3g} s)",
    "position_dependent_friction": "a torque at {where} that varies with angle (amplitude {amplitude:.3g}, period {period:.3g}, spring {spring:.3g})",
    "backlash": "a dead band of {width:.3g} rad between {where} and its link, the link starting at {position:+.2f} of its half-width (a band that opens one way only reads as slip in that direction)",
    "joint_compliance": "a torsional spring of {stiffness:.4g} between {where} and its link",
    "payload": "a tip mass {mass:+.3g} kg different from the declared payload",
    "link_stiffness_change": "bending stiffness of {where} at {ratio:.3g} x the datasheet",
    "structural_damping": "beam damping of {where} at {ratio:.3g} x nominal",
    "actuator_gain": "{where} acts with {ratio:.4g} x the commanded value",
    "actuator_offset": "a constant bias of {offset:+.4g} on {where}",
    "current_saturation": "{where} saturates at +-{limit:.3g}",
    "sensor_gain": "{where} reads {ratio:.4g} x the true value",
    "sensor_offset": "{where} reads {offset:+.4g} off",
    "delay": "a transport delay of {seconds:.3g} s on {where}",
    "bearing_friction": "an air bearing touching down: {force:.3g} N sliding friction at {where}",
    "table_tilt": "the table tilted by {angle:.3g} rad",
}


def _explain(effect: str, where: str, params: dict) -> str:
    return EXPLAIN[effect].format(where=where, **{**{p.name: p.start for p in CATALOGUE[effect][1]}, **params})


def _finding(result: dict, model: Model, before: float, after: float, mismatch: list[dict],
             train_before: float = math.nan) -> dict:
    effect = next(e for e in model.effects if e["effect"] == result["effect"] and e["where"] == result["where"])
    params = {k: v for k, v in effect.items() if k not in ("effect", "where")}
    units = {p.name: p.unit for p in CATALOGUE[result["effect"]][1]}
    direction = "both"
    if "torque_positive" in params or "breakaway_positive" in params or "coefficient_negative" in params:
        a, b = list(params.values())[:2]
        direction = "both" if abs(a - b) <= 0.1 * max(abs(a), abs(b), 1e-12) else ("positive" if abs(a) > abs(b) else "negative")
    if "position" in params and abs(params["position"]) > 0.5:  # a band that opens one way only
        direction = "positive" if params["position"] > 0 else "negative"
    hot = [w for w in mismatch][:3]
    evidence = "; ".join(f"{w['channel']} off by {w['score']:.2f} of its spread in {w['recording']} "
                         f"{w['t_start']:.2f}-{w['t_end']:.2f} s ({w['regime']})" for w in hot)
    return {
        "effect": result["effect"], "where": result["where"], "direction": direction,
        "parameters": params, "units": {k: units.get(k, "") for k in params},
        "explanation": _explain(result["effect"], result["where"], params),
        "evidence": (f"residual: {evidence}. " if evidence else "") +
                    f"With this effect fitted: training NRMSE {train_before:.4f} -> {result['train']['nrmse']:.4f}, "
                    f"held-out {before:.4f} -> {after:.4f}.",
        "delta_fit": before - after,
    }


def excited(data: Data, effect: str, where: str) -> bool:
    """False when the recordings cannot show `effect` at `where`: a joint locked or still in every
    recording, a command channel that is constant, a sensor channel not compared."""
    kind = CATALOGUE[effect][2]
    compared = {c for chans in data.channels for c in chans}
    if kind == "joint":
        angles = [c for c, spec in data.rig.channels.items() if spec["kind"] == "measured"
                  and (c == f"{where}_angle" or spec.get("joint") == where)]
        commands = [c for c in data.rig.of_kind("command") if data.rig.channels[c].get("joint") == where]
        moving = [c for c in angles + commands if any(c in chans for chans in data.channels)]
        return bool(moving) or not (angles or commands)
    if kind == "command" and effect != "delay":
        return where in compared
    if kind == "channel" or (effect == "delay" and where != "command"):
        return where in compared
    return True


def _prune(data: Data, pairs: list[tuple[str, str]]) -> list[tuple[str, str]]:
    return [(e, w) for e, w in pairs if excited(data, e, w)]


SCREEN_TOP = 2  # candidates fitted in full after the signature screening (one per worker)
SCREEN_TIE = 0.95  # ... and any more that screen within 5 % of the last of those: a tie in the
SCREEN_MAX = 4  # screening is no evidence (up to this many; friction laws often screen alike)
FIT_ITERATIONS = 6  # Levenberg-Marquardt iterations of a candidate fit (one simulation each)


def shortlist(ranked: list[Candidate], screen_top: int = SCREEN_TOP) -> list[Candidate]:
    """The candidates to fit in full, from those ranked by screening gain: the first `screen_top`
    that explain anything, and any more (to SCREEN_MAX) within SCREEN_TIE of the last of them."""
    top = [c for c in ranked[:screen_top] if c.gain > 0]
    return top + [c for c in ranked[screen_top:SCREEN_MAX] if top and c.gain >= SCREEN_TIE * top[-1].gain]


def diagnose(recordings: list[Recording], names: list[str], workers: int = 2, max_effects: int = 2,
             screen_top: int = SCREEN_TOP, progress=None, jobs_done=None) -> dict:
    """Run the whole diagnosis; return the report (recordings.md schema) plus 'sims' for plotting.

    `progress(message)` hears each stage, `jobs_done(done, total)` each finished simulation job
    of a stage. Raises ConfigError for recordings that cannot be diagnosed together.
    """
    data = prepare(recordings, names)
    with Runner(data, workers, jobs_done) as runner:
        stages = Stages(progress or (lambda message: None), runner)
        report = _diagnose(data, runner, max_effects, screen_top, stages)
        stages("done", "done")
        report["timing"] = stages.table
        return report


class Stages:
    """Names the stage in progress, tells the user, and adds up wall time (s) and simulation
    jobs per kind of stage (the report's "timing"; a job is one simulation, or a whole candidate fit)."""

    def __init__(self, say, runner: Runner):
        self.say, self.runner = say, runner
        self.table: dict[str, dict[str, float]] = {}
        self.kind, self.t0, self.jobs0 = None, time.perf_counter(), 0

    def __call__(self, kind: str, message: str) -> None:
        now = time.perf_counter()
        if self.kind is not None:
            row = self.table.setdefault(self.kind, {"seconds": 0.0, "jobs": 0})
            row["seconds"] += now - self.t0
            row["jobs"] += self.runner.jobs - self.jobs0
        self.kind, self.t0, self.jobs0 = kind, now, self.runner.jobs
        if kind != "done":
            self.say(message)


def _diagnose(data: Data, runner: Runner, max_effects: int, screen_top: int, say: Stages) -> dict:
    evaluate = evaluator(runner)
    say("nominal", "re-simulating with the nominal model")
    nominal = Model()
    sims_nominal = runner.simulate(nominal)
    if sims_nominal is None:
        raise ConfigError("the nominal model diverges on these recordings")
    free = rig_slots(data)
    r_nominal = residual_vector(data, sims_nominal)
    say("refit", f"refitting the {len(free)} nominal parameters within their tolerances")
    at = np.array([_value(nominal, s) for s in free])
    rig_columns = jacobian(evaluate, nominal, free, at, r_nominal) if free else np.zeros((r_nominal.size, 0))
    current, _, _ = (levenberg(evaluate, nominal, free, at, rig_columns, 4, r_nominal, noise_cost(data)) if free
                     else (nominal, 0, None))
    sims = runner.simulate(current)
    if sims is None or fit_scores(data, sims, "held_out")["nrmse"] > fit_scores(data, sims_nominal, "held_out")["nrmse"]:
        # a refit must earn its place on held-out data too: parameters pulled off their
        # datasheet values to absorb an unmodelled effect would hide that effect
        current, sims = nominal, sims_nominal
    steps = [{"model": "nominal", **_scores(data, sims_nominal, nominal)}, {"model": "parameters refit", **_scores(data, sims, current)}]
    mismatch = locate(data, sims)
    noise, noise_train, noise_held = noise_nrmse(data), noise_nrmse(data, "train"), noise_nrmse(data, "held_out")
    held = fit_scores(data, sims, "held_out")["nrmse"]
    findings, rejected, screened_report, fitted_report = [], [], [], []
    for round_ in range(max_effects):
        train_now = fit_scores(data, sims, "train")["nrmse"]
        if held <= NOISE_MARGIN * noise_held or train_now <= NOISE_MARGIN * noise_train:
            say("verdict", f"NRMSE (held-out {held:.4f}, training {train_now:.4f}) within {NOISE_MARGIN:g} x what noise leaves "
                f"({noise_held:.4f}, {noise_train:.4f}): nothing left to explain")
            break
        r0 = residual_vector(data, sims)
        pairs = _prune(data, candidates(data.rig, current.effects))
        # signatures are taken around the current model: an effect can look different once
        # another is in (a slip shows only where stiction lets the joint move)
        live = [make_candidate(data, e, w) for e, w in pairs]
        say("signatures", f"round {round_ + 1}: taking the signatures of {len(live)} candidate effects "
            f"({sum(len(c.probes()) for c in live)} probe simulations)")
        signatures(data, runner, current, sims, r0, live)
        at = np.array([_value(current, s) for s in free])
        screen(live, rig_columns, free, at, r0)
        live.sort(key=lambda c: -c.gain)
        screened_report.append([{"effect": c.effect, "where": c.where, "explained": round(c.gain, 4)} for c in live[:8]])
        top = shortlist(live, screen_top)
        if not top:
            break
        say("candidate fits", f"round {round_ + 1}: fitting the {len(top)} whose signatures match the residual best: "
            + ", ".join(f"{c.effect}@{c.where} ({100 * c.gain:.0f} %)" for c in top))
        results = runner.map(fit_candidate, [(current, c, rig_columns, FIT_ITERATIONS) for c in top])
        for r in results:
            if "error" in r:
                rejected.append({"effect": r["effect"], "where": r["where"], "error": r["error"]})
        fitted = [r for r in results if "error" not in r]
        if not fitted:
            break
        for r in fitted:  # relative improvements, and a score that charges every parameter
            r["train_gain"] = (train_now - r["train"]["nrmse"]) / train_now
            r["held_gain"] = (held - r["held_out"]["nrmse"]) / held
            r["score"] = r["train_gain"] + r["held_gain"] - MIN_GAIN * r["n_params"]
        fitted.sort(key=lambda r: -r["score"])
        fitted_report.append([{"effect": r["effect"], "where": r["where"], "parameters": r["n_params"],
                               "train_gain": round(r["train_gain"], 4), "held_out_gain": round(r["held_gain"], 4),
                               "score": round(r["score"], 4)} for r in fitted])
        best = fitted[0]
        if best["train_gain"] < MIN_GAIN * best["n_params"] or best["held_gain"] < MIN_HELD_GAIN:
            rejected.append({"effect": best["effect"], "where": best["where"], "train_gain": best["train_gain"],
                             "held_out_gain": best["held_gain"]})
            break
        say("polish", f"round {round_ + 1}: polishing {best['effect']} at {best['where']} and trying alternatives")
        best = polish(data, runner, best, held)
        alternative = offset_alternative(data, runner, current, best, train_now, held)
        if alternative is not None and alternative["score"] >= best["score"] - 1e-3:
            say("verdict", "asymmetric Coulomb friction is better explained as symmetric friction plus an actuator offset")
            findings.append(_finding(alternative, alternative["model"], held, alternative["held_out"]["nrmse"], mismatch, train_now))
            offset = {**alternative, "effect": "actuator_offset", "where": alternative["model"].effects[-1]["where"]}
            findings.append(_finding(offset, alternative["model"], held, alternative["held_out"]["nrmse"], mismatch, train_now))
            best = alternative
        else:
            findings.append(_finding(best, best["model"], held, best["held_out"]["nrmse"], mismatch, train_now))
        say("verdict", f"round {round_ + 1}: found {best['effect']} at {best['where']}: held-out NRMSE {held:.4f} -> {best['held_out']['nrmse']:.4f}")
        current, sims = best["model"], best["sims"]
        held = best["held_out"]["nrmse"]
        steps.append({"model": f"+ {best['effect']} at {best['where']}", **_scores(data, sims, current)})
        mismatch = locate(data, sims) or mismatch
    for f in findings:  # the parameters as refit together in the final model
        final = next((e for e in current.effects if e["effect"] == f["effect"] and e["where"] == f["where"]), None)
        if final is not None:
            f["parameters"] = {k: v for k, v in final.items() if k not in ("effect", "where")}
            f["explanation"] = _explain(f["effect"], f["where"], f["parameters"])
    before_mismatch = locate(data, sims_nominal)
    return {
        "format": "flexarm-diagnosis/1",
        "rig": data.rig.name,
        "recordings": data.names,
        "mismatch": before_mismatch,
        "findings": findings,
        "fit_before": fit_scores(data, sims_nominal, "all"),
        "fit_after": fit_scores(data, sims, "all"),
        "held_out": {"before": fit_scores(data, sims_nominal, "held_out"), "after": fit_scores(data, sims, "held_out"),
                     "how": data.how},
        "refit_parameters": {n: current.parameters[n] for n in current.parameters},
        "noise_nrmse": noise,
        "steps": steps,
        "screening": screened_report,
        "candidates": fitted_report,
        "rejected": rejected,
        "patch": {"effects": current.effects, "parameters": current.parameters},
        "sims": {"nominal": sims_nominal, "final": sims},
    }


POLISH_ITERATIONS = 6


def polish(data: Data, runner: Runner, result: dict, held: float) -> dict:
    """Carry the chosen candidate's fit on from a fresh finite-difference Jacobian at its
    solution, each simulation split over the workers; keep it if the training fit improved."""
    free = result["free"]
    model, cost, _ = levenberg(evaluator(runner), result["model"], free, [_value(result["model"], s) for s in free],
                               None, POLISH_ITERATIONS, floor=noise_cost(data))
    if cost >= result["cost"]:
        return result
    sims = runner.simulate(model)
    if sims is None:
        return result
    train_before = result["train"]["nrmse"] / (1 - result["train_gain"])
    out = {**result, "model": model, "cost": cost, "sims": sims, "train": fit_scores(data, sims, "train"),
           "held_out": fit_scores(data, sims, "held_out"), "all": fit_scores(data, sims, "all")}
    out["train_gain"] = (train_before - out["train"]["nrmse"]) / train_before
    out["held_gain"] = (held - out["held_out"]["nrmse"]) / held
    return out


def _scores(data: Data, sims: list[Recording], model: Model) -> dict:
    """One stage of the report's 'steps': training and held-out NRMSE, and the model (effects and
    parameter ratios) to re-simulate it."""
    return {"train_nrmse": fit_scores(data, sims, "train")["nrmse"], "held_out_nrmse": fit_scores(data, sims, "held_out")["nrmse"],
            "effects": [dict(e) for e in model.effects], "parameters": dict(model.parameters)}
