"""Benchmark the simulator: cost of our 1 ms control loop against bare mj_step, and cost vs segment count.

Usage: python tools/bench.py [--quick] [--profile SCENARIO] [...]

1. Scenarios (every scenarios/*.toml): simulated time, wall time of the control loop
   (SimResult.wall_time_s, best of --repeats), real-time factor, and the cost per physics
   step of our full loop (sensors, controller, recording, divergence check) against bare
   `mujoco.mj_step(m, d, nstep=...)` on the same compiled model (same payload, locks, tilt,
   timestep), the same number of steps, from the same initial state (keyframe, settled air
   bearings), stepped in chunks. The project's target is ours/bare <= 1.3.
2. Segment sweep: each rig rebuilt by `BUILDERS` with `n_segments` = N (nominal model, no
   locks, no payload), bare mj_step per step and real-time factor at the rig's timestep.
3. Optional (--profile): a cProfile breakdown of the control loop in us per control tick.
5. Lockstep (watflex_sim.lockstep): per-simulation cost in batches of 1, 8, 32, 128 against bare
   mj_step on laser_arm_step, watflex_elbow_step and watflex_observer_two_joint (the observer with friction
   compensation at both joints: the benchmark's two-joint set-up), 1 vs 2 threads, where the time goes, and a
   sweep's runs per second against its bare-physics limit.
6. When a lockstep batch pays: B = 2..32 runs in lockstep on one thread against one by one (laser arm with and
   without hub friction, Watflex with a PD and with the two-joint observer), and the driver simulate_batch picks.

Every timing is run --repeats times (default 3) and the best is reported. The default run
takes well under 2 minutes on 2 cores; --quick caps scenarios at 1 s simulated and the sweep
at a few hundred steps.
"""
from __future__ import annotations

import argparse
import cProfile
import dataclasses
import datetime
import os
import platform
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from watflex_sim import engine  # noqa: E402
from watflex_sim.build import BUILDERS  # noqa: E402
from watflex_sim.params import CONTROL_PERIOD, RIGS  # noqa: E402
from watflex_sim.scenario import available, load_scenario  # noqa: E402

TARGET_RATIO = 1.3  # ours / bare mj_step per physics step, the project's stated target
DEFAULT_SEGMENTS = (5, 11, 21, 41)


# ----------------------------------------------------------------------------- output


def table(headers: list[str], rows: list[list[str]], align: str | None = None) -> str:
    """A markdown table; `align` is one char per column, 'l' or 'r' (default: first l, rest r)."""
    align = align or "l" + "r" * (len(headers) - 1)
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells):
        return "| " + " | ".join(c.ljust(w) if a == "l" else c.rjust(w) for c, w, a in zip(cells, widths, align)) + " |"

    rule = "|" + "|".join(("-" * (w + 1) + ":") if a == "r" else (":" + "-" * (w + 1)) for w, a in zip(widths, align)) + "|"
    return "\n".join([line(headers), rule, *(line(r) for r in rows)])


def cpu_model() -> str:
    try:
        for text in Path("/proc/cpuinfo").read_text().splitlines():
            if text.startswith("model name"):
                return text.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def cpu_busy(seconds: float = 0.5) -> float | None:
    """Share (0..1) of all CPUs busy over `seconds` before the run (Linux /proc/stat), None elsewhere."""

    def sample():
        fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
        idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
        return sum(fields), idle

    try:
        total0, idle0 = sample()
        time.sleep(seconds)
        total1, idle1 = sample()
    except (OSError, ValueError, IndexError):
        return None
    return 1.0 - (idle1 - idle0) / max(total1 - total0, 1)


def header(args) -> str:
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = os.cpu_count()
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"
    busy = cpu_busy()
    lines = [
        "# watflex-sim benchmark",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- CPUs: os.cpu_count() = {os.cpu_count()}, usable by this process = {affinity} ({cpu_model()})",
        f"- load average (1/5/15 min): {load}; CPUs busy just before the run: "
        + ("n/a" if busy is None else f"{busy * 100:.0f} %")
        + ("  <- other processes are running: timings are noisy, compare the spread column" if busy and busy > 0.1 else ""),
        f"- mujoco {mujoco.__version__}, numpy {np.__version__}, Python {platform.python_version()} on {platform.platform()}",
        f"- OPENBLAS_CORETYPE = {os.environ.get('OPENBLAS_CORETYPE', '(unset)')}",
        f"- control period {CONTROL_PERIOD * 1e3:g} ms; every timing best of {args.repeats}; "
        f"bare mj_step in chunks of {args.chunk} steps" + ("; QUICK run" if args.quick else ""),
    ]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- timing


def initial_state(scenario: dict) -> tuple[mujoco.MjModel, mujoco.MjData, int]:
    """The compiled model, the state the control loop starts from, and the substeps per tick.

    Uses the engine's own setup (ControlLoop) when there is one, so the state is exactly the
    loop's; otherwise repeats it: load_model with the scenario's options, keyframe 0,
    mj_forward, settled air bearings.
    """
    loop = engine.ControlLoop(scenario)
    return loop.model, loop.data, loop.n_sub


