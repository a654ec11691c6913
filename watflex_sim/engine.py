"""The control loop (1 ms, or a generic rig's own period): sensors -> controller -> actuators,
zero-order hold over physics substeps."""
from __future__ import annotations

import copy
import hashlib
import inspect
import logging
import math
import time as wallclock
from dataclasses import dataclass
from typing import Callable

import mujoco
import numpy as np

from . import __version__
from .effects import Patch, apply_effects, apply_parameters
from .joint_friction import FrictionCallback, patched, scenario_frictions
from .latest import Latest
from .model import ConfigError, load_model
from .params import CONTROL_PERIOD
from .recording import FORMAT, Recording
from .rigdesc import RigDescription, load_rig
from .signals import make_signal

log = logging.getLogger(__name__)

class SimulationError(RuntimeError):
    """MuJoCo warned or the state diverged; the message names the time and the cause."""


@dataclass
class SimResult:
    recording: Recording
    frames: np.ndarray  # (n_frames, n_points, 3) arm drawing points, m
    frame_time: np.ndarray  # (n_frames,) s
    wall_time_s: float


def substeps(control_period: float, timestep: float) -> int:
    """Physics steps per control period; ConfigError unless the period is a whole multiple."""
    n = round(control_period / timestep)
    if n < 1 or abs(n * timestep - control_period) > 1e-9 * control_period:
        raise ConfigError(
            f"control period {control_period * 1e3:g} ms is not a whole multiple of the physics step {timestep * 1e3:g} ms"
        )
    return n


def make_controller(scenario: dict, rig: RigDescription, period: float = CONTROL_PERIOD):
    """The scenario's controller on `rig`: a registered closed-loop type, or open loop from its command
    signals. A controller that takes a `period` and is not given one runs at the rig's (s)."""
    from .controllers import CONTROLLERS, OpenLoop  # controllers import watflex_sim.params: import late

    spec = dict(scenario["controller"])
    kind = spec.pop("type")
    sign = 1.0 if scenario["direction"] == "positive" else -1.0
    if kind in ("none", "open_loop"):
        return OpenLoop({c["channel"]: make_signal(c, sign) for c in scenario["command"]})
    if kind == "parallel":  # controllers/parallel.py: each part a controller table of its own
        return _parallel(spec, scenario, rig, period)
    if kind not in CONTROLLERS:
        raise ConfigError(f"unknown controller type {kind!r} (known: none, parallel, {', '.join(CONTROLLERS)})")
    compensation = spec.pop("compensation", None)
    if "period" not in spec and period != CONTROL_PERIOD and "period" in inspect.signature(CONTROLLERS[kind]).parameters:
        spec["period"] = period
    try:
        controller = CONTROLLERS[kind](**spec)
        if compensation is not None:  # [controller.compensation]: friction compensation around it
            from .controllers.friction_compensation import wrap_compensation

            controller = wrap_compensation(controller, compensation, rig.params)
        return controller
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"controller {kind!r}: {exc}") from None


def _parallel(spec: dict, scenario: dict, rig: RigDescription, period: float):
    """The parts of a `parallel` controller, each built as make_controller builds one; ConfigError where they are not
    a list of controller tables or two drive the same command (each tried once, on a copy, on zero readings)."""
    from .controllers.parallel import Parallel

    parts = spec.pop("parts", None)
    if spec or not isinstance(parts, list) or not parts or not all(isinstance(p, dict) and "type" in p for p in parts):
        raise ConfigError("controller 'parallel': needs only `parts`, a list of controller tables, each with its type")
    if any(p["type"] in ("parallel", "none", "open_loop") for p in parts):
        raise ConfigError("controller 'parallel': a part must be a closed-loop controller "
                          "(not parallel, none, open_loop)")
    built = [make_controller({**scenario, "controller": p}, rig, period) for p in parts]
    drives: dict[str, int] = {}
    for i, part in enumerate(built):
        trial = copy.deepcopy(part)
        trial.reset()
        try:
            commands = trial(0.0, {c: 0.0 for c in rig.channels})
        except KeyError:  # a channel the rig lacks: ControlLoop names it
            continue
        for command in commands:
            if command in drives:
                raise ConfigError(f"controller 'parallel': parts {drives[command]} and {i} both drive {command}")
            drives[command] = i
    return Parallel(built)


