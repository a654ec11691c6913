"""Sweeps: many runs of one scenario over varied parameters, on a local process pool or on Ray.

A sweep file (TOML; README "Sweeps", examples in `sweeps/`) names a `scenario`, a `method`
(grid | random | lhs) with `samples` and `seed` for the last two, a `[fixed]` table set on every
run and a `[parameters]` table of swept dotted scenario keys ('payload_kg', 'controller.kp',
'effects.0.torque_positive': lists by index), each a list of values, {low, high[, n][, log]} or
{mean, std}. Locally, each worker process steps a chunk of runs together (lockstep.simulate_batch).
Each run is a row of DIR/results.parquet and .csv; finished rows are journalled to
DIR/runs.jsonl as they come, so an interrupted or killed sweep resumes where it stopped.
"""
from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import json
import logging
import math
import multiprocessing as mp
import os
import signal
import socket
import statistics
import time
import uuid
from dataclasses import dataclass
from multiprocessing.connection import wait
from pathlib import Path
from typing import Callable, Iterator

import mujoco
import numpy as np

from .engine import ControlLoop, SimulationError, simulate
from .lockstep import simulate_batch
from .metrics import step_metrics
from .model import ConfigError, load_model, read_toml, rig_params
from .recording import write_recording
from .rigdesc import load_rig
from .scenario import DEFAULTS, check, load_scenario

log = logging.getLogger(__name__)

METHODS = ("grid", "random", "lhs")
SWEEP_KEYS = ("scenario", "method", "samples", "seed", "fixed", "parameters")
OPEN_TABLES = ("parameters", "joint_friction")  # tables whose keys a sweep may create
METRICS = ("rise_time_s", "settling_time_s", "overshoot_pct", "steady_state_error", "tracking_rms",
           "peak_strain_V", "tip_error_rms_m", "tip_error_final_m")
CHECKPOINT_S = 30.0  # s between rewrites of the results files during a sweep (at least 10x a rewrite's time)
LOCKSTEP = 32  # runs a worker steps together (lockstep.simulate_batch); at most this many are lost to a crash


@dataclass
class Sweep:
    """A checked sweep: the base scenario ([fixed] applied) and the parsed parameter specs by key."""

    base: dict
    parameters: dict[str, dict]
    method: str = "grid"
    samples: int = 0
    seed: int = 0


def assign(scenario: dict, key: str, value, create: bool = False) -> None:
    """Set dotted `key`: tables by name, lists by index ('effects.0.torque_positive'), a one-table
    list also directly ('reference.time_s'). The key must exist unless `create` or it lies under
    `parameters` / `joint_friction`. ConfigError for an unknown key."""
    parts = key.strip().split(".")
    if parts[0] not in DEFAULTS:
        raise ConfigError(f"unknown scenario parameter {key!r} (known: {', '.join(DEFAULTS)})")
    create, node = create or parts[0] in OPEN_TABLES, scenario
    for i, part in enumerate(parts):
        where = ".".join(parts[:i])
        if isinstance(node, list) and not part.isdigit() and len(node) == 1:
            node = node[0]
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ConfigError(f"unknown scenario parameter {key!r}: {where} has {len(node)} entries "
                                  "(give them under [fixed], index from 0)")
            part = int(part)
        elif not isinstance(node, dict):
            raise ConfigError(f"cannot set {key!r}: {where} is a value, not a table")
        elif part not in node:
            if not create:
                raise ConfigError(f"unknown scenario parameter {key!r} (not in scenario {scenario.get('name')!r}; "
                                  "set it under [fixed] first)")
            node[part] = {}
        if i == len(parts) - 1:
            node[part] = value
        node = node[part]


