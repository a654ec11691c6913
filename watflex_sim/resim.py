"""Re-simulate a recording: the same experiment on a (possibly patched) model, noise off."""
from __future__ import annotations

import copy
import math

import numpy as np

from .effects import CATALOGUE
from .engine import SimulationError, make_controller, simulate, warm_up
from .latest import Latest
from .lockstep import simulate_batch
from .model import ConfigError, load_model
from .recording import Recording
from .rigdesc import RigDescription, load_rig
from .scenario import DEFAULTS, check

OFFSET_REACH = CATALOGUE["sensor_offset"][1][0].high  # x a channel's spread: the largest sensor offset fitted
START_WINDOW_S = 0.02  # s: a recording's first samples, through which a parabola gives its start's values and rates
START_SAMPLES = 6  # ... at least this many
MOVING_SD = 5.0  # a sensor's rate this many standard errors from 0 at the first sample: the arm was moving ...
MOVING_SHARE = 0.25  # ... and this share of the channel's rms rate over the recording: a start's motion that matters
# (measured: EMPS' runs, whose reference starts moving at the first sample, 0.07; recordings cut mid-move 1.6-27)
JUDGE_S = 0.1  # s: a moving start is kept where the nominal model started so follows this much of the recording closer
STATE_TOLERANCE = 0.05  # rms misfit (in the commands' spreads) of a controller's replayed first commands that its
# state is fitted beyond (measured 0.0013-0.005 for Watflex runs from reset: the 12-bit converter steps)


def scenario_from_recording(rec: Recording, rig: RigDescription | None = None) -> dict:
    """A scenario that repeats `rec`'s experiment on `rig` (loaded; else by the recording's name): its
    references and disturbances replayed as recorded; closed loop re-runs the sidecar's controller,
    open loop replays the commands.

    Raises ConfigError when the recording cannot drive a simulation (no controller, no command).
    """
    meta, description = rec.meta, rig if rig is not None else load_rig(rec.rig)
    if meta.get("rig") != description.name:
        raise ConfigError(f"a recording of rig {meta.get('rig')!r} re-simulated on rig {description.name!r}")
    scenario = copy.deepcopy(DEFAULTS)
    time = rec.time - rec.time[0]
    period = description.period_of(meta)  # s
    scenario.update(
        rig=description.name, experiment=meta.get("experiment", "recording"), name=meta.get("experiment", "recording"),
        duration_s=float(round(time[-1] / period) + 1) * period,
        payload_kg=float(meta.get("payload_kg", 0.0)), locked_joints=dict(meta.get("locked_joints", {})),
        noise=False, seed=0, control_period_s=period,
    )
    for key in ("tilt_rad", "actuator_bench", "friction", "joint_friction", "timestep"):
        if key in meta.get("scenario", {}):  # our own recordings say how they were made
            scenario[key] = meta["scenario"][key]
    # start where the recording starts (its first finite samples): a generic rig's every sensor; the laser arm's and
    # Watflex's encoders where they read further from the nominal pose than an offset would (_away_from_nominal);
    # where it starts moving, every sensor the rig starts from, at the value and rate its first samples give
    scenario["initial"] = {c: _first(rec.channels[c]) for c in description.start_channels() if c in rec.channels
                           and (description.sensors == "generic" or c in description.position_channels()
                                and _away_from_nominal(rec.channels[c]))}
    inputs = [c for c in description.of_kind("reference") + description.of_kind("disturbance") if c in rec.channels]
    scenario["reference"] = [_samples(c, time, rec.channels[c]) for c in inputs]
    mode = meta.get("mode", "closed_loop")
    controller = dict(meta.get("controller") or description.controller)
    if mode == "open_loop" or controller.get("type") in ("none", "open_loop"):
        commands = [c for c in description.of_kind("command") if c in rec.channels]
        if not commands:
            raise ConfigError(f"open-loop recording has no command channel ({', '.join(description.of_kind('command'))})")
        scenario["controller"] = {"type": "none"}
        scenario["command"] = [_samples(c, time, rec.channels[c]) for c in commands]
    else:
        scenario["controller"] = controller
    return _start_as_recorded(rec, description, check(scenario))


_STARTS = Latest(1024)  # (rig, the recording's first samples) -> the start chosen for it (scenario keys)
START_KEYS = ("initial", "initial_rate", "initial_acceleration", "controller_state")


