"""Simulation jobs of one diagnosis: re-simulating the recordings with a model, in lockstep.

Contract: every worker holds the diagnosis' `Data` (set once by `Runner`); a job is one recording
simulated with one `Model`. The jobs of one call (every recording, for one or several models) run
together in lockstep (resim.resimulate_many, one mujoco.batch.Batch per model structure; a group too small
for a batch to pay, one by one: lockstep._pays); with
worker processes they are split into one contiguous share per worker, each stepped on one thread
(the batch's Python control half is single-threaded, so processes still pay on 2 cores). Several fits
running at once (the candidate fits, each in a thread of the main process) put their calls together through
`Gathered`. Every simulation runs `Runner.fidelity` x as fine as the rig's model (resim.finer_discretisation's
factor; 1 unless fidelity.choose_fidelity found a coarser one as good against the noise), and a call's `finer` is
relative to that. A model that diverges gives None, never an exception. Workers ignore Ctrl-C; `Runner` ends them at once
when the diagnosis is interrupted or fails (interrupts.stop_pool).
"""
from __future__ import annotations

import logging
import multiprocessing
import threading
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

from ..engine import SimulationError
from ..interrupts import stop_pool, worker_init
from ..latest import Latest
from ..recording import Recording
from ..resim import finer_discretisation, resimulate_many, scenario_from_recording
from .data import Data, Model, in_part, residual_vector

log = logging.getLogger(__name__)

MEMO_BYTES = 64e6  # residuals kept by the runner, the latest (Runner.remember): 0.1 MB each for three 6 s recordings


def last_time(rec: Recording, train: np.ndarray, part: str) -> float | None:
    """Time (s from the start) after which no sample of `part` is needed: the simulation may stop."""
    if part != "train" or not train.any():
        return None
    return float(rec.time[np.flatnonzero(train)[-1]] - rec.time[0])


def simulate_all(data: Data, model: Model, part: str = "all") -> list[Recording] | None:
    """The recordings re-simulated with `model` (those with samples in `part`; the others are left
    as the measurement itself, contributing nothing); None if a simulation diverged."""
    wanted = [i for i, t in enumerate(data.train) if in_part(t, part).any()]
    sims = resimulate_many([(data.recordings[i], model.effects, model.parameters,
                             last_time(data.recordings[i], data.train[i], part)) for i in wanted], _threads(), data.rig)
    failed = next((s for s in sims if isinstance(s, SimulationError)), None)
    if failed is not None:
        log.info("model %s diverged: %s", model, failed)
        return None
    out = list(data.recordings)
    for i, sim in zip(wanted, sims):
        out[i] = sim
    return out


def _threads() -> int:
    """Batch threads here: one in a worker process (the workers share the CPUs), else all CPUs (0)."""
    return 1 if multiprocessing.parent_process() is not None else 0


_DATA: Data | None = None  # the diagnosis' data in this process (set by `Runner`)


def hold(data: Data) -> None:
    global _DATA
    _DATA = data


def held() -> Data:
    return _DATA


def _residual(model: Model, part: str = "train", unit: str = "spread") -> np.ndarray | None:
    """Residual vector of `model` on a part ('train' or 'all') of this process' data, in `unit` (spread or
    noise, data.residual_vector); None if it diverged."""
    sims = simulate_all(_DATA, model, part)
    return None if sims is None else residual_vector(_DATA, sims, part, unit=unit)


def _pieces(jobs: list[tuple], nthread: int = 1) -> list[np.ndarray | None]:
    """The residual of recording i alone on a part (a piece of _residual) for each job (model, i, part, unit,
    finer: resim.finer_discretisation's factor), all simulated in lockstep; None for a job whose simulation diverged."""
    todo = [k for k, (_m, i, part, _u, _f) in enumerate(jobs) if in_part(_DATA.train[i], part).any()]
    sims = resimulate_many([(_DATA.recordings[jobs[k][1]], jobs[k][0].effects, jobs[k][0].parameters,
                             last_time(_DATA.recordings[jobs[k][1]], _DATA.train[jobs[k][1]], jobs[k][2]), None,
                             jobs[k][4]) for k in todo], nthread, _DATA.rig)
    out: list = [np.zeros(0)] * len(jobs)
    for k, sim in zip(todo, sims):
        _m, i, part, unit, _f = jobs[k]
        if isinstance(sim, SimulationError):
            out[k] = None
            continue
        recs = [sim if j == i else r for j, r in enumerate(_DATA.recordings)]  # the others give zeros
        out[k] = residual_vector(_DATA, recs, part, only=i, unit=unit)
    return out


