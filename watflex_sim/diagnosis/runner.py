"""Simulation jobs of one diagnosis: re-simulating the recordings with a model, in worker processes.

Contract: every worker holds the diagnosis' `Data` (set once by `Runner`); a job is one recording
simulated with one `Model`. MuJoCo callbacks are process-global, so each process runs one simulation
at a time. A model that diverges gives None, never an exception. Workers ignore Ctrl-C; `Runner`
ends them at once when the diagnosis is interrupted or fails (interrupts.stop_pool).
"""
from __future__ import annotations

import logging
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

from ..engine import SimulationError
from ..interrupts import stop_pool, worker_init
from ..recording import Recording
from ..resim import resimulate
from .data import Data, Model, in_part, residual_vector

log = logging.getLogger(__name__)


def last_time(rec: Recording, train: np.ndarray, part: str) -> float | None:
    """Time (s from the start) after which no sample of `part` is needed: the simulation may stop."""
    if part != "train" or not train.any():
        return None
    return float(rec.time[np.flatnonzero(train)[-1]] - rec.time[0])


def simulate_all(data: Data, model: Model, part: str = "all") -> list[Recording] | None:
    """The recordings re-simulated with `model` (those with samples in `part`; the others are left
    as the measurement itself, contributing nothing); None if a simulation diverged."""
    try:
        return [resimulate(r, model.effects, model.parameters, until=last_time(r, t, part)) if in_part(t, part).any() else r
                for r, t in zip(data.recordings, data.train)]
    except SimulationError as exc:
        log.info("model %s diverged: %s", model, exc)
        return None


_DATA: Data | None = None  # the diagnosis' data in this process (set by `Runner`)


def hold(data: Data) -> None:
    global _DATA
    _DATA = data


def held() -> Data:
    return _DATA


def _residual(model: Model, part: str = "train") -> np.ndarray | None:
    """Residual vector of `model` on a part ('train' or 'all') of this process' data; None if it diverged."""
    sims = simulate_all(_DATA, model, part)
    return None if sims is None else residual_vector(_DATA, sims, part)


def _piece(job: tuple) -> np.ndarray | None:
    """The residual of recording i alone on a part (a piece of _residual); job (model, i[, part])."""
    model, i, part = (*job, "train")[:3]
    rec, train = _DATA.recordings[i], _DATA.train[i]
    if not in_part(train, part).any():
        return np.zeros(0)
    try:
        sim = resimulate(rec, model.effects, model.parameters, until=last_time(rec, train, part))
    except SimulationError:
        return None
    sims = [sim if j == i else r for j, r in enumerate(_DATA.recordings)]  # the others give zeros
    return residual_vector(_DATA, sims, part, only=i)


def _simulate_one(job: tuple) -> Recording | None:
    model, i, noise_seed = (*job, None)[:3]
    try:
        return resimulate(_DATA.recordings[i], model.effects, model.parameters, noise_seed=noise_seed)
    except SimulationError:
        return None


class Runner:
    """Simulation jobs on one diagnosis' data, in `workers` processes, or here when workers <= 1."""

    def __init__(self, data: Data, workers: int, jobs_done=None):
        hold(data)
        self.data = data
        self.jobs_done = jobs_done or (lambda done, total: None)  # progress: (jobs done, jobs in this batch)
        self.jobs = 0  # simulation jobs run so far (a job: one recording, or a model's training part)
        self.pool = (ProcessPoolExecutor(workers, initializer=worker_init, initargs=(hold, data))  # workers ignore Ctrl-C
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

    def simulate(self, model: Model, noise_seed: int | None = None) -> list[Recording] | None:
        """Every recording re-simulated with `model` (one job per recording; with `noise_seed` the rig's
        measurement noise on); None if one diverged."""
        sims = self.map(_simulate_one, [(model, i, noise_seed) for i in range(len(self.data.recordings))])
        return None if any(s is None for s in sims) else sims

    def close(self, abort: bool = False) -> None:
        """Shut the pool down; on `abort` (Ctrl-C, an error) end its processes at once."""
        if self.pool is not None:
            stop_pool(self.pool) if abort else self.pool.shutdown(cancel_futures=True)

    def __enter__(self) -> "Runner":
        return self

    def __exit__(self, kind, *exc) -> None:
        self.close(abort=kind is not None)


def evaluator(runner: Runner | None, part: str = "train"):
    """models -> residual vectors on a part ('train': what fits minimise; 'all': the final refit), in
    the pool (one job per model and recording) or in this process."""
    if runner is None:
        return lambda models: [_residual(m, part) for m in models]

    def evaluate(models):
        n = len(runner.data.recordings)
        pieces = runner.map(_piece, [(m, i, part) for m in models for i in range(n)])
        out = []
        for k in range(len(models)):
            mine = pieces[k * n:(k + 1) * n]
            out.append(None if any(p is None for p in mine) else np.concatenate(mine))
        return out
    return evaluate