def time_bare(model: mujoco.MjModel, start: mujoco.MjData, n_steps: int, chunk: int) -> tuple[float, float, bool]:
    """Wall and CPU seconds of n_steps bare mj_step from a copy of `start` (ctrl as in `start`), and whether it stayed sane."""
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, start)
    full, rest = divmod(n_steps, chunk)
    c0, t0 = time.process_time(), time.perf_counter()
    for _ in range(full):
        mujoco.mj_step(model, data, nstep=chunk)
    if rest:
        mujoco.mj_step(model, data, nstep=rest)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ok = not data.warning.number.any() and bool(np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all())
    return wall, cpu, ok


def scenario_list(args) -> list[str]:
    names = args.scenarios or available()
    unknown = set(names) - set(available())
    if unknown:
        sys.exit(f"bench: unknown scenario(s) {', '.join(sorted(unknown))} (known: {', '.join(available())})")
    return names


def load(name: str, cap_s: float | None) -> dict:
    scenario = load_scenario(name)
    if cap_s is not None and scenario["duration_s"] > cap_s:
        scenario = load_scenario(name, [f"duration_s={cap_s!r}"])
    return scenario


def time_ours(scenario: dict, n_ticks: int):
    """One run of the control loop: (wall s = SimResult.wall_time_s, CPU s per tick, SimResult).

    CPU time comes from the progress callback (called after tick 0, every 0.1 s and at the end),
    so it covers the loop only, less its first tick, and excludes time the OS gave other processes.
    """
    marks = []
    result = engine.simulate(scenario, progress=lambda f: marks.append((f, time.process_time())))
    (f0, c0), (f1, c1) = marks[0], marks[-1]

    def done(f):  # ticks finished when progress(f) is called: f = k / n after tick k, 1.0 at the end
        return n_ticks if f >= 1.0 else f * n_ticks + 1

    ticks = done(f1) - done(f0)
    return result.wall_time_s, (c1 - c0) / ticks if ticks > 0 else float("nan"), result


# Recorded command channel that holds each actuator's ctrl value (rigs.py: the rigs write the
# saturated/quantised command they record into data.ctrl).
CTRL_CHANNEL = {"motor": "voltage_cmd", "shoulder_motor": "shoulder_torque_cmd", "elbow_motor": "elbow_torque_cmd"}


def recorded_ctrl(model: mujoco.MjModel, result) -> np.ndarray | None:
    """(n_ticks, nu) ctrl the loop applied, from its recording; None if a channel is missing."""
    channels = result.recording.channels
    columns = []
    for i in range(model.nu):
        channel = CTRL_CHANNEL.get(model.actuator(i).name)
        if channel not in channels:
            return None
        columns.append(np.asarray(channels[channel], dtype=float))
    return np.stack(columns, axis=1) if columns else np.zeros((len(result.recording.time), 0))


def time_replay(model: mujoco.MjModel, start: mujoco.MjData, ctrl: np.ndarray, n_sub: int) -> float:
    """Wall seconds of mj_step(nstep=n_sub) per tick with the loop's recorded ctrl set before each tick.

    MuJoCo is deterministic, so this is the loop's own trajectory (same contacts, same solver
    work) without the Python of sensors, controller and recording.
    """
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, start)
    view = data.ctrl
    t0 = time.perf_counter()
    for u in ctrl:
        view[:] = u
        mujoco.mj_step(model, data, nstep=n_sub)
    return time.perf_counter() - t0


def solver_iterations(model: mujoco.MjModel, start: mujoco.MjData, ctrl: np.ndarray | None, n_sub: int, n_ticks: int) -> float:
    """Mean constraint-solver iterations per physics step (untimed), with `ctrl` per tick or ctrl held."""
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, start)
    total = 0
    for k in range(n_ticks):
        if ctrl is not None:
            data.ctrl[:] = ctrl[k]
        for _ in range(n_sub):
            mujoco.mj_step(model, data)
            total += int(data.solver_niter[: max(int(data.nisland), 1)].sum())
    return total / (n_ticks * n_sub)