def _start_as_recorded(rec: Recording, rig: RigDescription, at_rest: dict) -> dict:
    """`at_rest` started as the recording starts: at rest but loaded, the links bent as the start sensors read that
    are further from the nominal pose than an offset (_away_from_nominal: a load held against friction); moving, every
    start sensor at the value, rate and acceleration a parabola through its first START_WINDOW_S gives (_start),
    where one of them moves (_moving); its controller in the state its first commands say (_controller_start), where
    it has one the run would not start it in. Each is kept only where the nominal model started so follows the
    recording's first JUDGE_S closer than the rest (a step at or just after the first sample moves an arm at rest as
    fast, on a motor quicker than the window; measured: a laser step 0-10 ms in and Watflex steps 0-10 ms in read as
    moving by their parabolas alone). The choice is made once per recording (per process), on the nominal model, so
    every model a diagnosis simulates starts alike."""
    judged = int(np.searchsorted(rec.time, rec.time[0] + JUDGE_S))  # the samples the choice compares
    key = (rig.name, rig.source, len(rec.time), rec.time[:judged].tobytes(),
           tuple((c, x[:judged].tobytes()) for c, x in rec.channels.items()))
    chosen = _STARTS.get(key)
    if chosen is None:
        options = [at_rest]
        bent = {c: _first(rec.channels[c]) for c in rig.start_channels() if c in rec.channels
                and c not in at_rest["initial"] and _away_from_nominal(rec.channels[c])}
        if bent:  # at rest, loaded: the links bent as their sensors read
            options.append(dict(at_rest, initial={**at_rest["initial"], **bent}))
        starts = {c: _start(rec.time, rec.channels[c]) for c in rig.start_channels() if c in rec.channels}
        if any(_moving(rec.time, rec.channels[c], starts[c][1], starts[c][3]) for c in starts):
            moving = copy.deepcopy(at_rest)
            for name, k in zip(START_KEYS, range(3)):
                moving[name] = {c: start[k] for c, start in starts.items() if math.isfinite(start[k])}
            options.append(moving)
        state = _controller_start(rec, rig, options[-1])
        if state:
            options.append(dict(options[-1], controller_state=state))
        best = options[0] if len(options) == 1 else min(options, key=lambda s: _start_misfit(rec, rig, s))
        chosen = {name: best[name] for name in START_KEYS}
        _STARTS.put(key, chosen)
    return dict(at_rest, **copy.deepcopy(chosen))


def _controller_start(rec: Recording, rig: RigDescription, scenario: dict) -> dict[str, float]:
    """The state of `scenario`'s controller at the recording's first sample (controllers.base.StatefulController)
    where the controller, started as the run would start it (at rest, or warmed up on the moving start's past) and
    fed the recording's measured channels, repeats the commands the recording holds worse than STATE_TOLERANCE over
    the first START_WINDOW_S: the state (after that warm-up) whose replay repeats them best over the first JUDGE_S,
    least squares in the commands' spreads, where it halves that misfit; {} otherwise, and where nothing can be
    replayed (open loop, a controller without state, a recording not sampled at the control period, a channel the
    controller reads that the recording lacks). Samples where a command sits at its recorded extreme are left out (a
    converter's limit the controller's output is cut to)."""
    if scenario["controller"]["type"] in ("none", "open_loop"):
        return {}
    period = float(scenario["control_period_s"])
    n = int(round(JUDGE_S / period))
    if len(rec.time) < n or not np.allclose(np.diff(rec.time[:n]), period, rtol=1e-3, atol=0.0):
        return {}
    spread = {c: float(np.nanstd(rec.channels[c])) for c in rig.of_kind("command") if c in rec.channels}
    commands = [c for c, s in spread.items() if s > 0]
    controller = make_controller(scenario, rig, period)
    if not commands or not hasattr(controller, "set_state"):
        return {}
    inputs = {c: x[:n].tolist() for c, x in rec.channels.items() if c not in spread}
    rows = [{c: x[k] for c, x in inputs.items()} for k in range(n)]
    recorded = {c: rec.channels[c][:n] for c in commands}
    usable = {c: np.isfinite(x) & (x != np.nanmax(rec.channels[c])) & (x != np.nanmin(rec.channels[c]))
              for c, x in recorded.items()}
    warm = {c: (r, scenario["initial_acceleration"].get(c, 0.0)) for c, r in scenario["initial_rate"].items()}

    def misfit(start, values: dict | None, samples: int) -> np.ndarray:
        """The replay's misfit per usable command sample (in spreads) from `start` (a copy is run), set to values."""
        law = copy.deepcopy(start)
        if values is not None:
            law.set_state(values)
        out = []
        for k in range(samples):
            command = law(k * period, rows[k])
            out.extend((command[c] - recorded[c][k]) / spread[c] if usable[c][k] else 0.0 for c in commands)
        return np.asarray(out)

    try:
        controller.reset()
        if warm:
            warm_up(controller, rows[0], warm, period)
        elif scenario["initial"] and hasattr(controller, "settle"):  # as engine.ControlLoop starts it at rest
            controller.settle(rows[0])
        first = int(round(START_WINDOW_S / period))
        if _rms(misfit(controller, None, first)) <= STATE_TOLERANCE:
            return {}
        if not warm:  # a run at rest sets the state after a warm-up on the first reading held
            warm_up(controller, rows[0], {}, period)
        names = list(controller.state())
        if not names:
            return {}
        start = np.array([controller.state()[name] for name in names])
        before = _rms(misfit(controller, None, n))
        fitted = _gauss_newton(lambda x: misfit(controller, dict(zip(names, x)), n), start)
        after = _rms(misfit(controller, dict(zip(names, fitted)), n))
    except (KeyError, ValueError):  # a channel the recording lacks; a state the law refuses
        return {}
    return dict(zip(names, map(float, fitted))) if after < 0.5 * before else {}