def _references(scenario: dict, rig: RigDescription) -> dict[str, Callable[[float], float]]:
    """Reference signals by channel (rad); a laser-arm 'arc_m' step is converted by the beam length."""
    sign = 1.0 if scenario["direction"] == "positive" else -1.0
    out = {}
    for table in scenario["reference"]:
        table = dict(table)
        scale = 1.0
        if "arc_m" in table:  # laser spot displacement along the tip's arc (m) -> rad
            table["amplitude"], scale = table.pop("arc_m"), 1.0 / rig.params.beam.length
        out[table["channel"]] = make_signal(table, sign, scale)
    return out


_last_warning = [""]


def _keep_warning(message: str) -> None:
    """MuJoCo warning handler: keep the text for the error message (and write no MUJOCO_LOG.TXT)."""
    _last_warning[0] = message.strip()


mujoco.set_mju_user_warning(_keep_warning)


WARM_UP_S = 0.2  # s of a moving start's past fed to the controller (engine.warm_up): a 10 Hz rate filter settles
MAX_QVEL = 1e4  # rad/s or m/s: beyond this a run is taken as diverged
CHECK_EVERY = 10  # control periods between divergence checks (MuJoCo's warning counters persist)


def _check_state(model: mujoco.MjModel, data: mujoco.MjData, t: float) -> None:
    """Raise SimulationError if MuJoCo warned (bad qacc, full contact buffer, ...), the velocity
    is not finite or exceeds MAX_QVEL; `t` (s) is the time the check is made."""
    counts = data.warning.number
    qvel = data.qvel
    if not counts.any() and float(qvel @ qvel) < MAX_QVEL**2:  # NaN fails the comparison
        return
    if counts.any():
        cause = mujoco.mjtWarning(int(np.flatnonzero(counts)[0])).name
        raise SimulationError(
            f"simulation diverged (detected at t = {t:.3f} s): MuJoCo warning {cause} ({_last_warning[0]}); "
            f"try a smaller timestep or lower gains; nothing was written"
        )
    raise SimulationError(
        f"simulation diverged (detected at t = {t:.3f} s): velocity not finite or above {MAX_QVEL:g}; "
        f"try a smaller timestep or lower gains; nothing was written"
    )