def bench_scenarios(args) -> str:
    rows_cost, rows_time, rows_physics, verdicts, n_met = [], [], [], [], 0
    for name in scenario_list(args):
        scenario = load(name, args.max_duration)
        model, start, n_sub = initial_state(scenario)
        n_ticks = int(round(scenario["duration_s"] / CONTROL_PERIOD))
        n_steps = n_ticks * n_sub
        ours, ours_cpu, bare, bare_cpu, replay = [], [], [], [], []
        bare_ok, error, ctrl = True, None, None
        for _ in range(args.repeats):  # interleaved, so slow drifts of the machine hit all alike
            try:
                wall, cpu_tick, result = time_ours(scenario, n_ticks)
                ours.append(wall)
                ours_cpu.append(cpu_tick)
                if ctrl is None:
                    ctrl = recorded_ctrl(model, result)
            except Exception as exc:  # noqa: BLE001 - a diverging scenario is reported, not fatal
                error = f"{type(exc).__name__}: {exc}"
            wall, cpu, ok = time_bare(model, start, n_steps, args.chunk)
            bare.append(wall)
            bare_cpu.append(cpu)
            bare_ok &= ok
            if ctrl is not None:
                replay.append(time_replay(model, start, ctrl, n_sub))
        sim_s = n_ticks * CONTROL_PERIOD
        bare_us = min(bare) / n_steps * 1e6
        flag = "" if bare_ok else " (bare diverged)"
        if not ours:
            rows_time.append([name, scenario["rig"], f"{sim_s:.3f}", "failed", "-", f"{n_ticks}", f"{n_steps}",
                              f"{model.opt.timestep * 1e3:g}", f"{n_sub}", f"{model.nv}", "-"])
            rows_cost.append([name, "-", f"{bare_us:.2f}{flag}", "-", "-", "-", "-", "-"])
            verdicts.append(f"- {name}: loop failed: {error}")
            continue
        wall = min(ours)
        ours_us = wall / n_steps * 1e6
        ratio = ours_us / bare_us
        cpu_ratio = min(ours_cpu) / n_sub / (min(bare_cpu) / n_steps) if min(bare_cpu) > 0 else float("nan")
        overhead_tick = (ours_us - bare_us) * n_sub
        budget_tick = (TARGET_RATIO - 1.0) * bare_us * n_sub
        met = ratio <= TARGET_RATIO
        n_met += met
        spread = (max(ours) - wall) / wall * 100
        rows_time.append([
            name, scenario["rig"], f"{sim_s:.3f}", f"{wall:.3f}", f"{sim_s / wall:.1f}", f"{n_ticks}",
            f"{n_steps}", f"{model.opt.timestep * 1e3:g}", f"{n_sub}", f"{model.nv}", f"{spread:.0f}",
        ])
        rows_cost.append([
            name, f"{ours_us:.2f}", f"{bare_us:.2f}{flag}", f"{ratio:.2f}", "yes" if met else "NO",
            f"{cpu_ratio:.2f}", f"{overhead_tick:.1f}", f"{budget_tick:.1f}",
        ])
        if replay:
            replay_us = min(replay) / n_steps * 1e6
            it_loop = solver_iterations(model, start, ctrl, n_sub, n_ticks)
            it_bare = solver_iterations(model, start, None, n_sub, n_ticks)
            rows_physics.append([
                name, f"{bare_us:.2f}", f"{replay_us:.2f}", f"{replay_us / bare_us:.2f}", f"{ours_us / replay_us:.2f}",
                f"{(ours_us - replay_us) * n_sub:.1f}", f"{it_bare:.3f}", f"{it_loop:.3f}",
            ])
        verdicts.append(
            f"- {name}: ours/bare = {ratio:.2f} -> target <= {TARGET_RATIO} {'met' if met else 'NOT met'}"
            + ("" if met else f" (overhead {overhead_tick:.1f} us/tick, budget {budget_tick:.1f} us/tick)")
        )
    out = [
        "## 1. Scenarios: our control loop vs bare mj_step",
        "",
        table(
            ["scenario", "rig", "simulated (s)", "loop wall (s)", "real-time factor", "ticks", "physics steps",
             "dt (ms)", "steps/tick", "nv", f"spread of {args.repeats} (%)"],
            rows_time,
        ),
        "",
        table(
            ["scenario", "ours (us/step)", "bare mj_step (us/step)", "ours/bare", f"<= {TARGET_RATIO}",
             "ours/bare, CPU time", "overhead (us/tick)", f"budget at {TARGET_RATIO} (us/tick)"],
            rows_cost,
        ),
        "",
        f"Target (project): ours/bare <= {TARGET_RATIO} per physics step. Met for {n_met} of {len(verdicts)} scenarios:",
        *verdicts,
        "",
        "ours = loop wall (SimResult.wall_time_s) / physics steps: sensors, noise, controller, actuators,",
        "recording, frames, divergence check and mj_step. bare = mj_step(m, d, nstep=chunk) on the same model",
        "from the same initial state, ctrl held at its initial value (0). overhead = (ours - bare) x steps/tick;",
        "budget = the overhead per tick the target allows. spread = (worst - best) / best of our loop's wall",
        "times. The CPU-time ratio (process_time; ours from the progress callback) is a cross-check that",
        "ignores time the OS gave to other processes; the verdict uses wall time.",
    ]
    if rows_physics:
        out += [
            "",
            "### Where the ratio comes from: physics of the moving arm vs Python",
            "",
            table(
                ["scenario", "bare at rest (us/step)", "replay (us/step)", "replay/bare", "ours/replay",
                 "non-physics (us/tick)", "solver it/step, bare", "solver it/step, loop"],
                rows_physics,
            ),
            "",
            "replay = the loop's recorded ctrl written into data.ctrl before each tick's mj_step(nstep=steps/tick):",
            "bit-for-bit the loop's own trajectory without its Python. replay/bare = extra physics cost of the",
            "moving arm (e.g. constraint-solver iterations: the bare run from rest converges at once);",
            "ours/replay and non-physics (us/tick) = the loop's own overhead (its Python, and any MuJoCo call",
            "besides the physics steps such as a position refresh). ours/bare = replay/bare x ours/replay.",
        ]
    return "\n".join(out)


