"""The control half of a lockstep batch on arrays: B simulations' sensors, controller and converters at once.

Each simulation's own control half (engine.ControlLoop.control) costs 10-14 us of Python per tick;
here the same arithmetic runs once per tick on arrays of shape (B,) and gives, member by member, the
same numbers (tests/test_lockstep.py compares every channel with tolerance 0): the rig's sensors and
converters (LaserColumns, WatflexColumns: encoders, strain bridges, camera, tip sensor, current
monitor, converters and saturation; GenericColumns: a rig described as data), the controller's column
form (`columns` of PID, StateFeedback, OpenLoop, Observer and FrictionCompensation, in controllers/), the
references and the noise tabulated at set-up (rigs.NoiseStream.take: the draws the single run makes, in its
order), the recording written as columns. Where the single run calls math.atan2 it is called here too
(numpy's arctan2 differs in the last bit for ~0.6 % of arguments).

Effects on the control half that act sample by sample - a sensor's gain and offset, an actuator's gain, offset
and limit (engine.ControlLoop.control; a refit rig's `sensor_gain` / `actuator_gain` knobs, the diagnosis' effects)
- are applied here too, on the members that have them (`Patches`). `ColumnControl.of` gives None where a member
needs what has no column form - another controller (passivity, fuzzy PD, PI velocity; a friction compensation has
one around a controller that has one: the observer's), a delay (sensor or command), control jitter - and lockstep
then runs each member's own control half.
"""
from __future__ import annotations

import math

import numpy as np

from .engine import GrowthMonitor, SimulationError
from .rigs import GenericRig, LaserArmRig, WatflexRig


def _per_member(rigs: list, value) -> np.ndarray:
    """value(rig) of each member, as an array (B,)."""
    return np.array([value(r) for r in rigs], dtype=float)


def _quantise(value: np.ndarray, step: np.ndarray) -> np.ndarray:
    """rigs.quantise on arrays (numpy's round, like Python's, rounds half to even)."""
    return step * np.round(value / step)