class GrowthMonitor:
    """Flags an exponentially growing oscillation long before it overflows.

    It watches E = sum of qvel^2 over the flexible coordinates (DOFs of joints with a spring,
    i.e. the beam/link segments; all DOFs if there are none), keeps the largest E of each
    WINDOW-tick window and raises SimulationError when E has grown by more than GROWTH from one
    window to the next RUN times in a row, at a steady rate (the mean log-ratio of the last
    half of those windows is at least STEADY times that of the first half) and the last window
    exceeds every window before the growth began. A step grows once; motion starting from rest
    (a ramped load, a trajectory) grows like a power of t, its ratios falling towards 1 (a 4 s
    half-cosine force on the locked Watflex: x34, x12, x5.8, ... x1.5); a numerical instability
    (a step too large for the stiffest chain, gains too high) multiplies E by a constant factor
    per window: the laser arm at 0.2 ms grows x4.1 per 20 ms and is flagged at 0.46 s (README
    "Damping, time step and integrator")."""

    WINDOW = 20  # control periods (20 ms)
    GROWTH = 1.5  # energy ratio between consecutive windows counted as growth
    RUN = 10  # consecutive growing windows (x1.5^10 = x58 in 200 ms); shipped scenarios reach at most 6
    STEADY = 0.8  # exponential growth keeps its rate; power-law growth from rest slows down

    def __init__(self, model: mujoco.MjModel, n_segments: int):
        springs = [j for j in range(model.njnt) if model.jnt_stiffness[j] > 0]
        self.dofs = np.array([model.jnt_dofadr[j] for j in springs] or range(model.nv), dtype=int)
        self.timestep, self.n_segments = model.opt.timestep, n_segments
        self.current = self.previous = self.before = 0.0  # window maxima of E, (rad/s)^2
        self.run, self.longest = 0, 0  # consecutive growing windows now, most seen (for tests)
        self.rates: list[float] = []  # log energy ratios of the current run's windows

    def update(self, data: mujoco.MjData, k: int) -> None:
        """Feed the state after control period k (0-based); sampled every other period (~1 us a tick)."""
        if k % 2:
            v = data.qvel[self.dofs]
            self.current = max(self.current, float(v @ v))
        if (k + 1) % self.WINDOW == 0:
            self.close_window(k)

    def close_window(self, k: int) -> None:
        """End the window that closes after control period k: count growth, raise if it is exponential."""
        if self.current > self.GROWTH * self.previous:
            self.run += 1
            self.rates = (self.rates + [math.log(self.current / self.previous) if self.previous else math.inf])[-self.RUN:]
        else:
            self.before = max(self.before, self.previous if self.run else self.current)
            self.run, self.rates = 0, []
        self.longest = max(self.longest, self.run)
        half = self.RUN // 2
        if (self.run >= self.RUN and self.current > self.before
                and sum(self.rates[half:]) >= self.STEADY * sum(self.rates[:half])):
            t = (k + 1) * CONTROL_PERIOD
            raise SimulationError(
                f"simulation unstable (detected at t = {t:.3f} s): the flexible coordinates' energy grew "
                f"x{math.exp(self.rates[-1]):.1f} per {self.WINDOW} ms for {self.run * self.WINDOW} ms, an "
                f"exponentially growing oscillation; likely cause: the physics step {self.timestep * 1e3:g} ms "
                f"is too large for the stiffest flexible chain ({self.n_segments} segments; stable steps in "
                f"README 'Damping, time step and integrator') or the gains are too high; nothing was written")
        if not self.run:
            self.before = max(self.before, self.current)
        self.previous, self.current = self.current, 0.0


class _References:
    """Reference values by tick: `refs[k]` is {channel: value} at t = k ms (columns, not dicts per tick)."""

    def __init__(self, columns: dict[str, np.ndarray], n: int):
        self.columns, self.n = {c: np.asarray(v, dtype=float).tolist() for c, v in columns.items()}, n  # Python floats

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k: int) -> dict[str, float]:
        return {c: v[k] for c, v in self.columns.items()}


SETTLED_KEPT = 64  # models whose settled start `_settle_bearings` keeps (a diagnosis simulates one model for each of
# its recordings, and most candidate effects - friction laws, sensor and actuator effects - leave the model as it is)
_SETTLED = Latest(SETTLED_KEPT)  # (model digest, s) -> (state, warnings)


def _model_digest(model: mujoco.MjModel) -> bytes:
    """A digest of every field of `model` (its binary form, mj_saveModel): equal digests, the same model."""
    buffer = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return hashlib.blake2b(buffer.tobytes(), digest_size=20).digest()


def _settle_bearings(model: mujoco.MjModel, data: mujoco.MjData, seconds: float = 0.3) -> None:
    """Let air-bearing slides sink onto the glass, then restore the planar pose at rest. `data` is fresh, at the
    model's keyframe: the result depends on the model alone, so a model settled before (SETTLED_KEPT, by its digest)
    gets that one's integration state (the solver's warm start among it) and warning counts, then `mj_forward`: bit
    for bit what settling again gives (~20 ms of physics on a Watflex model)."""
    slides = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE]
    if not slides:
        return
    key = (_model_digest(model), seconds)
    settled = _SETTLED.get(key)
    if settled is not None:
        state, warnings = settled
        mujoco.mj_setState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        for warning, (number, info) in zip(data.warning, warnings):
            warning.number, warning.lastinfo = int(number), int(info)
        mujoco.mj_forward(model, data)
        return
    qpos0 = data.qpos.copy()
    mujoco.mj_step(model, data, nstep=int(round(seconds / model.opt.timestep)))
    keep = [model.jnt_qposadr[j] for j in slides]
    settled = data.qpos[keep].copy()
    data.qpos[:] = qpos0
    data.qpos[keep] = settled
    data.qvel[:] = 0
    data.time = 0.0
    mujoco.mj_forward(model, data)
    state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
    warnings = np.array([(w.number, w.lastinfo) for w in data.warning], dtype=np.int64)
    _SETTLED.put(key, (state, warnings))