def bench_segments(args) -> str:
    rows = []
    settle = getattr(engine, "_settle_bearings", None)
    for rig, build in BUILDERS.items():
        base = RIGS[rig]
        if "n_segments" not in {f.name for f in dataclasses.fields(base)}:
            continue  # a rigid rig (EMPS): nothing to discretise
        for n in args.segments:
            params = dataclasses.replace(base, n_segments=n)
            t0 = time.perf_counter()
            model = build(params).compile()
            compile_s = time.perf_counter() - t0
            start = mujoco.MjData(model)
            if model.nkey:
                mujoco.mj_resetDataKeyframe(model, start, 0)
            mujoco.mj_forward(model, start)
            if settle is not None:
                settle(model, start)  # air bearings resting on the glass, as at a loop's start
            walls, ok = [], True
            for _ in range(args.repeats):
                wall, _cpu, good = time_bare(model, start, args.sweep_steps, args.chunk)
                walls.append(wall)
                ok &= good
            per_step = min(walls) / args.sweep_steps
            dt = model.opt.timestep
            rows.append([
                rig, f"{n}", f"{model.nv}", f"{model.nbody}", f"{dt * 1e3:g}", f"{per_step * 1e6:.2f}",
                f"{dt / per_step:.1f}", f"{per_step * 1e6 * round(CONTROL_PERIOD / dt):.1f}",
                f"{compile_s * 1e3:.0f}", "ok" if ok else "DIVERGED",
            ])
    out = [
        "## 2. Cost vs segment count (bare mj_step, nominal model: no locks, no payload)",
        "",
        table(
            ["rig", "N segments", "nv", "bodies", "dt (ms)", "mj_step (us/step)", "real-time factor",
             "physics per 1 ms tick (us)", "build+compile (ms)", "state"],
            rows,
        ),
        "",
        f"{args.sweep_steps} steps from keyframe 0 (bearings settled), ctrl = 0; real-time factor = dt / wall per step.",
        "The laser arm's N is its one beam; the Watflex's N is per link (both links).",
    ]
    return "\n".join(out)


def profile(name: str, args) -> str:
    """cProfile of one run of the scenario's loop: tottime and cumtime per control tick (us)."""
    scenario = load(name, args.max_duration)
    engine.simulate(scenario)  # warm-up
    n_ticks = int(round(scenario["duration_s"] / CONTROL_PERIOD))
    plain = min(engine.simulate(scenario).wall_time_s for _ in range(args.repeats))
    prof = cProfile.Profile()

    def gate(fraction):  # progress: first call after tick 0, last after the loop -> profile the loop only
        if fraction >= 1.0:
            prof.disable()
        elif not gate.on:
            gate.on = True
            prof.enable()

    gate.on = False
    result = engine.simulate(scenario, progress=gate)
    prof.disable()
    n_ticks -= 1  # tick 0 ran before the profiler started
    stats = pstats.Stats(prof).stats
    rows = []
    for (path, line, func), (_cc, ncalls, tottime, cumtime, _callers) in stats.items():
        where = f"{Path(path).name}:{line}" if line else "built-in"
        rows.append((tottime, cumtime, ncalls, f"{where} {func}"))
    rows.sort(reverse=True)
    body = [
        [f"{tt / n_ticks * 1e6:.2f}", f"{ct / n_ticks * 1e6:.2f}", f"{nc / n_ticks:.2f}", where]
        for tt, ct, nc, where in rows[: args.profile_top]
    ]
    rest = result.wall_time_s - sum(r[0] for r in rows)  # simulate's own frame was entered before profiling
    body.append([f"{rest / n_ticks * 1e6:.2f}", "", "", "simulate's loop body (recording rows, loop), by difference"])
    out = [
        f"## cProfile of the {name} control loop (ticks 1..{n_ticks}, setup excluded)",
        "",
        f"Loop wall: {plain / (n_ticks + 1) * 1e6:.1f} us/tick without the profiler (best of {args.repeats}), "
        f"{result.wall_time_s / (n_ticks + 1) * 1e6:.1f} us/tick under cProfile. The profiler inflates",
        "every Python-level call (C calls such as mj_step much less): read the relative sizes.",
        "",
        table(["tottime (us/tick)", "cumtime (us/tick)", "calls/tick", "function"], body, "rrrl"),
    ]
    return "\n".join(out)