def resolve(sweep: Sweep, values: dict) -> dict:
    """The scenario of one run: the sweep's base with `values` assigned (not yet checked)."""
    scenario = copy.deepcopy(sweep.base)
    for key, value in values.items():
        assign(scenario, key, value)
    return scenario


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _integer(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def parse_spec(key: str, spec, method: str) -> dict:
    """A parameter spec as {kind: values | range | normal, ...}; ConfigError if malformed or empty.
    A range of two integers without n is the integers low..high (both included)."""
    what = f"parameter {key!r}"
    spec = {"values": spec} if isinstance(spec, list) else spec
    if not isinstance(spec, dict) or set(spec) - {"values", "low", "high", "n", "log", "mean", "std"}:
        raise ConfigError(f"{what}: expected a list of values or a table {{low, high, n, log}} / {{values}} / "
                          f"{{mean, std}}, got {spec!r}")
    if "values" in spec:
        if not isinstance(spec["values"], list) or not spec["values"]:
            raise ConfigError(f"{what}: empty range (no values)")
        return {"kind": "values", "values": spec["values"]}
    if "mean" in spec:
        if method == "grid":
            raise ConfigError(f"{what}: {{mean, std}} needs method 'random' or 'lhs'")
        if not (_number(spec["mean"]) and _number(spec.get("std")) and spec["std"] > 0):
            raise ConfigError(f"{what}: mean and std must be numbers, std > 0")
        return {"kind": "normal", "mean": spec["mean"], "std": spec["std"]}
    low, high, n, use_log = spec.get("low"), spec.get("high"), spec.get("n"), spec.get("log", False)
    if not (_number(low) and _number(high)) or not isinstance(use_log, bool):
        raise ConfigError(f"{what}: low and high must be numbers (log true/false), got {low!r}, {high!r}")
    if not low < high:
        raise ConfigError(f"{what}: empty range, low {low} is not below high {high}")
    if use_log and low <= 0:
        raise ConfigError(f"{what}: a log range needs low > 0")
    if n is not None and not (_integer(n) and n >= 1):
        raise ConfigError(f"{what}: n must be an integer >= 1, got {n!r}")
    integer = _integer(low) and _integer(high) and not use_log and n is None
    if method == "grid" and n is None and not integer:
        raise ConfigError(f"{what}: a grid over a float range needs n (number of values)")
    return {"kind": "range", "low": low, "high": high, "n": n, "log": use_log, "integer": integer}


def _grid(spec: dict) -> list:
    if spec["kind"] == "values":
        return spec["values"]
    if spec["integer"]:
        return list(range(spec["low"], spec["high"] + 1))
    return [float(x) for x in (np.geomspace if spec["log"] else np.linspace)(spec["low"], spec["high"], spec["n"])]


def _draw(spec: dict, u: float):
    """The value at quantile u (0..1) of a spec's distribution (lists: each value equally likely)."""
    if spec["kind"] == "values":
        return spec["values"][min(int(u * len(spec["values"])), len(spec["values"]) - 1)]
    if spec["kind"] == "normal":
        return statistics.NormalDist(spec["mean"], spec["std"]).inv_cdf(min(max(u, 1e-12), 1 - 1e-12))
    low, high = spec["low"], spec["high"]
    if spec["integer"]:
        return min(low + math.floor(u * (high - low + 1)), high)
    if spec["log"]:
        return math.exp(math.log(low) + u * (math.log(high) - math.log(low)))
    return low + u * (high - low)


def points(sweep: Sweep) -> Iterator[dict]:
    """Parameter values of each run in sweep order: the grid's product (last key fastest), or
    `samples` draws, independent ('random') or Latin-hypercube ('lhs'), reproducible by `seed`."""
    keys = list(sweep.parameters)
    if sweep.method == "grid":
        for combo in itertools.product(*(_grid(sweep.parameters[k]) for k in keys)):
            yield dict(zip(keys, combo))
        return
    rng, n = np.random.default_rng(sweep.seed), sweep.samples
    u = rng.random((n, len(keys)))
    if sweep.method == "lhs":  # one draw in each of n equal strata of every parameter, strata shuffled
        u = (np.argsort(rng.random((len(keys), n)), axis=1).T + u) / n
    for row in u:
        yield {k: _draw(sweep.parameters[k], float(x)) for k, x in zip(keys, row)}


def load_sweep(path) -> Sweep:
    """Read and check a sweep file. ConfigError (one line, naming the file) for unreadable TOML,
    unknown keys or parameters, empty ranges, wrong types, and a first run the engine cannot set up."""
    path = Path(path)
    try:
        raw = read_toml(path, "sweep file")
    except FileNotFoundError:
        raise ConfigError(f"no sweep file {path}") from None
    try:
        if set(raw) - set(SWEEP_KEYS):
            raise ConfigError(f"unknown sweep key(s) {', '.join(sorted(set(raw) - set(SWEEP_KEYS)))} "
                              f"(known: {', '.join(SWEEP_KEYS)})")
        name, method, samples, seed = raw.get("scenario"), raw.get("method", "grid"), raw.get("samples"), raw.get("seed", 0)
        fixed, parameters = raw.get("fixed", {}), raw.get("parameters")
        if not isinstance(name, str):
            raise ConfigError("'scenario' must name a scenario or a .toml path")
        if method not in METHODS:
            raise ConfigError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        if method == "grid" and samples is not None:
            raise ConfigError("'samples' is for method random or lhs; a grid runs every combination")
        if method != "grid" and not (_integer(samples) and samples >= 1):
            raise ConfigError(f"method {method!r} needs samples = an integer >= 1, got {samples!r}")
        if not _integer(seed):
            raise ConfigError(f"seed must be an integer, got {seed!r}")
        if not isinstance(fixed, dict) or not isinstance(parameters, dict) or not parameters:
            raise ConfigError("needs a [parameters] table of swept keys (and [fixed] must be a table)")
        base = load_scenario(str(path.parent / name) if Path(name).suffix else name)
        for key, value in fixed.items():
            assign(base, key, value, create=True)
        sweep = Sweep(check(base), {k: parse_spec(k, s, method) for k, s in parameters.items()}, method, samples or 0, seed)
        for key, spec in sweep.parameters.items():  # listed values and range ends: known key, right type
            for value in spec["values"] if spec["kind"] == "values" else (spec.get("low", spec.get("mean")), spec.get("high")):
                if value is not None:
                    check(resolve(Sweep(base, {}), {key: value}))
        for i, values in enumerate(points(sweep)):  # every run's values, drawn ones too, before any runs
            try:
                check(resolve(sweep, values))
            except ConfigError as exc:
                raise ConfigError(f"run {i} ({', '.join(f'{k}={v!r}' for k, v in values.items())}): {exc}") from None
        first = check(resolve(sweep, next(points(sweep))))
        ControlLoop(first)  # set up, not run: controller, joints, effects, the rig's refit parameters
        return sweep
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


# ----------------------------------------------------------------------------- one run


@functools.lru_cache(maxsize=8)
def _rigid_model(rig: str, locked: tuple) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = load_model(rig, locked_joints=dict(locked))
    return model, mujoco.MjData(model)


def _rigid_tip_error(ch: dict, scenario: dict) -> np.ndarray | None:
    """|camera tip - tip of the rigid arm at the reference angles| (m) at each camera sample."""
    locked = scenario["locked_joints"]
    try:
        model, data = _rigid_model(scenario["rig"], tuple(sorted(locked.items())))
        joints = {j: model.joint(j).qposadr[0] for j in ("shoulder", "elbow") if j not in locked}
        tip = model.site("tip").id
    except (KeyError, ConfigError):
        return None
    if any(f"{j}_reference" not in ch for j in joints):
        return None
    data.qpos[:] = model.qpos0
    err = []
    for i in np.flatnonzero(np.isfinite(ch["tip_x"])):
        for j, adr in joints.items():
            data.qpos[adr] = ch[f"{j}_reference"][i]
        mujoco.mj_kinematics(model, data)
        err.append(math.hypot(ch["tip_x"][i] - data.site_xpos[tip, 0], ch["tip_y"][i] - data.site_xpos[tip, 1]))
    return np.array(err)


def run_metrics(rec, scenario: dict) -> dict:
    """Step metrics (metrics.step_metrics) of the tracked response on a 'step' reference (laser arm:
    the tip's arc, m; others: the referenced joint's angle, rad), its RMS tracking error, peak
    |strain| (V), and the tip error (m): the laser arm's tip sensor (spot to tip), the Watflex
    camera against the rigid arm at the reference angles (RMS, and mean of the last 10 %)."""
    out: dict = dict.fromkeys(METRICS, math.nan) | {"response": ""}
    t, ch, tables = rec.time, rec.channels, scenario["reference"]
    ref = y = tip_error = None
    if scenario["rig"] == "laser_arm":
        p = rig_params("laser_arm")
        ref = p.beam.length * ch["reference"]
        y, out["response"] = ref - ch["tip_sensor"] / p.sensor_gain, "tip_arc (m)"
        tip_error = np.abs(ch["tip_sensor"] / p.sensor_gain) if tables else None
    elif tables:
        name = tables[0]["channel"]
        ref, y = ch.get(name), ch.get(name.replace("_reference", "_angle"))
        out["response"] = f"{name.replace('_reference', '_angle')} (rad)" if y is not None else ""
        tip_error = _rigid_tip_error(ch, scenario) if "tip_x" in ch else None
    strains = [np.nanmax(np.abs(v)) for k, v in ch.items() if k.startswith("strain_")]
    if strains:
        out["peak_strain_V"] = float(max(strains))
    if ref is not None and y is not None:
        out["tracking_rms"] = float(np.sqrt(np.mean((ref - y) ** 2)))
        moved = np.flatnonzero(ref != ref[0])
        if tables[0].get("kind") == "step" and moved.size:
            out |= step_metrics(t, y, t[moved[0]], ref[0], ref[-1])
    if tip_error is not None and tip_error.size:
        out["tip_error_rms_m"] = float(np.sqrt(np.mean(tip_error**2)))
        out["tip_error_final_m"] = float(np.mean(tip_error[-max(1, tip_error.size // 10):]))
    return out


def _row(task: dict, status: str, error: str = "") -> dict:
    return {"index": task["index"], "run_id": task["run_id"], **task["values"], "status": status, "error": error,
            "wall_time_s": math.nan, "worker": "", "response": "", **dict.fromkeys(METRICS, math.nan)}


def run_one(task: dict) -> dict:
    """Simulate one run ({index, run_id, values, scenario, keep}) and return its row: a failed run
    is a row with status 'diverged' or 'error' and the message, never an exception."""
    start, row = time.perf_counter(), _row(task, "ok")
    try:
        result = simulate(check(task["scenario"]))
        row |= run_metrics(result.recording, task["scenario"])
        if task.get("keep"):
            write_recording(result.recording, task["keep"], task["run_id"])
    except SimulationError as exc:
        row |= {"status": "diverged", "error": str(exc).replace("; nothing was written", "")}
    except Exception as exc:  # noqa: BLE001 - any failure is the run's, recorded in its row
        row |= {"status": "error", "error": " ".join(f"{type(exc).__name__}: {exc}".split())}
    return row | {"wall_time_s": time.perf_counter() - start, "worker": f"{socket.gethostname()}:{os.getpid()}"}


def run_many(tasks: list[dict], nthread: int = 1) -> list[dict]:
    """run_one for each task, the simulations of each rig stepped together in lockstep
    (lockstep.simulate_batch, on nthread threads); a group whose set-up fails (a bad scenario)
    falls back to run_one per task, so each row carries its own error."""
    rows: list = [None] * len(tasks)
    by_rig: dict[str, list[int]] = {}
    for k, task in enumerate(tasks):
        by_rig.setdefault(task["scenario"].get("rig", ""), []).append(k)
    for rig, ks in by_rig.items():
        start = time.perf_counter()
        try:
            results = simulate_batch([check(tasks[k]["scenario"]) for k in ks], nthread=nthread, rig=load_rig(rig))
        except Exception:  # noqa: BLE001 - found again, per run, by run_one
            for k in ks:
                rows[k] = run_one(tasks[k])
            continue
        setup = (time.perf_counter() - start - sum(getattr(r, "wall_time_s", 0.0) for r in results)) / len(ks)
        for k, result in zip(ks, results):
            t0, task, row = time.perf_counter(), tasks[k], _row(tasks[k], "ok")
            if isinstance(result, SimulationError):
                row |= {"status": "diverged", "error": str(result).replace("; nothing was written", "")}
            else:
                try:
                    row |= run_metrics(result.recording, task["scenario"])
                    if task.get("keep"):
                        write_recording(result.recording, task["keep"], task["run_id"])
                except Exception as exc:  # noqa: BLE001
                    row |= {"status": "error", "error": " ".join(f"{type(exc).__name__}: {exc}".split())}
            run = getattr(result, "wall_time_s", 0.0)  # its share of the lockstep loop
            rows[k] = row | {"wall_time_s": setup + run + time.perf_counter() - t0,
                             "worker": f"{socket.gethostname()}:{os.getpid()}"}
    return rows


def chunks(tasks: Iterator[dict], to_do: int, workers: int) -> Iterator[list[dict]]:
    """`to_do` tasks in lists, the unit a worker steps in lockstep: at least 4 per worker (so the pool
    stays busy to the end), at most LOCKSTEP runs each (the last one shorter)."""
    size = min(LOCKSTEP, -(-to_do // (4 * workers)))
    chunk: list[dict] = []
    for task in tasks:
        chunk.append(task)
        if len(chunk) == size:
            yield chunk
            chunk = []
    if chunk:
        yield chunk


# ----------------------------------------------------------------------------- executors


def cores() -> int:
    """CPUs this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _worker(conn) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's; it stops the workers
    try:
        while (chunk := conn.recv()) is not None:
            conn.send(run_many(chunk))
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        pass  # the parent is gone


def run_pool(tasks: Iterator[list[dict]], workers: int, on_row: Callable[[dict], None]) -> None:
    """Run chunks of tasks (`chunks`) on `workers` processes, each chunk in lockstep on one thread
    (run_many: processes still pay, since the control half of every simulation is Python). A chunk
    whose process dies is retried once in a fresh one, then its runs are recorded as 'crashed'.
    The workers are killed when this returns or raises (Ctrl-C)."""
    forkserver = "forkserver" in mp.get_all_start_methods()  # workers forked from a clean, preloaded process
    ctx = mp.get_context("forkserver" if forkserver else "spawn")
    if forkserver:
        ctx.set_forkserver_preload(["watflex_sim.batch", "watflex_sim.controllers"])
        from multiprocessing import forkserver as fs

        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited through exec: a Ctrl-C while the
        try:  # server preloads would print its traceback; the parent stops the workers instead
            fs.ensure_running()
        finally:
            signal.signal(signal.SIGINT, previous)
    procs: dict = {}  # parent end of the pipe -> [process, task or None]

    def start() -> None:
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_worker, args=(child,), daemon=True)
        proc.start()
        child.close()
        procs[parent] = [proc, None]

    tasks, retry = iter(tasks), []
    try:
        for _ in range(workers):
            start()
        while True:
            for conn, slot in procs.items():
                if slot[1] is None:
                    slot[1] = retry.pop() if retry else next(tasks, None)
                    try:
                        if slot[1] is not None:
                            conn.send(slot[1])
                    except OSError:
                        pass  # the worker died: found below, its task retried
            busy = {c: s for c, s in procs.items() if s[1] is not None}
            if not busy:
                return
            ready = set(wait([*busy, *(s[0].sentinel for s in busy.values())]))
            for conn, (proc, task) in busy.items():
                if conn not in ready and proc.sentinel not in ready:
                    continue
                try:
                    row = conn.recv()
                except Exception:  # noqa: BLE001 - EOF or a torn message: the worker died
                    row = None
                if row is not None:
                    procs[conn][1] = None
                    for r in row:
                        on_row(r)
                    continue
                proc.join()
                del procs[conn]
                conn.close()
                start()
                lost = task[0]["lost"] = task[0].get("lost", 0) + 1
                log.warning("worker %d died (exit code %s) running the chunk of runs %s; %s", proc.pid, proc.exitcode,
                            ", ".join(str(t["index"]) for t in task), "recorded as crashed" if lost > 1 else "retrying it")
                if lost > 1:
                    for t in task:
                        on_row(_row(t, "crashed", f"worker process died twice running it (exit code {proc.exitcode})"))
                else:
                    retry.append(task)
    finally:
        for conn, (proc, _) in procs.items():
            proc.kill()
            proc.join()
            conn.close()


def run_ray(tasks: Iterator[dict], address: str, on_row: Callable[[dict], None], workers: int | None = None,
            to_do: int = 1) -> None:
    """Run `to_do` tasks in chunks as Ray tasks of one CPU on the cluster at `address` ('auto', 'local'
    or host:port; a Ray already initialised in this process is used as it is), each chunk in lockstep
    (run_many, as a local worker does; at least 4 chunks per CPU, at most LOCKSTEP runs each). A chunk
    whose worker dies is retried once, then each of its runs is recorded as 'crashed'. Workers must be
    able to import watflex_sim."""
    import ray

    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=address, num_cpus=workers if address == "local" else None,
                     include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise ConfigError(f"cannot start or reach Ray at {address!r}: {exc}".replace("\n", " ")) from None
    remote = ray.remote(num_cpus=1, max_retries=1)(run_many)
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    limit = max(2, 2 * cpus)  # chunks in flight
    pending, tasks = {}, chunks(tasks, to_do, cpus)
    try:
        while True:
            while len(pending) < limit and (chunk := next(tasks, None)) is not None:
                pending[remote.remote(chunk)] = chunk
            if not pending:
                return
            for ref in ray.wait(list(pending), num_returns=1)[0]:
                chunk = pending.pop(ref)
                try:
                    rows = ray.get(ref)
                except ray.exceptions.RayError as exc:
                    rows = [_row(task, "crashed", " ".join(str(exc).split())[:500]) for task in chunk]
                for row in rows:
                    on_row(row)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


# ----------------------------------------------------------------------------- outputs


def _atomic(path: Path, write: Callable[[Path], None]) -> None:
    """Write `path` through a temporary file beside it, fsync'ed, then renamed into place."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        write(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        os.fsync(fd)
        os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def read_journal(path: Path) -> dict[str, dict]:
    """Finished rows by run id from DIR/runs.jsonl; a torn line is skipped, the last row of an id wins."""
    rows = {}
    for line in path.read_text().splitlines() if path.exists() else ():
        try:
            row = json.loads(line)
            rows[row["run_id"]] = row
        except (ValueError, KeyError, TypeError):
            continue
    return rows


def write_results(out: Path, rows: list[dict], keys: list[str]) -> Path:
    """DIR/results.parquet and DIR/results.csv, each atomically; values that are lists or tables as JSON."""
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    data = {}
    for c in ["index", "run_id", *keys, "status", "error", "wall_time_s", "worker", "response", *METRICS]:
        values = [r.get(c) for r in rows]
        try:
            if any(isinstance(v, (list, dict)) for v in values):
                raise pa.ArrowInvalid("not a scalar")
            data[c] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            data[c] = pa.array([json.dumps(v) for v in values])
    table = pa.table(data)
    _atomic(out / "results.parquet", lambda p: pq.write_table(table, p))
    _atomic(out / "results.csv", lambda p: pacsv.write_csv(table, p))
    return out / "results.parquet"


def plot_summary(out: Path, rows: list[dict], keys: list[str]) -> Path | None:
    """DIR/summary.png: each metric (rows of plots) against each numeric swept parameter (columns)."""
    from matplotlib.figure import Figure

    ok = [r for r in rows if r["status"] == "ok"]
    xs = [k for k in keys if ok and all(_number(r[k]) for r in ok)][:4]
    ys = [m for m in METRICS if any(np.isfinite(r[m]) for r in ok)][:6]
    if not xs or not ys:
        return None
    fig = Figure(figsize=(3.2 * len(xs), 2.2 * len(ys)), layout="constrained")
    axes = fig.subplots(len(ys), len(xs), squeeze=False)
    for i, m in enumerate(ys):
        for j, k in enumerate(xs):
            axes[i, j].plot([r[k] for r in ok], [r[m] for r in ok], ".", alpha=0.6)
            axes[i, j].set(xlabel=k if i == len(ys) - 1 else "", ylabel=m if j == 0 else "")
    fig.suptitle(f"{len(ok)} of {len(rows)} runs finished ok; response: {ok[0]['response']}")
    _atomic(out / "summary.png", lambda p: fig.savefig(p, format="png", dpi=90))
    return out / "summary.png"


# ----------------------------------------------------------------------------- the sweep


@dataclass
class SweepResult:
    rows: list[dict]  # finished rows of the sweep, in sweep order
    ran: int  # runs finished by this call
    skipped: int  # runs finished before it (resumed)
    failed: int  # runs of this call whose status is not 'ok'
    wall_s: float
    results: Path


def run_sweep(sweep: Sweep | str | Path, out, workers: int | None = None, ray_address: str | None = None,
              keep_recordings: bool = False, progress: Callable[[int, int], None] | None = None,
              plots: bool = True) -> SweepResult:
    """Run each run of `sweep` not yet finished in `out` (DIR/runs.jsonl) on a process pool of
    `workers` (default: all cores) or on Ray at `ray_address`; write DIR/results.parquet and .csv
    (every CHECKPOINT_S, at the end and when interrupted), DIR/summary.png, and with
    `keep_recordings` DIR/recordings/RUN_ID.csv/.json. `progress(done, to_do)` after each run.
    Run ids hash the base scenario and the values (and, random/lhs, the sample's index).
    Raises ConfigError for a bad sweep or a missing Ray; KeyboardInterrupt passes through after
    the finished rows are written. From a script, call it under `if __name__ == "__main__":`
    (the workers import the main module, as multiprocessing's forkserver and spawn do)."""
    sweep = sweep if isinstance(sweep, Sweep) else load_sweep(sweep)
    if ray_address:
        try:
            import ray  # noqa: F401
        except ImportError:
            raise ConfigError("--ray needs Ray: pip install 'watflex-sim[cluster]'") from None
    out, keys, t0 = Path(out), list(sweep.parameters), time.perf_counter()
    base = hashlib.sha1(json.dumps(sweep.base, sort_keys=True, default=str).encode()).hexdigest()

    def run_id(i: int, values: dict) -> str:
        text = json.dumps([base, values, None if sweep.method == "grid" else i], sort_keys=True, default=str)
        return hashlib.sha1(text.encode()).hexdigest()[:16]

    ids: dict[str, int] = {}
    for i, values in enumerate(points(sweep)):
        ids.setdefault(run_id(i, values), i)
    out.mkdir(parents=True, exist_ok=True)
    journal_path = out / "runs.jsonl"
    done = read_journal(journal_path)
    skipped = sum(1 for r in ids if r in done)
    to_do, state = len(ids) - skipped, {"ran": 0, "failed": 0, "next": time.monotonic() + CHECKPOINT_S}
    keep = out.resolve() / "recordings" if keep_recordings else None

    def tasks() -> Iterator[dict]:
        for i, values in enumerate(points(sweep)):
            rid = run_id(i, values)
            if rid not in done and ids[rid] == i:
                yield {"index": i, "run_id": rid, "values": values, "scenario": resolve(sweep, values), "keep": keep}

    def finished() -> list[dict]:
        return sorted((r | {"index": ids[r["run_id"]]} for r in done.values() if r["run_id"] in ids), key=lambda r: r["index"])

    def on_row(row: dict) -> None:
        journal.write(json.dumps(row) + "\n")
        journal.flush()
        done[row["run_id"]] = row
        state["ran"] += 1
        if row["status"] != "ok":
            state["failed"] += 1
            log.warning("run %d %s: %s", row["index"], row["status"], row["error"])
        if progress:
            progress(state["ran"], to_do)
        if time.monotonic() > state["next"]:
            start = time.monotonic()
            os.fsync(journal.fileno())
            write_results(out, finished(), keys)
            state["next"] = time.monotonic() + max(CHECKPOINT_S, 10 * (time.monotonic() - start))

    log.info("sweep of %s: %d runs, %d already done in %s, %d to run on %s", sweep.base["name"], len(ids), skipped,
             out, to_do, f"Ray at {ray_address}" if ray_address else f"{workers or cores()} processes")
    with open(journal_path, "a+b") as f:  # a line torn by a killed sweep: end it before appending
        if f.tell():
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                f.write(b"\n")
    journal, complete = open(journal_path, "a"), False
    try:
        if to_do and ray_address:
            run_ray(tasks(), ray_address, on_row, workers, to_do)
        elif to_do:
            n = min(workers or cores(), to_do)
            run_pool(chunks(tasks(), to_do, n), n, on_row)
        complete = True
    finally:
        journal.flush()
        os.fsync(journal.fileno())
        journal.close()
        if not complete and keep is not None and keep.exists():  # a worker killed mid-write leaves its temporaries
            for tmp in keep.glob(".*.tmp"):
                tmp.unlink(missing_ok=True)
        rows = finished()
        results = write_results(out, rows, keys)
        if complete and plots and (state["ran"] or not (out / "summary.png").exists()):
            plot_summary(out, rows, keys)
    return SweepResult(rows, state["ran"], skipped, state["failed"], time.perf_counter() - t0, results)