def warm_up(controller, obs: dict[str, float], warm: dict[str, tuple[float, float]], period: float) -> None:
    """A run that starts moving, or sets its controller's state: the controller fed the WARM_UP_S before the start
    that `warm` (channel -> (rate, acceleration) at the start, unit/s and unit/s^2) implies, each such channel on a
    parabola back from its first reading `obs`, the rest as at the start, at every `period` (s), its commands
    discarded, so that its rate filters and observers start in step with the motion, not at rest."""
    for i in range(round(WARM_UP_S / period), 0, -1):
        back = i * period  # s before the start
        controller(-back, {**obs, **{c: obs[c] - rate * back + 0.5 * acceleration * back * back
                                     for c, (rate, acceleration) in warm.items() if c in obs}})


class ControlLoop:
    """A scenario set up to run: model, data, rig, joint friction, controller and references.

    Use it as `with ControlLoop(scenario) as loop:` (the friction callback is process-global
    and installed only inside the block). `tick(k)` does control period k (the rig's, 1 ms unless it says):
    references -> sensors -> controller -> saturation/converters -> `n_sub` physics steps with
    the command held (zero-order hold), then the divergence check every CHECK_EVERY periods.
    Raises ConfigError for an impossible configuration.
    """

    def __init__(self, scenario: dict, parameter_names: dict[str, tuple[str, str]] | None = None,
                 rig: RigDescription | None = None):
        """`rig`: the scenario's rig, loaded (rigdesc.load_rig); loaded here by its name if not given."""
        self.scenario = scenario
        rig_name = scenario["rig"]
        self.description = description = rig if rig is not None else load_rig(rig_name)
        if description.name != rig_name:
            raise ConfigError(f"scenario of rig {rig_name!r} given the rig {description.name!r} ({description.source})")
        self.patch = patch = Patch()
        names = parameter_names if parameter_names is not None else description.parameter_knobs()
        apply_parameters(patch, scenario["parameters"], names)
        apply_effects(patch, scenario["effects"])
        self.model = load_model(
            description,
            payload_kg=scenario["payload_kg"] + patch.payload_kg,
            locked_joints=scenario["locked_joints"],
            tilt_rad=scenario["tilt_rad"] + patch.tilt_rad,
            tilt_azimuth_rad=scenario["tilt_azimuth_rad"],
            timestep=scenario["timestep"] or None,
            actuator_bench=scenario["actuator_bench"],
            edits=patch.spec_edits,
            n_segments=scenario["n_segments"],
        )
        for edit in patch.model_edits:
            edit(self.model)
        self.period = period = description.period_of(scenario)  # s
        self.n_sub = substeps(period, self.model.opt.timestep)
        self.jitter = description.control_jitter_s  # s
        self.data = mujoco.MjData(self.model)
        mujoco.mj_resetDataKeyframe(self.model, self.data, 0)
        mujoco.mj_forward(self.model, self.data)
        _settle_bearings(self.model, self.data)
        self.rig = description.make_sensors(self.model, self.data, scenario, period)
        initial, rates = scenario.get("initial") or {}, scenario.get("initial_rate") or {}
        accelerations = scenario.get("initial_acceleration") or {}
        if initial or rates or accelerations:  # start where a recording starts
            unknown = sorted((set(initial) | set(rates) | set(accelerations)) - set(description.start_channels()))
            if unknown:
                raise ConfigError(f"initial: rig {rig_name!r} cannot start from {', '.join(unknown)} "
                                  f"(it starts from {', '.join(description.start_channels())})")
            period = description.period_of(scenario)  # s
            inputs = {c: (float(f(0.0)), (float(f(period)) - float(f(0.0))) / period)
                      for c, f in _references(scenario, description).items()}  # the references where the run starts
            self.rig.start_at({**{c: v for c, (v, _) in inputs.items()}, **self._true_values(initial)},
                              {**{c: r for c, (_, r) in inputs.items()}, **self._true_values(rates, rates=True)})
        if scenario["friction"] == "none":
            self.model.dof_frictionloss[:] = 0.0
        frictions = patched(scenario_frictions(description, scenario), patch.friction, patch.friction_add)
        self.friction = FrictionCallback(self.model, self.data, frictions)
        self.controller = make_controller(scenario, description, period)
        reads = getattr(self.controller, "channels", None)  # a law on named channels says which it reads
        unknown = sorted(set(reads()) - set(self.rig.channels)) if callable(reads) else []
        if unknown:
            raise ConfigError(f"controller {scenario['controller']['type']!r} reads unknown channel(s) of {rig_name}: {', '.join(unknown)}")
        self.controller.reset()
        self._warm = {c: (float(r), float(accelerations.get(c, 0.0))) for c, r in rates.items()}  # a moving start
        self._controller_state = dict(scenario.get("controller_state") or {})  # set after the warm-up
        self._settle = bool(initial) and hasattr(self.controller, "settle")  # controllers.base.SettlingController
        if self._controller_state and not hasattr(self.controller, "set_state"):
            raise ConfigError(f"controller_state: controller {scenario['controller']['type']!r} has no state to set")
        references = _references(scenario, description)
        unknown = set(references) - set(self.rig.input_channels)
        if unknown:
            raise ConfigError(f"unknown reference channel(s) for {rig_name}: {', '.join(sorted(unknown))}")
        self.n_ticks = int(round(scenario["duration_s"] / period))
        # references depend on t only: tabulate them once for every tick
        times = np.arange(self.n_ticks) * period
        self.references = _References({c: f.table(times) if hasattr(f, "table") else np.array([f(t) for t in times.tolist()])
                                       for c, f in references.items()}, self.n_ticks)
        self.n_segments = getattr(description.segmented(scenario["n_segments"]), "n_segments", 0)
        self.monitor = GrowthMonitor(self.model, self.n_segments)
        ticks = CONTROL_PERIOD / period  # delays are counted in CONTROL_PERIOD ticks (effects.delay): in ours
        self._commands = [{}] * round(patch.command_delay * ticks)  # FIFO of commands waiting for the plant
        self._sensor_fifo = {c: [None] * round(n * ticks) for c, n in patch.sensor_delay.items()
                             if round(n * ticks) > 0}  # filled by the first reading
        self._actuators = {c: (a, self.rig.command_scale.get(c, 1.0))
                           for c, a in self.rig.command_actuators.items() if c in patch.actuator}
        self.delays = _output_delays(self.jitter, self.model.opt.timestep, self.n_sub, self.n_ticks, scenario["seed"],
                                     description.source)
        self._applied, self._due = self.data.ctrl.copy(), 0  # the plant input held, substep the new one is due

    def __enter__(self) -> "ControlLoop":
        self.friction.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.friction.__exit__(*exc)

    def tick(self, k: int) -> tuple[dict[str, float], dict[str, float]]:
        """Run control period k; return (measured channels, recorded commands) at its start."""
        obs, recorded = self.control(k)
        self.friction.take_applied()  # the friction's torque is added to what the rig applies, during the steps
        if self._due:  # jitter: the previous command holds until the new one is due
            mujoco.mj_step(self.model, self.data, nstep=self._due)
            self.release(self._due)
        mujoco.mj_step(self.model, self.data, nstep=self.n_sub - self._due)
        self.friction.restore_applied()
        mujoco.mj_kinematics(self.model, self.data)  # mj_step leaves positions one substep old
        self.monitor.update(self.data, k)
        if k % CHECK_EVERY == CHECK_EVERY - 1 or k == self.n_ticks - 1:
            _check_state(self.model, self.data, (k + 1) * self.period)
        return obs, recorded

    def control(self, k: int) -> tuple[dict[str, float], dict[str, float]]:
        """The control half of period k, shared with lockstep.simulate_batch: sensors, controller,
        converters and effects, up to the plant input in `data.ctrl`; returns (measured, recorded)."""
        t = k * self.period
        obs = self.rig.observe(self.references[k])
        if self.patch.sensor or self._sensor_fifo:
            obs = self._sense(obs)
        if k == 0 and self._settle and not (self._warm or self._controller_state):
            self.controller.settle(obs)  # at rest away from the nominal pose: as the law holds it there
        if k == 0 and (self._warm or self._controller_state):
            warm_up(self.controller, obs, self._warm, self.period)
            if self._controller_state:
                try:
                    self.controller.set_state(self._controller_state)
                except ValueError as exc:
                    raise ConfigError(f"controller_state: {exc}") from None
        command = self.controller(t, obs)
        recorded = self.rig.actuate(command)
        if self._commands:  # delayed plant input; the recorded command is the one computed now
            self._commands.append(command)
            recorded = {**self.rig.actuate(self._commands.pop(0)), **{c: recorded[c] for c in self.rig.command_channels}}
        for channel, (actuator, scale) in self._actuators.items():  # effects act in the command's unit
            gain, offset, limit = self.patch.actuator[channel]
            u = self.data.ctrl[actuator] / scale * gain + offset
            self.data.ctrl[actuator] = scale * max(-limit, min(limit, u))
        recorded.update(self._sense(self.rig.monitor()) if self.patch.sensor else self.rig.monitor())
        if self.delays is not None:  # the new plant input waits delays[k] substeps (release)
            self._due = int(self.delays[k])
            if self._due:
                self._applied, self.data.ctrl[:] = self.data.ctrl.copy(), self._applied
            else:
                self._applied = self.data.ctrl.copy()
        return obs, recorded

    def release(self, j: int) -> None:
        """Before physics substep j of a tick: the new plant input arrives if it is due (jitter)."""
        if j == self._due and j:
            self.data.ctrl[:] = self._applied

    def _true_values(self, readings: dict[str, float], rates: bool = False) -> dict[str, float]:
        """What the rig's own sensors would read (channel -> value) where the sensor gain and offset effects make
        them read `readings`: a run started at a recording's first samples with an encoder offset in the model
        starts where that offset puts the joint, not at the reading. `rates`: readings are rates of change (unit/s),
        which the offsets leave alone."""
        out = dict(readings)
        for channel, (gain, offset) in self.patch.sensor.items():
            if channel in out and gain:
                out[channel] = (out[channel] - (0.0 if rates else offset)) / gain
        return out

    def _sense(self, obs: dict[str, float]) -> dict[str, float]:
        """Sensor gain/offset and delay effects on the measured channels."""
        obs = dict(obs)
        for channel, (gain, offset) in self.patch.sensor.items():
            if channel in obs:
                obs[channel] = obs[channel] * gain + offset
        for channel, fifo in self._sensor_fifo.items():
            if channel in obs:
                if fifo[0] is None:  # before the delay has passed, the sensor reads its first value
                    fifo[:] = [obs[channel]] * len(fifo)
                fifo.append(obs[channel])
                obs[channel] = fifo.pop(0)
        return obs