def bench_friction(args) -> str:
    """Section 3: cost of the joint-friction callback per physics step vs the same model without friction."""
    from watflex_sim.joint_friction import FrictionCallback, nominal_frictions

    n_steps = 2000 if args.quick else 20000
    rows = []
    for label, overrides in (("elbow on the arm (watflex_elbow_step)", []),
                             ("shoulder actuator bench", ['actuator_bench="shoulder"', "locked_joints={}",
                                                          'reference.channel="shoulder_reference"',
                                                          'controller.joints=["shoulder"]'])):
        scenario = load_scenario("watflex_elbow_step", overrides)
        model, start, _ = initial_state(scenario)
        joint = "shoulder" if overrides else "elbow"
        law = nominal_frictions("watflex")[joint]
        act = model.actuator(f"{joint}_motor").id
        for regime, torque in (("sticking", 0.5 * law.breakaway(+1)), ("sliding", 1.5 * law.breakaway(+1))):
            start.ctrl[:] = 0.0
            start.ctrl[act] = torque
            frictionloss = model.dof_frictionloss.copy()
            model.dof_frictionloss[:] = 0.0
            bare = min(time_bare(model, start, n_steps, args.chunk)[0] for _ in range(args.repeats))
            model.dof_frictionloss[:] = frictionloss
            walls = []
            for _ in range(args.repeats):
                data = mujoco.MjData(model)
                mujoco.mj_copyData(data, model, start)
                with FrictionCallback(model, data, {joint: law}):
                    t0 = time.perf_counter()
                    mujoco.mj_step(model, data, nstep=n_steps)
                    walls.append(time.perf_counter() - t0)
            model.dof_frictionloss[:] = frictionloss
            ours = min(walls)
            rows.append([label, regime, f"{torque:.2f}", f"{1e6 * bare / n_steps:.2f}", f"{1e6 * ours / n_steps:.2f}",
                         f"{ours / bare:.2f}", "yes" if ours / bare <= TARGET_RATIO else "NO"])
    return "## 3. Joint friction: callback + frictionloss constraint vs the same model without friction\n\n" + table(
        ["model", "regime", "torque (N m)", "no friction (us/step)", "with friction (us/step)", "ratio", f"<= {TARGET_RATIO}"],
        rows) + f"\n\n{n_steps} physics steps at a constant torque, best of {args.repeats}."