def _simulate_some(jobs: list[tuple], nthread: int = 1) -> list[Recording | None]:
    """Recordings i re-simulated with their models, jobs (model, i, noise_seed, finer), in lockstep."""
    sims = resimulate_many([(_DATA.recordings[i], m.effects, m.parameters, None, seed, finer)
                            for m, i, seed, finer in jobs], nthread, _DATA.rig)
    return [None if isinstance(s, SimulationError) else s for s in sims]


class Runner:
    """Simulation jobs on one diagnosis' data, in `workers` processes, or here when workers <= 1."""

    def __init__(self, data: Data, workers: int, jobs_done=None):
        hold(data)
        self.data = data
        self.jobs_done = jobs_done or (lambda done, total: None)  # progress: (jobs done, jobs in this batch)
        self.jobs = 0  # simulation jobs run so far (a job: one recording, or a model's training part)
        self.fidelity = 1.0  # every simulation this many times as fine as the rig's model (fidelity.choose_fidelity)
        self.workers = workers if workers > 1 else 1
        self.memo = Latest(MEMO_BYTES, lambda residual: 0 if residual is None else residual.nbytes)  # see remember
        self.pool = (ProcessPoolExecutor(workers, initializer=worker_init, initargs=(hold, data))  # workers ignore Ctrl-C
                     if workers > 1 else None)

    def remember(self, key: tuple, residual: np.ndarray | None) -> None:
        """Keep a model's residual (`evaluator`'s key: the model, part, unit and fidelity; None: it diverged) among the
        latest MEMO_BYTES: a fit asks again for a model it has just simulated (a carried-on fit's start, a scan's given
        values, a step search's rounded start), ~4 % of a diagnosis' simulations and most of them a call of their own."""
        self.memo.put(key, residual)

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

    def refinable(self, factor: float) -> bool:
        """Whether simulating `factor` x finer (below 1: coarser) than the runner's fidelity changes the model of
        some recording: its segments or its step (resim.finer_discretisation)."""
        scenarios = [scenario_from_recording(r, self.data.rig) for r in self.data.recordings]
        return any(finer_discretisation(self.data.rig, s, factor * self.fidelity)
                   != finer_discretisation(self.data.rig, s, self.fidelity) for s in scenarios)

    def simulate(self, model: Model, noise_seed: int | None = None, finer: float = 1) -> list[Recording] | None:
        """Every recording re-simulated with `model` (in lockstep; with `noise_seed` the rig's
        measurement noise on; `finer` x finer segments and step, resim.finer_discretisation); None if
        one diverged."""
        return self.simulate_seeds(model, [noise_seed], finer)[0]

    def simulate_seeds(self, model: Model, seeds: list[int | None], finer: float = 1) -> list[list[Recording] | None]:
        """`simulate` once per noise seed (None: noise off), all in one lockstep call; `finer` relative to the fidelity."""
        return self.simulate_runs([(model, seed) for seed in seeds], finer)

    def simulate_models(self, models: list[Model], finer: float = 1) -> list[list[Recording] | None]:
        """`simulate` for each model (noise off), all in one lockstep call; `finer` relative to the fidelity."""
        return self.simulate_runs([(model, None) for model in models], finer)

    def simulate_runs(self, runs: list[tuple[Model, int | None]], finer: float = 1) -> list[list[Recording] | None]:
        """`simulate` for each (model, noise seed), all in one lockstep call; `finer` relative to the fidelity."""
        n = len(self.data.recordings)
        factor = finer * self.fidelity
        sims = self.lockstep(_simulate_some, [(model, i, seed, factor) for model, seed in runs for i in range(n)])
        return [None if any(s is None for s in sims[k * n:(k + 1) * n]) else sims[k * n:(k + 1) * n]
                for k in range(len(runs))]

    def lockstep(self, fn, jobs: list) -> list:
        """fn(jobs share) -> a result per job, over one share per worker (here: one, on all threads)."""
        if self.pool is None or len(jobs) <= 1:
            self.jobs += len(jobs)
            out = fn(jobs, 0)
            self.jobs_done(len(jobs), len(jobs))
            return out
        n = min(self.workers, len(jobs))
        bounds = np.linspace(0, len(jobs), n + 1).round().astype(int)
        shares = [jobs[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
        done = self.map(fn, shares)
        self.jobs += len(jobs) - len(shares)
        return [r for share in done for r in share]

    def close(self, abort: bool = False) -> None:
        """Shut the pool down; on `abort` (Ctrl-C, an error) end its processes at once."""
        if self.pool is not None:
            stop_pool(self.pool) if abort else self.pool.shutdown(cancel_futures=True)

    def __enter__(self) -> "Runner":
        return self

    def __exit__(self, kind, *exc) -> None:
        self.close(abort=kind is not None)


def evaluator(runner: Runner | None, part: str = "train", unit: str = "spread", finer: float = 1):
    """models -> residual vectors on a part ('train': what fits minimise; 'all': the final refit) in `unit`
    ('spread', or 'noise': the refit of the rig's parameters), in the pool (one job per model and
    recording) or in this process. The workers' noise is the data's when the Runner started. `finer`:
    the models simulated that many times finer than the runner's fidelity (below 1: coarser;
    resim.finer_discretisation; with a Runner)."""
    if runner is None:
        return lambda models: [_residual(m, part, unit) for m in models]

    def evaluate(models):
        n = len(runner.data.recordings)
        factor = finer * runner.fidelity
        here = () if runner.pool else (id(held()), repr(held().noise) if unit == "noise" else "")  # this process' data
        keys = [(repr(m.effects), repr(sorted(m.parameters.items())), part, unit, factor, *here) for m in models]
        known = {key: runner.memo.get(key) for key in keys if key in runner.memo}
        todo = list({key: m for key, m in zip(keys, models) if key not in known}.items())
        pieces = runner.lockstep(_pieces, [(m, i, part, unit, factor) for _, m in todo for i in range(n)]) if todo else []
        for k, (key, _) in enumerate(todo):
            mine = pieces[k * n:(k + 1) * n]
            known[key] = None if any(p is None for p in mine) else np.concatenate(mine)
            runner.remember(key, known[key])
        return [None if known[key] is None else known[key].copy() for key in keys]
    return evaluate


class Gathered:
    """One evaluator shared by `n` threads (the candidate fits, effect_fit.fit_candidates): a call waits until every
    thread still running has called, then all their models go to `evaluate` together - one lockstep call over the
    workers, so a fit that simulates little, or has ended, leaves no worker idle. Call k of each thread goes with
    call k of the others, in thread order: the same simulations whatever the threads' timing. `leave()` when a
    thread ends; an error in `evaluate` is raised in every waiting thread."""

    def __init__(self, evaluate, n: int):
        self.evaluate, self.live = evaluate, n
        self.waiting: dict[int, list] = {}  # thread index -> its models
        self.answers: dict[int, object] = {}  # thread index -> its residuals, or the error
        self.cond = threading.Condition()

    def caller(self, k: int):
        """Thread k's evaluator: models -> residuals (as `evaluate`)."""
        def call(models: list) -> list:
            with self.cond:
                self.waiting[k] = list(models)
                self._run_if_all_wait()
                while k not in self.answers:
                    self.cond.wait()
                answer = self.answers.pop(k)
            if isinstance(answer, BaseException):
                raise answer
            return answer
        return call

    def leave(self) -> None:
        with self.cond:
            self.live -= 1
            self._run_if_all_wait()

    def _run_if_all_wait(self) -> None:
        if not self.waiting or len(self.waiting) < self.live:
            return
        order = sorted(self.waiting)
        try:
            out = self.evaluate([m for k in order for m in self.waiting[k]])
        except BaseException as exc:  # noqa: BLE001 - handed to every waiting thread
            self.answers.update((k, exc) for k in order)
        else:
            start = 0
            for k in order:
                self.answers[k], start = out[start:start + len(self.waiting[k])], start + len(self.waiting[k])
        self.waiting.clear()
        self.cond.notify_all()


def run_gathered(evaluate, works: list) -> list:
    """work(its evaluator) for each of `works`, each in a thread of its own, their calls to `evaluate` gathered
    (`Gathered`): the same simulations, so the same results, as running them one after another, in fewer and larger
    lockstep calls (a single model's call is ~4 x the cost per simulation of one of 50). The results in order; the
    first error of a work is raised here."""
    gathered = Gathered(evaluate, len(works))
    results, errors = [None] * len(works), [None] * len(works)

    def run(k: int) -> None:
        try:
            results[k] = works[k](gathered.caller(k))
        except BaseException as exc:  # noqa: BLE001 - raised again below, in the caller's thread
            errors[k] = exc
        finally:
            gathered.leave()

    threads = [threading.Thread(target=run, args=(k,), daemon=True) for k in range(len(works))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    failed = next((e for e in errors if e is not None), None)
    if failed is not None:
        raise failed
    return results


def in_units(evaluate, per: np.ndarray):
    """An evaluator of residuals in spread units turned to the units `per` (`data.unit_change`, computed in
    the main process: its noise has the closed-loop noise floor, add_closed_loop_noise, which the workers'
    copies of the data lack; with the model's simulations, a channel's misfit where that is larger)."""
    return lambda models: [None if r is None else r / per for r in evaluate(models)]