def _output_delays(jitter: float, timestep: float, n_sub: int, n_ticks: int, seed: int,
                   source: str) -> np.ndarray | None:
    """Per tick, the physics substeps by which the command reaches the plant late: uniform on
    0..round(jitter / timestep) (mean jitter / 2, s), drawn from the scenario's seed; None without jitter.
    ConfigError naming the rig file `source` unless jitter is whole physics steps below the period."""
    if not jitter:
        return None
    most = round(jitter / timestep)
    if abs(most * timestep - jitter) > 1e-9 * jitter or most >= n_sub:
        raise ConfigError(f"{source}: control_jitter_s {jitter:g} s is not a whole number of physics steps "
                          f"({timestep * 1e3:g} ms) below the control period")
    return np.random.default_rng([seed, 0x6A17]).integers(0, most + 1, size=n_ticks)


def simulate(scenario: dict, progress: Callable[[float], None] | None = None,
             parameter_names: dict[str, tuple[str, str]] | None = None, rig: RigDescription | None = None) -> SimResult:
    """Run a checked scenario (scenario.load_scenario) and return its recording and drawings;
    `rig`: its rig, loaded (else loaded by the scenario's name).

    Raises ConfigError for an impossible configuration and SimulationError on divergence.
    `progress(fraction)` is called about every simulated 0.1 s.
    """
    return run(ControlLoop(scenario, parameter_names, rig), progress)