def bench_batch(args) -> str:
    """Section 4, batch scaling: runs/s of `watflex-sim batch` (watflex_sim.batch.run_sweep) on 1 and 2
    worker processes, its overhead against a bare loop of the same runs in one process, and Ray's
    per-task overhead (if Ray is installed) on a local instance of 2 CPUs."""
    import importlib.util
    import tempfile

    from watflex_sim import batch

    n = 12 if args.quick else 40
    text = ('scenario = "laser_arm_step"\n[fixed]\nnoise = false\n[parameters]\n'
            f'payload_kg = {{ low = 0.0, high = 1.6, n = {n // 4} }}\n"controller.kp" = [0.1, 0.12, 0.14, 0.16]\n')
    tmp = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    (tmp / "sweep.toml").write_text(text)
    sweep = batch.load_sweep(tmp / "sweep.toml")
    scenarios = [batch.resolve(sweep, values) for values in batch.points(sweep)]

    bare_loop = ("import json, sys, time\nimport watflex_sim.controllers\nfrom watflex_sim import check, simulate\n"
                 "scenarios = json.load(sys.stdin)\nt0 = time.perf_counter()\n"
                 "for s in scenarios:\n    simulate(check(s))\nprint(time.perf_counter() - t0)\n")

    def bare() -> tuple[float, float]:
        """A user's plain loop over the same scenarios in a fresh process (its imports not timed)."""
        import json
        import subprocess

        done = subprocess.run([sys.executable, "-c", bare_loop], input=json.dumps(scenarios), capture_output=True,
                              text=True, check=True)
        wall = float(done.stdout.split()[-1])
        return wall, wall

    def sweep_wall(workers: int, ray: str | None = None) -> tuple[float, float]:
        """Wall of a whole run_sweep (s) and the sum of its runs' own wall times (run_one, s)."""
        out = Path(tempfile.mkdtemp(dir=tmp))
        t0 = time.perf_counter()
        result = batch.run_sweep(sweep, out, workers=workers, ray_address=ray, plots=False)
        wall = time.perf_counter() - t0
        assert result.ran == n and result.failed == 0, result
        return wall, sum(r["wall_time_s"] for r in result.rows)

    how = {"bare loop, 1 process": (bare, 1), "process pool, 1 worker": (lambda: sweep_wall(1), 1),
           "process pool, 2 workers": (lambda: sweep_wall(2), 2)}
    sweep_wall(2)  # warm-up: forkserver started, pyarrow imported
    noop_line = "Ray: not installed (pip install '.[cluster]'): its per-task overhead not measured."
    ray_ready = importlib.util.find_spec("ray") is not None
    if ray_ready:
        import ray

        t0 = time.perf_counter()
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="WARNING")
        init_s = time.perf_counter() - t0
        noop = ray.remote(num_cpus=1)(lambda: None)
        ray.get([noop.remote() for _ in range(100)])  # workers started
        t0 = time.perf_counter()
        ray.get([noop.remote() for _ in range(1000)])
        noop_line = (f"Ray: local instance started in {init_s:.1f} s; 1000 empty tasks in a row: "
                     f"{(time.perf_counter() - t0) / 1000 * 1e3:.2f} ms each, submit to result.")
        sweep_wall(2, ray="local")  # warm-up: Ray's workers import watflex_sim
        how["Ray, local, 2 CPUs"] = (lambda: sweep_wall(2, ray="local"), 2)
    burn = "import time\nt0 = time.perf_counter()\ns = 0\nfor i in range(4_000_000):\n    s += i * i\nprint(time.perf_counter() - t0)\n"

    def ceiling() -> float:
        """The machine's own 2-process scaling: 2 x (a pure-Python loop alone) / (two at once)."""
        import subprocess

        def launch():
            return subprocess.Popen([sys.executable, "-c", burn], stdout=subprocess.PIPE, text=True)

        alone = float(launch().communicate()[0])
        pair = [launch(), launch()]
        return 2 * alone / max(float(p.communicate()[0]) for p in pair)

    results, ceilings = {k: [] for k in how}, []
    for _ in range(args.repeats):  # interleaved, so slow drifts of the machine hit all alike
        ceilings.append(ceiling())
        for k, (f, _w) in how.items():
            results[k].append(f())
    if ray_ready:
        ray.shutdown()
    import shutil

    shutil.rmtree(tmp, ignore_errors=True)
    best = {k: min(v) for k, v in results.items()}  # by wall
    bare_wall = best["bare loop, 1 process"][0]
    rows = []
    for k, (wall, runs) in best.items():
        workers = how[k][1]
        outside = (wall * workers - runs) / n * 1e3  # ms of worker time per run spent outside run_one
        rows.append([k, f"{wall:.2f}", f"{n / wall:.1f}", f"{bare_wall / wall:.2f}", f"{runs / n * 1e3:.1f}",
                     "-" if k.startswith("bare") else f"{outside:.1f}",
                     f"{(max(w for w, _ in results[k]) - wall) / wall * 100:.0f}"])
    one, two = best["process pool, 1 worker"], best["process pool, 2 workers"]
    speedup, overhead, inside = one[0] / two[0], one[0] / bare_wall - 1, (one[0] - one[1]) / one[1]
    lines = [
        f"## 4. Batch scaling: {n} runs of laser_arm_step (1 s simulated, noise off), payload x gain grid",
        "",
        table(["how", "wall (s)", "runs/s", "vs bare loop", "mean run (ms)", "outside runs (ms/run)",
               f"spread of {args.repeats} (%)"], rows),
        "",
        f"- 2 workers vs 1: {speedup:.2f}x (target >= 1.8 on 2 cores) -> {'met' if speedup >= 1.8 else 'NOT met'}; "
        f"this machine's own ceiling, two pure-Python loops at once: {max(ceilings):.2f}x (best of {len(ceilings)})",
        f"- engine overhead, 1 worker: {inside * 100:+.1f} % of the runs' own time spent outside them in the same sweep "
        f"(target <= 5 %) -> {'met' if inside <= 0.05 else 'NOT met'}; against the bare loop, wall vs wall: "
        f"{overhead * 100:+.1f} % (two measurements apart in time: see the spread column)",
        "- " + noop_line,
    ]
    if "Ray, local, 2 CPUs" in best:
        wall, runs = best["Ray, local, 2 CPUs"]
        lines.append(f"- Ray per task: {(wall * 2 - runs) / n * 1e3:.1f} ms of a CPU outside the run (pool: "
                     f"{(two[0] * 2 - two[1]) / n * 1e3:.1f} ms); runs inside Ray workers took "
                     f"{runs / two[1]:.2f}x their time in pool workers (Ray's own processes share the 2 CPUs).")
    return "\n".join(lines + [
        "",
        "bare loop = `for s in scenarios: simulate(s)` in a fresh process (imports not timed). Pool and Ray walls are whole",
        "run_sweep calls (warm forkserver / Ray workers): task dispatch, metrics, journal, results.parquet/.csv;",
        "no summary plot. mean run = run_one's own wall (simulation + metrics) as its row records it;",
        "outside runs = (wall x workers - sum of runs) / runs. A cold first sweep also pays the forkserver's",
        "start (imports, 1-2 s); a Ray cluster's start is not counted.",
    ])


LOCKSTEP_SIZES = (1, 8, 32, 128)
LOCKSTEP_TARGET = 1.15  # per-simulation cost in a batch of >= 32 / bare mj_step (issue 16)