def _gauss_newton(residuals, x: np.ndarray, rounds: int = 4) -> np.ndarray:
    """x lowering the sum of squares of residuals(x): Gauss-Newton steps on a forward-difference Jacobian, each the
    least-norm one (np.linalg.lstsq on the columns scaled to unit norm, rcond 1e-9), so a state the residuals do not
    see (an observer's last torque under Ostojic's gain, which its next command does not depend on) stays where it
    was; a step that does not lower the sum ends the search. A controller's replay is linear in its state but
    where a limit cuts its output, so a few rounds do."""
    r = residuals(x)
    for _ in range(rounds):
        h = 1e-6 * np.maximum(1.0, np.abs(x))
        jacobian = np.column_stack([(residuals(x + h[i] * np.eye(x.size)[i]) - r) / h[i] for i in range(x.size)])
        norm = np.linalg.norm(jacobian, axis=0)
        seen = norm > 1e-9 * norm.max() if norm.max() > 0 else norm > 0
        step = np.zeros_like(x)
        step[seen] = np.linalg.lstsq(jacobian[:, seen] / norm[seen], -r, rcond=1e-9)[0] / norm[seen]
        trial = residuals(x + step)
        if not np.sum(trial**2) < np.sum(r**2):
            break
        x, r = x + step, trial
    return x


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else 0.0


def _start_misfit(rec: Recording, rig: RigDescription, scenario: dict) -> float:
    """Sum over the recording's measured and command channels of the mean squared misfit, in the channel's spread, of
    the nominal model run from `scenario`'s start over the recording's first JUDGE_S (inf where it diverges)."""
    period = float(scenario["control_period_s"])
    short = dict(scenario, duration_s=min(float(scenario["duration_s"]), round(JUDGE_S / period) * period))
    try:
        sim = simulate(check(short), rig=rig).recording
    except SimulationError:
        return math.inf
    within = rec.time - rec.time[0] <= sim.time[-1] + 1e-9  # s: the recording's samples the run covers
    part = Recording(rec.time[within], {c: v[within] for c, v in rec.channels.items()}, rec.meta)
    sampled = _sampled(part, sim)  # at the recording's own times (a logger's rate may differ from the loop's)
    total = 0.0
    for c in rig.of_kind("measured") + rig.of_kind("command"):  # a closed loop's commands are its response too
        if c in part.channels and c in sampled.channels:
            x, y = part.channels[c], sampled.channels[c]
            spread = float(np.nanstd(rec.channels[c]))
            ok = np.isfinite(x) & np.isfinite(y)
            if spread > 0 and ok.any():
                total += float(np.mean(((y[ok] - x[ok]) / spread) ** 2))
    return total