def run(loop: ControlLoop, progress: Callable[[float], None] | None = None) -> SimResult:
    """Run a set-up ControlLoop to its end (the single-run driver); as `simulate`."""
    scenario = loop.scenario
    tape = Tape(loop)
    report_every = max(1, int(0.1 / loop.period))
    start = wallclock.perf_counter()
    with loop:
        for k in range(loop.n_ticks):
            tape.frame(k)
            tape.write(k, *loop.tick(k))
            if progress and k % report_every == 0:
                progress(k / loop.n_ticks)
    wall = wallclock.perf_counter() - start
    if progress:
        progress(1.0)
    log.info("%s: %.2f s simulated in %.2f s wall", scenario["name"], loop.n_ticks * loop.period, wall)
    return tape.result(wall)


class Tape:
    """A run's recording as it is made: channel table and arm frames, preallocated (shared by
    `simulate` and lockstep.simulate_batch)."""

    def __init__(self, loop: ControlLoop):
        self.loop, rig = loop, loop.rig
        self.names = tuple(rig.channels)
        self.rows: list[list[float] | None] = [None] * loop.n_ticks  # per tick, a value per channel (NaN: none)
        self.table: np.ndarray | None = None  # (ticks, channels), where columns.py wrote it instead of rows
        self.frame_every = max(1, int(round(1.0 / (loop.scenario["frame_rate_hz"] * loop.period))))
        self.frame_ticks = range(0, loop.n_ticks, self.frame_every)
        self.frames = np.empty((len(self.frame_ticks), *np.shape(rig.arm_points())))

    def frame(self, k: int) -> None:
        """Draw the arm if tick k is a frame tick (before the tick runs)."""
        if k % self.frame_every == 0:
            self.frames[k // self.frame_every] = self.loop.rig.arm_points()

    def write(self, k: int, obs: dict[str, float], recorded: dict[str, float]) -> None:
        """Record tick k's measured and recorded channels."""
        values = obs | recorded
        self.rows[k] = [values.get(c, math.nan) for c in self.names]

    def result(self, wall: float) -> "SimResult":
        """The finished run (wall: s it took)."""
        loop, scenario, period = self.loop, self.loop.scenario, self.loop.period
        n_ticks = loop.n_ticks
        empty = [math.nan] * len(self.names)
        table = (self.table if self.table is not None else
                 np.array([row or empty for row in self.rows], dtype=float).reshape(n_ticks, len(self.names)))
        channels = {c: np.ascontiguousarray(table[:, j]) for j, c in enumerate(self.names) if not np.isnan(table[:, j]).all()}
        controller_meta = dict(scenario["controller"])
        meta = {
            "format": FORMAT,
            "rig": scenario["rig"],
            "experiment": scenario["experiment"],
            "payload_kg": scenario["payload_kg"],
            "controller": controller_meta,
            "mode": "open_loop" if controller_meta["type"] in ("none", "open_loop") else "closed_loop",
            "control_period_s": period,
            **({"control_jitter_s": loop.jitter} if loop.jitter else {}),
            "locked_joints": scenario["locked_joints"],
            "notes": scenario["notes"] or f"simulated by watflex-sim {__version__}",
            "seed": scenario["seed"],
            # the values used: timestep and n_segments 0 stand for the model's own
            "scenario": {k: v for k, v in scenario.items() if k != "name"}
            | {"timestep": float(loop.model.opt.timestep), "n_segments": loop.n_segments},
        }
        time = np.arange(n_ticks) * period
        frame_time = np.array(self.frame_ticks, dtype=float) * period
        return SimResult(Recording(time, channels, meta), self.frames, frame_time, wall)


def energy(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """Kinetic + potential (gravity and joint springs) energy (J); needs mjENBL_ENERGY."""
    mujoco.mj_energyPos(model, data)
    mujoco.mj_energyVel(model, data)
    return float(data.energy[0] + data.energy[1])