def bench_lockstep(args) -> str:
    """Section 5, lockstep (watflex_sim.lockstep.simulate_batch): per-simulation cost per physics step
    in batches of B against bare mj_step, thread scaling, where a batch's time goes, and a sweep's
    runs per second against the bare-physics limit measured in the same run."""
    from watflex_sim.lockstep import simulate_batch

    duration = 0.5 if args.quick else 1.0
    sizes = LOCKSTEP_SIZES[:3] if args.quick else LOCKSTEP_SIZES
    rows, lines = [], []
    for name in ("laser_arm_step", "watflex_elbow_step", "watflex_observer_two_joint"):
        scenario = load_scenario(name, [f"duration_s={duration}"])
        model, start, n_sub = initial_state(scenario)
        steps = round(duration / CONTROL_PERIOD) * n_sub
        bare = min(time_bare(model, start, steps, args.chunk)[0] for _ in range(args.repeats)) / steps
        batch = [load_scenario(name, [f"duration_s={duration}", f"seed={i}"]) for i in range(max(sizes))]
        cells = [name, f"{bare * 1e6:.2f}"]
        for b in sizes:
            per = min(simulate_batch(batch[:b], nthread=2, always=True)[0].wall_time_s for _ in range(args.repeats)) / steps
            cells.append(f"{per * 1e6:.2f} ({per / bare:.2f})")
        one = min(simulate_batch(batch[:32], nthread=1, always=True)[0].wall_time_s for _ in range(args.repeats)) / steps
        cells.append(f"{one * 1e6:.2f} ({one / bare:.2f})")
        rows.append(cells)
        profiler = cProfile.Profile()
        profiler.enable()
        simulate_batch(batch[:32], nthread=2)
        profiler.disable()
        stats = pstats.Stats(profiler).stats
        total = sum(v[2] for v in stats.values())  # tottime of everything
        share = {}
        for (file, _line, func), v in stats.items():
            key = ("physics (Batch.step)" if func.endswith("_batch.step}") or func == "<built-in method mujoco._batch.step>"
                   else "friction on arrays" if "joint_friction" in file and func == "step"
                   else "set-up (models, ControlLoop)" if func in ("__init__",) and "lockstep" in file else None)
            if key:
                share[key] = share.get(key, 0.0) + (v[3] if "set-up" in key else v[2])
        control = sum(v[3] for (f, _l, fn), v in stats.items() if (fn == "control" and f.endswith("engine.py"))
                      or (fn == "tick" and f.endswith("columns.py")))
        record = sum(v[3] for (f, _l, fn), v in stats.items() if fn in ("write", "frame") and f.endswith("engine.py"))
        share |= {"control half (sensors, controller, converters)": control, "recording (Tape)": record}
        lines.append(f"- {name}, B = 32, 2 threads, under cProfile (Python inflated): " + ", ".join(
            f"{k} {v / total * 100:.0f} %" for k, v in share.items()))

    # a sweep: 40 laser-arm runs (payload x gain, noise off, as section 4), against its bare physics
    n = 12 if args.quick else 40
    sweep = [load_scenario("laser_arm_step", ["noise=false", f"duration_s={duration}", f"payload_kg={0.4 * (i % 5)}",
                                              f"controller.kp={0.1 + 0.02 * (i // 5) % 4}"]) for i in range(n)]
    bare_total = 0.0
    for s in sweep:
        model, start, n_sub = initial_state(s)
        steps = round(duration / CONTROL_PERIOD) * n_sub
        bare_total += time_bare(model, start, steps, args.chunk)[0]
    limit = 2 * n / bare_total  # runs/s: bare mj_step of every run, on both cores, nothing else
    t0 = time.perf_counter()
    for s in sweep:
        engine.simulate(s)
    single = n / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    results = simulate_batch(sweep, nthread=2)
    lock = n / (time.perf_counter() - t0)
    physics = n / replay_wall(sweep, results)
    lines += [
        f"- sweep of {n} laser_arm_step runs ({duration:g} s, noise off; set-up included): single-run loop "
        f"{single:.1f} runs/s (1 process; x2 for 2 ideal processes: {2 * single:.1f}); lockstep, 1 process, "
        f"2 threads: {lock:.1f} runs/s; bare-physics limit (bare mj_step of every run on 2 cores, no set-up): "
        f"{limit:.1f} runs/s -> {lock / limit * 100:.0f} % of it (target 85 %: {'met' if lock >= 0.85 * limit else 'NOT met'})",
        f"- the same sweep's physics alone in lockstep (its batches on the same 2 threads, each tick's recorded voltage "
        f"replayed, no control half, no set-up): {physics:.1f} runs/s -> the sweep runs at {lock / physics * 100:.0f} % "
        "of its own physics; the limit above is lower than this by the batch's own overhead and the moving arm's "
        "dearer steps (the limit steps the arm at rest)",
    ]
    return "\n".join([
        f"## 5. Lockstep: per-simulation cost per physics step in batches of B ({duration:g} s runs, seeds 0..B-1)",
        "",
        table(["scenario", "bare mj_step (us)", *(f"B={b}, 2 thr (us, x bare)" for b in sizes), "B=32, 1 thr"], rows),
        "",
        *lines,
        f"- target: B >= 32 at <= {LOCKSTEP_TARGET} x bare. Per-simulation cost = the batch's loop wall (set-up "
        "excluded) / B / physics steps; bare = mj_step on one thread from the same state with zero control.",
    ])


def replay_wall(scenarios: list[dict], results: list) -> float:
    """Wall time (s) of the scenarios' physics alone in lockstep: grouped and set up as simulate_batch does, then
    stepped tick by tick with each run's recorded voltage (laser arm) as the motor input; set-up excluded."""
    from watflex_sim.engine import ControlLoop
    from watflex_sim.lockstep import _Lockstep, structure

    groups: dict[tuple, list[int]] = {}
    loops = [ControlLoop(s) for s in scenarios]
    for i, loop in enumerate(loops):
        groups.setdefault((structure(loop.model), loop.n_sub), []).append(i)
    wall = 0.0
    for members in groups.values():
        group = _Lockstep([loops[i] for i in members], nthread=2)
        volts = np.array([results[i].recording.channels["voltage_cmd"] for i in members]).T  # (tick, member)
        motor = loops[members[0]].rig._motor
        t0 = time.perf_counter()
        for row in volts:
            group.ctrl[:, motor] = row
            group.batch.step(None, nstep=loops[members[0]].n_sub)
        wall += time.perf_counter() - t0
    return wall