def _away_from_nominal(values: np.ndarray) -> bool:
    """Whether an encoder's first reading is further from the nominal pose (0 rad) than the largest sensor offset the
    diagnosis fits (OFFSET_REACH x the channel's spread): the arm started there. Nearer, the run starts at the nominal
    pose and the reading is an offset to find, as a rig started at its nominal pose shows one."""
    first = _first(values)
    return math.isfinite(first) and abs(first) > OFFSET_REACH * float(np.nanstd(values))


def _start(time: np.ndarray, values: np.ndarray) -> tuple[float, float, float, float]:
    """(value, rate, acceleration, the rate's standard error) at a channel's first finite sample (unit, unit/s,
    unit/s^2), from a parabola through its samples in the first START_WINDOW_S (at least START_SAMPLES); NaNs where it
    has too few."""
    finite = np.flatnonzero(np.isfinite(values))
    if finite.size < START_SAMPLES:
        return math.nan, math.nan, math.nan, math.nan
    t = time[finite] - time[finite[0]]
    take = max(START_SAMPLES, int(np.searchsorted(t, START_WINDOW_S, side="right")))
    t, y = t[:take], values[finite[:take]]
    design = np.vander(t, 3, increasing=True)  # 1, t, t^2
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    variance = float(np.sum((y - design @ coef) ** 2)) / (len(y) - 3)
    sd = math.sqrt(variance * np.linalg.inv(design.T @ design)[1, 1])
    return float(coef[0]), float(coef[1]), 2.0 * float(coef[2]), sd


def _moving(time: np.ndarray, values: np.ndarray, rate: float, sd: float) -> bool:
    """Whether a sensor's rate at its first sample says the arm was moving when the recording began: MOVING_SD
    standard errors from rest, a change over START_WINDOW_S of more than two of its steps (the smallest change
    between its samples), and MOVING_SHARE of the channel's rms rate over the whole recording (over START_WINDOW_S)."""
    finite = np.isfinite(values)
    t, x = time[finite], values[finite]
    change = np.abs(np.diff(x))
    step = float(change[change > 0].min()) if np.any(change > 0) else 0.0
    if not (math.isfinite(rate) and abs(rate) > MOVING_SD * sd and abs(rate) * START_WINDOW_S > 2 * step):
        return False
    later = np.searchsorted(t, t + START_WINDOW_S)  # the sample START_WINDOW_S after each
    ok = later < len(t)
    rates = (x[later[ok]] - x[ok]) / (t[later[ok]] - t[ok])
    return rates.size > 0 and abs(rate) > MOVING_SHARE * float(np.sqrt(np.mean(rates**2)))


def _first(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite[0]) if finite.size else float("nan")


def _samples(channel: str, time: np.ndarray, values: np.ndarray) -> dict:
    return {"channel": channel, "kind": "samples", "time_s": time.tolist(), "values": values.tolist()}


def resimulate(rec: Recording, effects: list[dict] = (), parameters: dict | None = None,
               until: float | None = None, noise_seed: int | None = None, rig: RigDescription | None = None) -> Recording:
    """Simulate `rec`'s experiment with `effects` and refit `parameters`; channels sampled at rec.time.

    With `until` (s from the start) the simulation stops there; later samples hold its last value.
    With `noise_seed` the rig's measurement noise is on (fed back through the controller as on the rig).
    `rig`: the recording's rig, loaded (else loaded by its name)."""
    rig = rig if rig is not None else load_rig(rec.rig)
    return _sampled(rec, simulate(_resim_scenario(rig, rec, effects, parameters, until, noise_seed), rig=rig).recording)


def resimulate_many(jobs: list[tuple], nthread: int = 0, rig: RigDescription | None = None) -> list[Recording | SimulationError]:
    """`resimulate(*job)` for every job (rec, effects, parameters, until, noise_seed[, finer]), stepped together
    in lockstep (lockstep.simulate_batch, nthread 0: all CPUs); a diverged job gives its SimulationError,
    and so does one whose model cannot be built (a payload lighter than none: the diagnosis tried a
    parameter beyond what is physical), without stopping the others.
    `rig`: the recordings' rig, loaded (else each rig is loaded by its name)."""
    out: list = [None] * len(jobs)
    by_rig: dict[str, list[int]] = {}
    for k, job in enumerate(jobs):
        by_rig.setdefault(job[0].meta.get("rig"), []).append(k)
    for name, ks in by_rig.items():
        description = rig if rig is not None and rig.name == name else load_rig(jobs[ks[0]][0].rig)
        scenarios = [_resim_scenario(description, *jobs[k]) for k in ks]
        try:
            results = simulate_batch(scenarios, nthread=nthread, rig=description)
        except ConfigError:
            results = [_built_or_error(s, nthread, description) for s in scenarios]
        for k, result in zip(ks, results):
            out[k] = result if isinstance(result, SimulationError) else _sampled(jobs[k][0], result.recording)
    return out