class LaserColumns:
    """LaserArmRig's observe / actuate / monitor for B members (rigs.md section 1)."""

    def __init__(self, rigs: list[LaserArmRig], arrays: dict[str, np.ndarray], tip: int, n: int):
        first = rigs[0]
        self.hub_q, self.hub_v, self.motor = first._hub_q, first._hub_v, first._motor
        self.qpos, self.qvel, self.ctrl, self.tip = arrays["qpos"], arrays["qvel"], arrays["ctrl"], arrays["site_xpos"][:, tip]
        self.length = _per_member(rigs, lambda r: r._length)  # m
        for name in ("sensor_gain", "encoder_step", "sensor_limit", "voltage_limit", "back_emf", "resistance",
                     "current_limit"):
            setattr(self, name, _per_member(rigs, lambda r, name=name: getattr(r.p, name)))
        self.tip_noise = _per_member(rigs, lambda r: r._tip_noise)  # V
        self.current_noise = _per_member(rigs, lambda r: r._current_noise)  # A
        self.gauss = np.stack([r.gauss.take(2 * n).reshape(n, 2) for r in rigs], axis=1)  # (tick, member, tip/current)
        self.applied = np.zeros(len(rigs))  # V, the last saturated command (a locked hub has no motor)

    def observe(self, k: int, refs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        theta = self.qpos[:, self.hub_q] if self.hub_q is not None else np.zeros(len(self.length))
        ys, xs = self.tip[:, 1].tolist(), self.tip[:, 0].tolist()
        arc = self.length * np.array([math.atan2(y, x) for y, x in zip(ys, xs)])
        error = self.length * refs["reference"] - arc  # m
        tip = self.sensor_gain * error + self.tip_noise * self.gauss[k, :, 0]
        return {"reference": refs["reference"], "hub_angle": _quantise(theta, self.encoder_step),
                "tip_sensor": np.clip(tip, -self.sensor_limit, self.sensor_limit)}

    def actuate(self, command: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        u = np.clip(command.get("voltage_cmd", 0.0), -self.voltage_limit, self.voltage_limit)
        if self.motor is not None:
            self.ctrl[:, self.motor] = u
        self.applied = u
        return {"voltage_cmd": u}

    def monitor(self, k: int) -> dict[str, np.ndarray]:
        u = self.applied if self.motor is None else self.ctrl[:, self.motor]
        speed = self.qvel[:, self.hub_v] if self.hub_v is not None else 0.0
        current = np.clip((u - self.back_emf * speed) / self.resistance, -self.current_limit, self.current_limit)
        return {"motor_current": current + self.current_noise * self.gauss[k, :, 1]}


class WatflexColumns:
    """WatflexRig's observe / actuate for B members (rigs.md sections 2-3)."""

    def __init__(self, rigs: list[WatflexRig], arrays: dict[str, np.ndarray], tip: int, n: int):
        first = rigs[0]
        self.qpos, self.ctrl = arrays["qpos"], arrays["ctrl"]
        self.tip = arrays["site_xpos"][:, tip] if tip >= 0 else None
        self.joint_q, self.motor, self.dac = first._joint_q, first._motor, first._dac
        self.locked = {j: _per_member(rigs, lambda r, j=j: r._locked[j]) for j in first.joints}  # rad
        self.encoder_step = _per_member(rigs, lambda r: r.p.encoder_step)  # rad
        self.converters = {j: tuple(_per_member(rigs, lambda r, j=j, i=i: r._dac[j][i]) for i in (1, 2, 3, 4))
                           for j in first._dac}  # V per N m, V per code, lowest and highest code
        self.gauges = [(channel, qa, qb) for channel, qa, qb, _va, _vb in first._gauges]
        self.weights = [(_per_member(rigs, lambda r, g=g: r._gauges[g][3]), _per_member(rigs, lambda r, g=g: r._gauges[g][4]))
                        for g in range(len(self.gauges))]  # V per hinge radian at a, b
        self.adc_limit = _per_member(rigs, lambda r: r.p.strain_adc_range)  # V
        self.adc_step = _per_member(rigs, lambda r: r._adc_step)  # V
        self.strain_noise = _per_member(rigs, lambda r: r._strain_noise)  # V
        size = n * len(self.gauges)
        self.gauss = np.stack([r.gauss.take(size).reshape(n, -1) if r._strain_noise else np.zeros((n, len(self.gauges)))
                               for r in rigs], axis=1)  # (tick, member, gauge); no draws where the noise is off
        self.camera_every = first._camera_every
        frames = -(-n // self.camera_every)
        self.uniform = np.stack([r.uniform.take(2 * frames).reshape(frames, 2) for r in rigs], axis=1)
        self.camera_noise = _per_member(rigs, lambda r: r._camera_noise)  # m
        self.nan = np.full(len(rigs), math.nan)

    @staticmethod
    def fits(rigs: list[WatflexRig]) -> bool:
        """Whether the members share what the columns take from the first: joints, gauges, camera rate, a fresh tick."""
        first = rigs[0]
        return all(r._joint_q == first._joint_q and r._motor == first._motor and r._tick == 0
                   and [g[:3] for g in r._gauges] == [g[:3] for g in first._gauges]
                   and r._camera_every == first._camera_every for r in rigs)

    def observe(self, k: int, refs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        qpos = self.qpos
        obs = {}
        for j, q in self.joint_q.items():
            obs[f"{j}_reference"] = refs.get(f"{j}_reference", self.locked[j])
            obs[f"{j}_angle"] = _quantise(self.locked[j] if q is None else qpos[:, q], self.encoder_step)
        for g, (channel, qa, qb) in enumerate(self.gauges):
            va, vb = self.weights[g]
            volts = va * qpos[:, qa] + vb * qpos[:, qb] + self.strain_noise * self.gauss[k, :, g]
            obs[channel] = _quantise(np.clip(volts, -self.adc_limit, self.adc_limit), self.adc_step)
        if k % self.camera_every == 0 and self.tip is not None:
            draw = self.uniform[k // self.camera_every]
            obs["tip_x"] = self.tip[:, 0] + self.camera_noise * (2 * draw[:, 0] - 1)
            obs["tip_y"] = self.tip[:, 1] + self.camera_noise * (2 * draw[:, 1] - 1)
        else:
            obs["tip_x"] = obs["tip_y"] = self.nan
        return obs

    def actuate(self, command: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for j, (channel, *_rest) in self.dac.items():
            volts_per_nm, step, lowest, highest = self.converters[j]
            code = np.round(command.get(channel, 0.0) * volts_per_nm / step)
            torque = np.minimum(np.maximum(code, lowest), highest) * step / volts_per_nm
            if j in self.motor:
                self.ctrl[:, self.motor[j]] = torque
            else:
                torque = np.zeros_like(torque)
            out[channel] = torque
        return out

    def monitor(self, k: int) -> dict[str, np.ndarray]:
        return {}


class GenericColumns:
    """GenericRig's observe / actuate for B members: a rig described as data (rigdesc; docs/rigs.md)."""

    def __init__(self, rigs: list[GenericRig], arrays: dict[str, np.ndarray], tip: int, n: int):
        first = rigs[0]
        self.qpos, self.qvel, self.ctrl, self.applied = arrays["qpos"], arrays["qvel"], arrays["ctrl"], arrays["qfrc_applied"]
        self.sensordata = arrays["sensordata"]
        self.inputs, self.disturbances = first._inputs, first._disturbances
        self.measured = []  # (channel, kind, index, per-member numbers, filter), in the rig's order
        noisy = [[m[6] != 0 for m in r._measured] for r in rigs]
        draws = [r.gauss.take(n * sum(flags)).reshape(n, -1) for r, flags in zip(rigs, noisy)]
        self.gauss = np.zeros((n, len(first._measured), len(rigs)))  # (tick, channel, member); 0 where no noise
        for i, flags in enumerate(noisy):
            self.gauss[:, np.flatnonzero(flags), i] = draws[i]
        for m, (channel, kind, index, *_rest) in enumerate(first._measured):
            numbers = {name: _per_member(rigs, lambda r, k=k: r._measured[m][k])
                       for k, name in ((3, "scale"), (4, "offset"), (5, "step"), (6, "noise"))}
            if kind == "current":
                numbers |= {name: _per_member(rigs, lambda r, k=k: r._measured[m][2][k])
                            for k, name in ((2, "low"), (3, "high"), (4, "emf"), (5, "per_input"), (6, "most"))}
                index = index[:2]  # actuator, dof
            elif kind == "link":
                numbers["weights"] = [_per_member(rigs, lambda r, k=k: r._measured[m][2][k][1]) for k in range(len(index))]
                index = [q for q, _w in index]
            alpha = first._measured[m][7]
            coefficients = None if alpha is None else tuple([_per_member(rigs, lambda r, a=a, k=k: r._measured[m][7][a][k])
                                                             for k in range(len(alpha[a]))] for a in (0, 1))
            self.measured.append((channel, kind, index, numbers, coefficients))
        self._filtered: dict[str, tuple[list, list]] = {}  # channel -> (inputs, outputs) of its filter
        self.commands = [(channel, actuator, *(_per_member(rigs, lambda r, c=channel, k=k: r._commands[c][k]) for k in (1, 2, 3)))
                         for channel, (actuator, *_rest) in first._commands.items()]  # gain, limit, step

    @staticmethod
    def fits(rigs: list[GenericRig]) -> bool:
        """Whether the members share channels, kinds, places, filter orders and converters, and have not run yet."""
        def form(r):
            return ([(c, k, i[:2] if k == "current" else [q for q, _w in i] if k == "link" else i,
                      None if a is None else (len(a[0]), len(a[1])), bool(st)) for c, k, i, _s, _o, st, _n, a in r._measured],
                    [(c, a, bool(st)) for c, (a, _g, _l, st) in r._commands.items()], r._inputs, r._disturbances)
        return all(form(r) == form(rigs[0]) and not r._filtered for r in rigs)

    def observe(self, k: int, refs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        obs = {c: refs.get(c, 0.0) for c in self.inputs}
        for channel, dof in self.disturbances.items():
            self.applied[:, dof] = obs[channel]
        qpos, qvel = self.qpos, self.qvel
        for m, (channel, kind, index, numbers, coefficients) in enumerate(self.measured):
            if kind == "position":
                x = qpos[:, index]
            elif kind == "velocity":
                x = qvel[:, index]
            elif kind == "current":
                actuator, dof = index
                u = np.minimum(numbers["high"], np.maximum(numbers["low"], self.ctrl[:, actuator]))
                x = np.clip((u - numbers["emf"] * qvel[:, dof]) * numbers["per_input"], -numbers["most"], numbers["most"])
            elif kind == "sensor":
                x = self.sensordata[:, index]
            else:
                x = sum(w * qpos[:, q] for q, w in zip(index, numbers["weights"]))
            value = numbers["scale"] * x + numbers["offset"] + numbers["noise"] * self.gauss[k, m]
            if coefficients is not None:
                value = self._filter(channel, coefficients, value)
            obs[channel] = _quantise(value, numbers["step"]) if numbers["step"][0] else value  # fits: all or none
        return obs

    _filter = GenericRig._filter  # the same arithmetic on arrays

    def actuate(self, command: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for channel, actuator, gain, limit, step in self.commands:
            u = np.clip(command.get(channel, 0.0), -limit, limit)
            if step[0]:  # a converter on every member or none (fits)
                u = _quantise(u, step)
            self.ctrl[:, actuator] = gain * u
            out[channel] = u
        return out

    def monitor(self, k: int) -> dict[str, np.ndarray]:
        return {}


class GrowthColumns:
    """engine.GrowthMonitor for B members: the energy sampled on arrays, each member's window logic its own
    (the energy summed by numpy, not BLAS: an ulp apart at most, which moves no window's verdict)."""

    def __init__(self, monitors: list[GrowthMonitor], qvel: np.ndarray):
        self.monitors, self.qvel, self.dofs = monitors, qvel, monitors[0].dofs
        self.current = np.zeros(len(monitors))

    def update(self, k: int, live: list[int], failed: dict) -> None:
        if k % 2:
            v = self.qvel[:, self.dofs]
            np.maximum(self.current, np.einsum("ij,ij->i", v, v), out=self.current)
        if (k + 1) % GrowthMonitor.WINDOW:
            return
        for i in live:
            monitor = self.monitors[i]
            monitor.current = max(monitor.current, float(self.current[i]))
            try:
                monitor.close_window(k)
            except SimulationError as exc:
                failed[i] = exc
        self.current[:] = 0.0


FORMS = {LaserArmRig: LaserColumns, WatflexRig: WatflexColumns, GenericRig: GenericColumns}


class Patches:
    """The members' sensor gains and offsets and actuator gains, offsets and limits (effects.Patch) on arrays, where
    any member has one: engine.ControlLoop's `_sense` and `_actuators` arithmetic, applied only to the members that
    carry the effect (np.where: the others' values untouched, bit for bit). Until 2026-12-03 a patch sent its whole
    batch to per-member control, and the laser arm's refit `tip_sensor_gain` (a sensor gain on every model a
    diagnosis simulates) sent every laser diagnosis batch there (seed 79's laser_arm-3ae9b37c: 561 of 720
    simulations; 30 re-simulations of 6 s on one thread: 7.96 s with the gain, 6.60 s without, now 6.80 s)."""

    def __init__(self, loops: list, ctrl: np.ndarray):
        self.ctrl = ctrl
        self.sensor = {c: self._columns(loops, lambda loop, c=c: loop.patch.sensor.get(c), (1.0, 0.0))
                       for c in sorted({c for loop in loops for c in loop.patch.sensor})}
        first = loops[0].rig
        self.actuator = {c: (first.command_actuators[c], first.command_scale.get(c, 1.0),
                             self._columns(loops, lambda loop, c=c: loop.patch.actuator.get(c), (1.0, 0.0, math.inf)))
                         for c in sorted({c for loop in loops for c in loop._actuators})}

    @staticmethod
    def _columns(loops: list, value, neutral: tuple) -> tuple[np.ndarray, ...]:
        """(mask of the members that have it, then each of its numbers per member, `neutral` where absent)."""
        rows = [value(loop) for loop in loops]
        numbers = [np.array([neutral[j] if r is None else r[j] for r in rows], dtype=float) for j in range(len(neutral))]
        return (np.array([r is not None for r in rows]), *numbers)

    def sense(self, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Sensor gain and offset on the measured channels in `values`."""
        for channel, (mask, gain, offset) in self.sensor.items():
            if channel in values:
                values[channel] = np.where(mask, values[channel] * gain + offset, values[channel])
        return values

    def act(self) -> None:
        """Actuator gain, offset and limit on the plant inputs, in the command's unit."""
        for actuator, scale, (mask, gain, offset, limit) in self.actuator.values():
            u = self.ctrl[:, actuator] / scale * gain + offset
            self.ctrl[:, actuator] = np.where(mask, scale * np.maximum(-limit, np.minimum(limit, u)), self.ctrl[:, actuator])


class ColumnControl:
    """The control half of a batch's loops (lockstep._Lockstep) on arrays; `tick(k)` does what each loop's
    `control(k)` and its Tape's `write` would, and leaves the plant inputs in the batch's `ctrl`."""

    @staticmethod
    def fits(loops: list) -> bool:
        """Whether these loops (one structure) may have a column form: a rig with one, no delay on the control
        half, no jitter, no moving start or controller state (engine.warm_up), a controller type with a `columns`
        form (which may still find its members unlike)."""
        first = loops[0]
        form = FORMS.get(type(first.rig))
        if form is None or any(type(loop.rig) is not type(first.rig) for loop in loops):
            return False
        if any(loop._sensor_fifo or loop._commands or loop.delays is not None or loop._warm or loop._controller_state
               or loop.period != first.period or loop.rig.channels != first.rig.channels
               or set(loop.references.columns) != set(first.references.columns)
               or not np.array_equal(loop.monitor.dofs, first.monitor.dofs) for loop in loops):
            return False
        if hasattr(form, "fits") and not form.fits([loop.rig for loop in loops]):
            return False
        return _has_form(first.controller)

    @staticmethod
    def of(loops: list, arrays: dict[str, np.ndarray], tip: int) -> "ColumnControl | None":
        """The column form of these loops (one structure), or None where one has none (module docstring)."""
        first = loops[0]
        if not ColumnControl.fits(loops) or (tip < 0 and type(first.rig) is LaserArmRig):
            return None
        n = max(loop.n_ticks for loop in loops)
        law = type(first.controller).columns([loop.controller for loop in loops], np.arange(n) * first.period)
        if law is None:
            return None
        return ColumnControl(loops, arrays, FORMS[type(first.rig)]([loop.rig for loop in loops], arrays, tip, n), law, n)

    def __init__(self, loops: list, arrays: dict[str, np.ndarray], rig, law, n: int):
        self.rig, self.law, self.period = rig, law, loops[0].period
        self.refs = {c: np.array([_padded(loop.references.columns[c], n) for loop in loops]).T
                     for c in loops[0].references.columns}  # (tick, member)
        self.names = loops[0].rig.channels
        self.table = np.full((n, len(self.names), len(loops)), math.nan)  # (tick, channel, member)
        self.growth = GrowthColumns([loop.monitor for loop in loops], arrays["qvel"])
        self.patches = Patches(loops, arrays["ctrl"])
        self.settling = np.array([loop._settle for loop in loops])  # members started at rest away from nominal

    def tick(self, k: int) -> None:
        """Sensors, controller, converters of control period k for every member; the recording's row k."""
        obs = self.patches.sense(self.rig.observe(k, {c: table[k] for c, table in self.refs.items()}))
        if k == 0 and self.settling.any():
            self.law.settle(obs, self.settling)  # as ControlLoop.control does: the law as it holds at rest there
        command = self.law(k * self.period, obs)
        recorded = self.rig.actuate(command)
        self.patches.act()
        values = obs | recorded | self.patches.sense(self.rig.monitor(k))
        row = self.table[k]
        for j, name in enumerate(self.names):
            if name in values:
                row[j] = values[name]

    def member_table(self, i: int, n_ticks: int) -> np.ndarray:
        """Member i's recording table (ticks, channels)."""
        return self.table[:n_ticks, :, i]


def _has_form(controller) -> bool:
    """Whether a controller, and the one it wraps (`inner`: a friction compensation's), have a column form."""
    inner = getattr(controller, "inner", None)
    return getattr(type(controller), "columns", None) is not None and (inner is None or _has_form(inner))


def _padded(values: list[float], n: int) -> list[float]:
    """A reference table of a shorter run held at its last value up to n ticks (never read after its end)."""
    return values + [values[-1] if values else 0.0] * (n - len(values))