PAYS_SIZES = (2, 4, 8, 16, 32)
HUB_COULOMB = "effects=[{effect='coulomb_friction', where='hub', torque_positive=0.01, torque_negative=0.03}]"


def bench_pays(args) -> str:
    """Section 6, when a lockstep batch pays: B runs of one structure (seeds 0..B-1) in lockstep on one
    thread (as a diagnosis worker runs them) against the same runs one by one on the single-run driver,
    set-up included in both; and the driver lockstep._pays picks."""
    from watflex_sim.lockstep import ControlLoop, _pays, simulate_batch

    duration = 0.5 if args.quick else 1.0
    cases = (("laser_arm_step", []), ("laser_arm_step (hub Coulomb friction)", [HUB_COULOMB]), ("watflex_elbow_step", []),
             ("watflex_observer_two_joint", []))
    rows = []
    for label, sets in cases:
        name = label.split()[0]
        cells = [label]
        for b in PAYS_SIZES:
            runs = [load_scenario(name, [f"duration_s={duration}", f"seed={i}", *sets]) for i in range(b)]
            lock = single = float("inf")
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                simulate_batch(runs, nthread=1, always=True)
                lock = min(lock, time.perf_counter() - t0)
                t0 = time.perf_counter()
                for run in runs:
                    engine.simulate(run)
                single = min(single, time.perf_counter() - t0)
            picked = "lockstep" if _pays([ControlLoop(run) for run in runs]) else "single"
            cells.append(f"{lock / single:.2f} ({picked})")
        rows.append(cells)
    return "\n".join([
        f"## 6. When lockstep pays: wall time of B runs in lockstep / one by one ({duration:g} s runs, 1 thread, set-up included)",
        "",
        table(["scenario", *(f"B={b}" for b in PAYS_SIZES)], rows),
        "",
        "- in brackets: the driver simulate_batch picks (lockstep._pays). A batch pays a fixed cost per Batch.step call "
        "and tick (and the array friction's numpy work per call); with joint friction it makes one call per physics "
        "step (the laser arm: 10 a tick), not one per tick.",
    ])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 2)[2],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--quick", action="store_true",
                        help="short run: scenarios capped at 1 s simulated, sweep of 500 steps (a few seconds)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of every timing; the best is reported (default 3)")
    parser.add_argument("--chunk", type=int, default=1000, help="physics steps per bare mj_step(nstep=...) call (default 1000)")
    parser.add_argument("--scenarios", nargs="+", metavar="NAME", help=f"scenarios to run (default: all of {', '.join(available())})")
    parser.add_argument("--max-duration", type=float, metavar="S",
                        help="cap each scenario's simulated duration (s); --quick sets 1")
    parser.add_argument("--segments", type=int, nargs="+", default=list(DEFAULT_SEGMENTS), metavar="N",
                        help=f"segment counts of the sweep (default {' '.join(map(str, DEFAULT_SEGMENTS))})")
    parser.add_argument("--sweep-steps", type=int, metavar="STEPS",
                        help="physics steps per sweep timing (default 5000; 500 with --quick)")
    parser.add_argument("--no-scenarios", action="store_true", help="skip section 1")
    parser.add_argument("--no-sweep", action="store_true", help="skip section 2")
    parser.add_argument("--no-friction", action="store_true", help="skip section 3")
    parser.add_argument("--no-batch", action="store_true", help="skip section 4 (batch scaling)")
    parser.add_argument("--no-lockstep", action="store_true", help="skip section 5 (lockstep batches)")
    parser.add_argument("--no-pays", action="store_true", help="skip section 6 (when a lockstep batch pays)")
    parser.add_argument("--profile", nargs="*", metavar="SCENARIO",
                        help="add a cProfile breakdown (us per control tick) of these scenarios "
                             "(no name: laser_arm_step)")
    parser.add_argument("--profile-top", type=int, default=25, help="rows of each profile (default 25)")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.chunk < 1:
        parser.error("--repeats and --chunk must be >= 1")
    if args.quick and args.max_duration is None:
        args.max_duration = 1.0
    if args.sweep_steps is None:
        args.sweep_steps = 500 if args.quick else 5000
    if args.profile is not None and not args.profile:
        args.profile = ["laser_arm_step"]

    t0 = time.perf_counter()
    print(header(args), flush=True)
    if not args.no_scenarios:
        print("\n" + bench_scenarios(args), flush=True)
    if not args.no_sweep:
        print("\n" + bench_segments(args), flush=True)
    if not args.no_friction:
        print("\n" + bench_friction(args), flush=True)
    if not args.no_batch:
        print("\n" + bench_batch(args), flush=True)
    if not args.no_lockstep:
        print("\n" + bench_lockstep(args), flush=True)
    if not args.no_pays:
        print("\n" + bench_pays(args), flush=True)
    for name in args.profile or ():
        print("\n" + profile(name, args), flush=True)
    print(f"\nbenchmark took {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