def _built_or_error(scenario: dict, nthread: int, rig: RigDescription):
    """One scenario simulated alone; a SimulationError if the effects or parameters it was given make
    a model that cannot be built (a ConfigError of the recording itself stays one)."""
    try:
        return simulate_batch([scenario], nthread=nthread, rig=rig)[0]
    except ConfigError as exc:
        if not scenario["effects"] and not scenario["parameters"]:
            raise
        return SimulationError(f"the model cannot be built: {exc}")


def finer_discretisation(rig: RigDescription, scenario: dict, factor: float) -> dict:
    """Scenario keys that simulate `scenario` `factor` x finer: that many times the segments per flexible
    part and a physics step that many times shorter ({} for factor 1). What the simulator's own
    discretisation leaves (its results against a finer one's) is model error the data cannot resolve.
    A factor below 1 is coarser (the screening's cheap signatures): the segments rounded, at least 2, and the
    step made longer only where it still divides the control period; {} where neither changes."""
    if factor == 1:
        return {}
    out = {}
    segments = getattr(rig.segmented(scenario["n_segments"]), "n_segments", 0)
    if segments and max(2, round(factor * segments)) != segments:
        out["n_segments"] = max(2, round(factor * segments))
    step = (scenario["timestep"] or model_timestep(rig)) / factor  # s: the scenario's, else the model's
    ticks = rig.period_of(scenario) / step  # physics steps per control period
    if factor > 1 or (round(ticks) >= 1 and abs(ticks - round(ticks)) < 1e-9):
        out["timestep"] = step
    return out


def model_timestep(rig: RigDescription) -> float:
    """The physics step (s) the rig's model is built with: its parameters', else the compiled model's
    (a rig described by a datasheet alone)."""
    return getattr(rig.params, "timestep", 0.0) or float(load_model(rig).opt.timestep)


def _resim_scenario(rig: RigDescription, rec: Recording, effects=(), parameters=None, until=None, noise_seed=None,
                    finer: float = 1) -> dict:
    scenario = scenario_from_recording(rec, rig)
    scenario.update(finer_discretisation(rig, scenario, finer))
    if noise_seed is not None:
        scenario.update(noise=True, seed=int(noise_seed))
    if until is not None:
        scenario["duration_s"] = min(scenario["duration_s"], until + 2 * scenario["control_period_s"])
    scenario["effects"] = list(effects)
    scenario["parameters"] = dict(parameters or {})
    return scenario


SAME_TIME = 1e-6  # x the simulation's sample spacing: a recording's time this near one of its samples is that sample's


def _sampled(rec: Recording, sim: Recording) -> Recording:
    """A simulation's channels sampled at the recording's times: at the simulation's own sample where a recording's
    time is within SAME_TIME of it, else interpolated. A logger's clock started at 100 s leaves its times, less the
    first, ~1e-14 s off the ticks, and interpolating a channel the simulation gives on some ticks only (the 25 Hz
    camera, NaN between frames) beside an empty tick gives nothing: seed 94's Watflex recordings so re-logged compared
    their camera on 6 frames of 150 (at whole seconds), and on none once a glitch took one of them out."""
    t = rec.time - rec.time[0]
    grid = sim.time
    after = np.clip(np.searchsorted(grid, t), 1, grid.size - 1)
    nearest = np.where(np.abs(grid[after - 1] - t) <= np.abs(grid[after] - t), after - 1, after)
    tolerance = SAME_TIME * float(np.median(np.diff(grid))) if grid.size > 1 else 0.0
    t = np.where(np.abs(grid[nearest] - t) <= tolerance, grid[nearest], t)
    channels = {c: np.interp(t, sim.time, v) for c, v in sim.channels.items() if c in rec.channels}
    return Recording(rec.time.copy(), channels, sim.meta)
