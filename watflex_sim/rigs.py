"""The rigs' sensors and actuators as the real rigs have them (rigs.md §1-3).

A `Rig` turns MuJoCo state into the measured channels of recordings.md (with quantisation
and seeded noise) and a controller's commands into actuator inputs (with saturation and
converters). Everything is looked up by name once, at construction; the per-tick methods
work on Python floats (they run every 1 ms).
"""
from __future__ import annotations

import math

import mujoco
import numpy as np

from .params import CONTROL_PERIOD, LaserArm, Watflex


def quantise(value: float, step: float) -> float:
    """Round to the nearest multiple of `step` (an encoder count or a converter code)."""
    return step * round(value / step)


def clip(value: float, limit: float) -> float:
    """`value` limited to [-limit, limit]."""
    return -limit if value < -limit else limit if value > limit else value


class NoiseStream:
    """Seeded draws handed out one at a time from blocks (cheaper than one numpy call each)."""

    BLOCK = 4096

    def __init__(self, rng: np.random.Generator, draw: str = "standard_normal"):
        self._draw = getattr(rng, draw)
        self._block: list[float] = []

    def __call__(self) -> float:
        if not self._block:
            self._block = self._draw(self.BLOCK).tolist()[::-1]
        return self._block.pop()

    def take(self, n: int) -> np.ndarray:
        """The next n draws at once: the numbers n calls would give, in order (columns.py)."""
        out = self._block[::-1]  # the pending draws, next first
        while len(out) < n:
            out += self._draw(self.BLOCK).tolist()
        self._block = out[n:][::-1]
        return np.array(out[:n], dtype=float)


class Rig:
    """Common part: model, data, seeded noise streams, the arm's drawing points."""

    name: str
    channels: tuple[str, ...]
    command_channels: tuple[str, ...]
    command_actuators: dict[str, int]  # command channel -> actuator id
    command_scale: dict[str, float] = {}  # command channel -> actuator input per command unit (1 if absent)
    positions_every = 1  # observe() reads body/site positions (not just qpos) on ticks that are multiples of this; 0: never
    encoders: dict[str, str] = {}  # encoder channel -> the joint it reads: where start_at can start a run

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, params, noise: bool, seed: int):
        self.model, self.data, self.p = model, data, params
        self.noise = 1.0 if noise else 0.0
        normal_seed, uniform_seed = np.random.SeedSequence(seed).spawn(2)
        self.gauss = NoiseStream(np.random.default_rng(normal_seed))
        self.uniform = NoiseStream(np.random.default_rng(uniform_seed), "random")  # [0, 1)
        # bodies in tree order: the rigid segments' origins, root to tip, then the tip site
        self._draw_bodies = np.arange(1, model.nbody)
        tip = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tip")  # none on an actuator bench
        self._tip_xpos = data.site_xpos[tip] if tip >= 0 else None  # a view: current after each kinematics pass

    def arm_points(self) -> np.ndarray:
        """(n, 3) positions (m) of the chain of rigid bodies and the tip, root to tip, for drawing."""
        points = self.data.xpos[self._draw_bodies]
        return points.copy() if self._tip_xpos is None else np.vstack([points, self._tip_xpos])

    @property
    def input_channels(self) -> tuple[str, ...]:
        """Channels given from outside the loop (references, disturbances), not measured."""
        return tuple(c for c in self.channels if c.endswith("reference"))

    def monitor(self) -> dict[str, float]:
        """Channels measured on the actuators once the commands are applied (none by default)."""
        return {}

    def start_at(self, first: dict[str, float], rates: dict[str, float] | None = None) -> None:
        """Start each encoder's joint at its value in `first` (channel -> rad) and at its rate in `rates` (rad/s; at
        rest without one), the links straight: a recording that starts away from the nominal pose, or moving. A joint
        within half an encoder count of it stays as it is (bit for bit); a locked joint, a missing or non-finite
        value are left alone."""
        moved, rates = False, rates or {}
        for channel, joint in self.encoders.items():
            q, value = self._qpos(joint), first.get(channel, math.nan)
            if q is not None and math.isfinite(value) and abs(self.data.qpos[q] - value) > 0.5 * self.p.encoder_step:
                self.data.qpos[q] = value
                moved = True
            if q is not None and math.isfinite(rates.get(channel, math.nan)) and rates[channel] != 0.0:
                self.data.qvel[self._dof(joint)] = rates[channel]
                moved = True
        if moved:
            mujoco.mj_forward(self.model, self.data)

    def _qpos(self, joint: str) -> int | None:
        jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        return None if jid < 0 else int(self.model.jnt_qposadr[jid])

    def _dof(self, joint: str) -> int | None:
        jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        return None if jid < 0 else int(self.model.jnt_dofadr[jid])

    def _dof_of_qpos(self, q: int) -> int:
        """The dof address of the joint at qpos address q (a hinge or slide)."""
        return int(self.model.jnt_dofadr[list(self.model.jnt_qposadr).index(q)])

    def _chain(self, ids: list[int], length: float, origin: int) -> list[tuple[int, int, float]]:
        """(qpos address, dof address, lever arm m) of each joint in `ids`, the arm `length` less the joint's distance
        from joint `origin`'s anchor with the model in its reference pose (the links straight): where a tip load's
        moment bends the chain."""
        straight = mujoco.MjData(self.model)
        mujoco.mj_kinematics(self.model, straight)
        root = straight.xanchor[origin]
        return [(int(self.model.jnt_qposadr[j]), int(self.model.jnt_dofadr[j]),
                 length - float(np.linalg.norm(straight.xanchor[j] - root))) for j in ids]


class LaserArmRig(Rig):
    """rigs.md §1: hub encoder, tip (laser spot) sensor, voltage drive with current monitor."""

    name = "laser_arm"
    channels = ("reference", "hub_angle", "tip_sensor", "voltage_cmd", "motor_current")
    command_channels = ("voltage_cmd",)
    encoders = {"hub_angle": "hub"}

    def __init__(self, model, data, params: LaserArm, noise: bool, seed: int):
        super().__init__(model, data, params, noise, seed)
        self._hub_q, self._hub_v = self._qpos("hub"), self._dof("hub")
        self._motor = model.actuator("motor").id if self._hub_q is not None else None
        self.command_actuators = {} if self._motor is None else {"voltage_cmd": self._motor}
        self._length = params.beam.length
        self._tip_noise = self.noise * params.noise_tip_sensor
        self._current_noise = self.noise * params.noise_current
        self._applied = 0.0

    def start_at(self, first: dict[str, float], rates: dict[str, float] | None = None) -> None:
        """As Rig.start_at, and where `first` has the tip sensor (V) (a run that starts moving), the beam in its
        static tip-load shape with the tip deflection, and its rate, that make the sensor read it and its rate
        (`rates`, V/s) against the reference then (`first`/`rates` of `reference`, rad and rad/s)."""
        super().start_at(first, rates)
        rates, tip = rates or {}, first.get("tip_sensor", math.nan)
        if self._hub_q is None or not math.isfinite(tip) or abs(tip) >= self.p.sensor_limit:
            return
        gain, length = self.p.sensor_gain, self._length
        deflection = length * first.get("reference", 0.0) - tip / gain - length * self.data.qpos[self._hub_q]  # m
        speed = (length * rates.get("reference", 0.0) - rates.get("tip_sensor", 0.0) / gain
                 - length * self.data.qvel[self._hub_v])  # m/s
        hinges = self._chain([j for j in range(self.model.njnt) if self.model.joint(j).name.startswith("beam_j")],
                             length, self.model.joint("hub").id)
        norm = sum(arm * arm for _q, _v, arm in hinges)
        for q, v, arm in hinges:  # w(L) = sum q_i (L - x_i), q_i proportional to the tip load's moment (L - x_i)
            self.data.qpos[q], self.data.qvel[v] = deflection * arm / norm, speed * arm / norm
        mujoco.mj_forward(self.model, self.data)

    def hub_velocity(self) -> float:
        """Hub speed (rad/s); 0 when the hub is locked."""
        return 0.0 if self._hub_v is None else self.data.qvel[self._hub_v].item()

    def tip_arc(self) -> float:
        """Tip position along the laser arc, L * atan2(y, x) (m): L theta + w(L) for small w."""
        return self._length * math.atan2(self._tip_xpos[1].item(), self._tip_xpos[0].item())

    def observe(self, reference: dict[str, float]) -> dict[str, float]:
        """Measured channels at the current state (V, rad), before the command is computed."""
        p = self.p
        theta = 0.0 if self._hub_q is None else self.data.qpos[self._hub_q].item()
        error = self._length * reference["reference"] - self.tip_arc()  # m
        tip = p.sensor_gain * error + self._tip_noise * self.gauss()
        return {
            "reference": reference["reference"],
            "hub_angle": quantise(theta, p.encoder_step),
            "tip_sensor": clip(tip, p.sensor_limit),
        }

    def current(self, voltage: float) -> float:
        """Armature current (A) = clip((u - K_E w) / R, +-i_max), rigs.md §1 'Drive'."""
        p = self.p
        return clip((voltage - p.back_emf * self.hub_velocity()) / p.resistance, p.current_limit)

    def actuate(self, command: dict[str, float]) -> dict[str, float]:
        """Saturate the voltage (V), apply it, and return the recorded command."""
        u = clip(float(command.get("voltage_cmd", 0.0)), self.p.voltage_limit)
        if self._motor is not None:
            self.data.ctrl[self._motor] = u
        self._applied = u
        return {"voltage_cmd": u}

    def monitor(self) -> dict[str, float]:
        """The amplifier's current monitor (A) for the voltage the motor really gets (after effects)."""
        u = self._applied if self._motor is None else self.data.ctrl[self._motor].item()
        return {"motor_current": self.current(u) + self._current_noise * self.gauss()}


class WatflexRig(Rig):
    """rigs.md §2-3: encoders, strain bridges, overhead camera, torque via 12-bit converter."""

    name = "watflex"
    channels = (
        "shoulder_reference", "elbow_reference", "shoulder_angle", "elbow_angle",
        "shoulder_torque_cmd", "elbow_torque_cmd",
        "strain_1A", "strain_1B", "strain_1C", "strain_2A", "strain_2B", "tip_x", "tip_y",
    )
    command_channels = ("shoulder_torque_cmd", "elbow_torque_cmd")
    joints = ("shoulder", "elbow")
    encoders = {"shoulder_angle": "shoulder", "elbow_angle": "elbow"}

    def __init__(self, model, data, params: Watflex, noise: bool, seed: int, locked: dict[str, float] | None = None):
        super().__init__(model, data, params, noise, seed)
        locked = locked or {}
        unmounted = params.unmounted_channels(locked)  # link 1's bridges in the single-link set-up
        self.channels = tuple(c for c in WatflexRig.channels if c not in unmounted)
        self._joint_q = {j: self._qpos(j) for j in self.joints}
        self._locked = {j: float(locked.get(j, 0.0)) for j in self.joints}
        self._motor = {j: model.actuator(f"{j}_motor").id for j in self.joints if self._joint_q[j] is not None}
        self.command_actuators = {f"{j}_torque_cmd": a for j, a in self._motor.items()}
        # per joint: (command channel, volts per N m, converter step in V, lowest and highest code)
        self._dac = {}
        for j, act in (("shoulder", params.shoulder), ("elbow", params.elbow)):
            half = 2 ** (act.dac_bits - 1)
            self._dac[j] = (f"{j}_torque_cmd", 1.0 / (act.amplifier_gain * act.torque_constant),
                            2 * act.dac_range / 2**act.dac_bits, -half, half - 1)
        # per gauge: (channel, hinge qpos a, b, volts per hinge radian at a, b): V = -(t/2) w'' / K
        self._gauges = []
        for name, (link, x_gauge, k_bridge) in params.gauges.items():
            qa, qb, wa, wb, thickness = self._gauge_weights(link, x_gauge)
            if f"strain_{name}" in unmounted or qa is None or qb is None:  # not mounted, or the link
                continue  # is not in the model (actuator bench)
            volts = -0.5 * thickness / k_bridge
            self._gauges.append((f"strain_{name}", qa, qb, volts * wa, volts * wb))
        self._adc_step = 2 * params.strain_adc_range / 4096
        self._strain_noise = self.noise * params.noise_strain
        self._camera_noise = self.noise * params.camera_error
        self._camera_every = self.positions_every = int(round(1.0 / (params.camera_rate * CONTROL_PERIOD)))
        self._tick = 0
        self._draw_bodies = np.array(
            [b for b in range(1, model.nbody) if not model.body(b).name.startswith("link2_root")]
        )

    def start_at(self, first: dict[str, float], rates: dict[str, float] | None = None) -> None:
        """As Rig.start_at, and where `first` has strain bridges (V) (a run that starts moving), each link with them
        bent in the static shape of a load at its tip, a force and a moment (hinge i's angle a (L - x_i) + b: the
        curvature linear along the link), a and b and their rates the least-squares fit of its bridges' readings and
        rates (`rates`, V/s; the least-norm one where a link has one bridge)."""
        super().start_at(first, rates)
        rates, bent = rates or {}, False
        for link in (1, 2):
            beam, n = (self.p.link1 if link == 1 else self.p.link2), self.p.n_segments
            hinges = {self._qpos(f"link{link}_j{i:02d}"): beam.length * (1 - (i - 0.5) / n) for i in range(1, n + 1)}
            hinges.pop(None, None)  # a rigid link 1 (the single-link set-up) has none
            gauges = [(c, qa, qb, va, vb) for c, qa, qb, va, vb in self._gauges
                      if qa in hinges and qb in hinges and math.isfinite(first.get(c, math.nan))]
            if not gauges:
                continue
            # a bridge's reading per unit a (force) and per unit b (moment)
            per_unit = np.array([[va * hinges[qa] + vb * hinges[qb], va + vb] for _c, qa, qb, va, vb in gauges])
            readings = np.array([[first[c], rates.get(c, 0.0)] for c, *_ in gauges])
            (a, a_rate), (b, b_rate) = np.linalg.lstsq(per_unit, np.nan_to_num(readings), rcond=None)[0]
            for q, arm in hinges.items():
                self.data.qpos[q], self.data.qvel[self._dof_of_qpos(q)] = a * arm + b, a_rate * arm + b_rate
            bent = True
        if bent:
            mujoco.mj_forward(self.model, self.data)

    def _gauge_weights(self, link: int, x_gauge: float):
        """Curvature at x_gauge (1/m) = wa q_a + wb q_b over the two nearest hinges (linear inter/extrapolation).

        Hinge i of an N-segment chain sits at (i - 1/2) dx and carries M = k q = EI q / dx,
        so the curvature there is q / dx.
        """
        beam = self.p.link1 if link == 1 else self.p.link2
        n, dx = self.p.n_segments, beam.length / self.p.n_segments
        i = min(max(int(math.floor(x_gauge / dx + 0.5)), 1), n - 1)  # hinges i and i+1 bracket x
        wb = (x_gauge - (i - 0.5) * dx) / dx
        qa, qb = self._qpos(f"link{link}_j{i:02d}"), self._qpos(f"link{link}_j{i + 1:02d}")
        return qa, qb, (1 - wb) / dx, wb / dx, beam.thickness

    def strain(self, gauge: str) -> float:
        """Surface strain eps = -(t/2) w'' at a gauge (thesis eq. 5.4), w'' from the hinge angles."""
        link, x_gauge, _k = self.p.gauges[gauge]
        qa, qb, wa, wb, thickness = self._gauge_weights(link, x_gauge)
        return -0.5 * thickness * (wa * self.data.qpos[qa].item() + wb * self.data.qpos[qb].item())

    def joint_angle(self, joint: str) -> float:
        """Joint angle (rad); the lock angle for a locked joint."""
        q = self._joint_q[joint]
        return self._locked[joint] if q is None else self.data.qpos[q].item()

    def observe(self, reference: dict[str, float]) -> dict[str, float]:
        """Encoders (rad), bridge voltages (V), camera (m, 25 Hz, NaN between frames)."""
        p = self.p
        qpos = self.data.qpos.tolist()  # one conversion, then plain float indexing
        angle = {j: self._locked[j] if q is None else qpos[q] for j, q in self._joint_q.items()}
        obs = {
            "shoulder_reference": reference.get("shoulder_reference", self._locked["shoulder"]),
            "elbow_reference": reference.get("elbow_reference", self._locked["elbow"]),
            "shoulder_angle": quantise(angle["shoulder"], p.encoder_step),
            "elbow_angle": quantise(angle["elbow"], p.encoder_step),
        }
        limit, step, noise = p.strain_adc_range, self._adc_step, self._strain_noise
        for channel, qa, qb, va, vb in self._gauges:
            volts = va * qpos[qa] + vb * qpos[qb]
            if noise:  # noise off (re-simulations): no draws
                volts += noise * self.gauss()
            obs[channel] = quantise(clip(volts, limit), step)
        if self._tick % self._camera_every == 0 and self._tip_xpos is not None:
            e = self._camera_noise
            obs["tip_x"] = self._tip_xpos[0].item() + e * (2 * self.uniform() - 1)
            obs["tip_y"] = self._tip_xpos[1].item() + e * (2 * self.uniform() - 1)
        else:
            obs["tip_x"] = obs["tip_y"] = math.nan
        self._tick += 1
        return obs

    def actuate(self, command: dict[str, float]) -> dict[str, float]:
        """Torque (N m) -> amplifier volts, clipped to +-10 V and quantised to 12 bits -> torque applied."""
        out = {}
        for j, (channel, volts_per_nm, step, lowest, highest) in self._dac.items():
            code = round(float(command.get(channel, 0.0)) * volts_per_nm / step)
            torque = min(max(code, lowest), highest) * step / volts_per_nm
            if j in self._motor:
                self.data.ctrl[self._motor[j]] = torque
            else:
                torque = 0.0
            out[channel] = torque
        return out


def link_joints(model: mujoco.MjModel, link: str) -> list[int]:
    """The joint ids of a generic rig's `link`: the hinge named so, or the chain LINK_j01, LINK_j02, ... (empty if the
    model lacks it)."""
    return [j for j in range(model.njnt) if model.joint(j).name == link or model.joint(j).name.startswith(f"{link}_j")]


class GenericRig(Rig):
    """A rig from its description alone (rigdesc): sensors, commands, references and
    disturbances as the channel table says (rigs/emps.toml, rigs/quanser_2dsfl.toml).

    A measured channel reads `quantity` (rigdesc.QUANTITIES) of a joint or a link, then
    value = scale * quantity + offset + noise, low-passed at filter_hz (1st order, or 2nd with
    filter_zeta), quantised to step.
    A link is the hinge joint named `link` or the chain `link_j01, link_j02, ...`; its tip
    deflection (m) is sum q_i (length - x_i) with x_i the hinge's distance from the first one,
    its angle that over length, and the strain at x the static tip-load shape's,
    3 t w_tip (length - x) / (2 length^3) (a cantilever with a tip force).
    A `current` channel reads a datasheet drive's current (A) from the input held since the last
    tick: datasheet.current_law (current drive: the command after the amplifier limit; voltage
    drive: (V - Ke w) / R, w the joint speed). An `acceleration` channel reads the accelerometer
    model.mount_accelerometers put on its link, across the link (m/s^2), as the last physics step computed it.
    """

    def __init__(self, model, data, description, noise: bool, seed: int, period: float | None = None):
        super().__init__(model, data, description, noise, seed)
        self.name = description.name
        self.channels = tuple(description.channels)
        self.command_channels = tuple(description.of_kind("command"))
        self._inputs = tuple(description.of_kind("reference") + description.of_kind("disturbance"))
        self._period = period or description.control_period_s  # s, the sample period the filters run at
        self._datasheet = description.datasheet  # drives for current channels
        self._measured, self._commands, self._disturbances = [], {}, {}
        mujoco.mj_kinematics(model, data)
        for channel, spec in description.channels.items():
            if spec["kind"] == "measured":
                sensor = self._sensor(channel, spec)
                if sensor is not None:
                    self._measured.append((channel, *sensor))
            elif spec["kind"] == "command":
                self._commands[channel] = (model.actuator(spec["actuator"]).id, float(spec.get("gain", 1.0)),
                                           float(spec.get("limit", math.inf)), _converter_step(spec))
            elif spec["kind"] == "disturbance":
                self._disturbances[channel] = self._dof(spec["joint"])
        self.command_actuators = {c: a for c, (a, *_rest) in self._commands.items()}
        self.command_scale = {c: g for c, (_a, g, *_rest) in self._commands.items()}
        self.positions_every = 0  # its sensors read qpos and qvel only
        self._filtered: dict[str, tuple[list, list]] = {}  # channel -> (inputs, outputs) of its filter

    def _link(self, spec) -> list[tuple[int, int, float]]:
        """(qpos, dof, lever arm m) of each hinge of link spec['link'] (empty if not in the model)."""
        ids = link_joints(self.model, spec["link"])
        return self._chain(ids, float(spec.get("length", 1.0)), ids[0]) if ids else []

    def _sensor(self, channel: str, spec):
        """(kind, index/weights, scale, offset, step, noise, filter coefficient) or None if absent."""
        quantity = spec.get("quantity", "position")
        scale, offset = float(spec.get("scale", 1.0)), float(spec.get("offset", 0.0))
        step, noise = float(spec.get("step", 0.0)), self.noise * float(spec.get("noise", 0.0))
        alpha = _low_pass(float(spec.get("filter_hz", 0.0)), spec.get("filter_zeta"), self._period)
        if quantity == "acceleration":  # model.mount_accelerometers: its y axis, across the link
            sensor = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SENSOR, f"accelerometer_{channel}")
            if sensor < 0:
                return None
            return "sensor", int(self.model.sensor_adr[sensor]) + 1, scale, offset, step, noise, alpha
        if quantity in ("position", "velocity"):
            index = self._qpos(spec["joint"]) if quantity == "position" else self._dof(spec["joint"])
            if index is None:
                return None
            return quantity, index, scale, offset, step, noise, alpha
        if quantity == "current":
            return "current", self._drive(spec["actuator"]), scale, offset, step, noise, alpha
        hinges = self._link(spec)
        if not hinges:
            return None
        length = float(spec.get("length", 1.0))
        per_metre = {"deflection": 1.0, "deflection_angle": 1.0 / length,
                     "strain": 3 * float(spec.get("thickness", 0.0)) * (length - float(spec.get("x", 0.0))) / (2 * length**3)}
        if quantity == "deflection_angle" and len(hinges) == 1:  # a torsional-spring link: its angle
            weights = [(hinges[0][0], 1.0)]
        else:
            weights = [(q, arm * per_metre[quantity]) for q, _d, arm in hinges]
        return "link", weights, scale, offset, step, noise, alpha

    def _drive(self, actuator: str) -> tuple:
        """(actuator id, its joint's dof, input range low, high, Ke, per_input, current limit) of a datasheet drive."""
        from .datasheet import current_law

        stage = next(st for st in self._datasheet["stages"] if st["drive"]["actuator"] == actuator)
        a = self.model.actuator(actuator).id
        low, high = self.model.actuator_ctrlrange[a] if self.model.actuator_ctrllimited[a] else (-math.inf, math.inf)
        dof = int(self.model.jnt_dofadr[self.model.actuator_trnid[a, 0]])
        return (a, dof, float(low), float(high), *current_law(stage))

    @property
    def input_channels(self) -> tuple[str, ...]:
        return self._inputs

    def observe(self, reference: dict[str, float]) -> dict[str, float]:
        """References and disturbances as given (disturbances also applied as force), then the sensors."""
        obs = {c: reference.get(c, 0.0) for c in self._inputs}
        for channel, dof in self._disturbances.items():
            self.data.qfrc_applied[dof] = obs[channel]
        qpos, qvel = self.data.qpos.tolist(), self.data.qvel.tolist()
        for channel, kind, index, scale, offset, step, noise, alpha in self._measured:
            if kind == "position":
                x = qpos[index]
            elif kind == "velocity":
                x = qvel[index]
            elif kind == "current":
                actuator, dof, low, high, emf, per_input, most = index
                u = min(high, max(low, float(self.data.ctrl[actuator])))  # the input held since the last tick
                x = clip((u - emf * qvel[dof]) * per_input, most)
            elif kind == "sensor":  # MuJoCo's, computed at the last physics step
                x = float(self.data.sensordata[index])
            else:
                x = sum(w * qpos[q] for q, w in index)
            value = scale * x + offset + (noise * self.gauss() if noise else 0.0)
            if alpha is not None:
                value = self._filter(channel, alpha, value)
            obs[channel] = quantise(value, step) if step else value
        return obs

    def _filter(self, channel: str, coefficients, value: float) -> float:
        """One sample of a channel's low-pass (b, a: direct form, at rest at its first input)."""
        b, a = coefficients
        x, y = self._filtered.setdefault(channel, ([value] * len(b), [value] * (len(a) - 1)))
        x.insert(0, value)
        x.pop()
        out = sum(bi * xi for bi, xi in zip(b, x)) - sum(ai * yi for ai, yi in zip(a[1:], y))
        if y:
            y.insert(0, out)
            y.pop()
        return out

    def start_at(self, first: dict[str, float], rates: dict[str, float] | None = None) -> None:
        """Set the state so the sensors read `first` (channel -> value; noise, filter and steps aside) and change
        at `rates` (channel -> unit/s; at rest without one): joint positions and velocities, and each link bent
        in its static tip-load shape."""
        rates = rates or {}
        for channel, kind, index, scale, offset, _step, _noise, _alpha in self._measured:
            if channel not in first or not math.isfinite(first[channel]) or kind in ("current", "sensor"):
                continue
            x = (first[channel] - offset) / scale
            rate = rates.get(channel, 0.0) / scale if math.isfinite(rates.get(channel, 0.0)) else 0.0
            if kind == "position":
                self.data.qpos[index] = x
                if rate:
                    self.data.qvel[self._dof_of_qpos(index)] = rate
            elif kind == "velocity":
                self.data.qvel[index] = x
            else:  # q_i = c w_i with sum w_i q_i = x: the least-norm shape, a tip-load shape for a chain
                norm = sum(w * w for _q, w in index)
                for q, w in index:
                    self.data.qpos[q] = x * w / norm
                    if rate:
                        self.data.qvel[self._dof_of_qpos(q)] = rate * w / norm
        mujoco.mj_forward(self.model, self.data)

    def actuate(self, command: dict[str, float]) -> dict[str, float]:
        """Each command clipped to its limit and converter (its unit), times its gain into the actuator."""
        out = {}
        for channel, (actuator, gain, limit, step) in self._commands.items():
            u = clip(float(command.get(channel, 0.0)), limit)
            if step:
                u = quantise(u, step)
            self.data.ctrl[actuator] = gain * u
            out[channel] = u
        return out


def _low_pass(hz: float, zeta, period: float):
    """(b, a) of a sensor's low-pass at `hz` (Hz) sampled every `period` (s): 1st order, or 2nd order
    wn^2 / (s^2 + 2 zeta wn s + wn^2) with `zeta` (Tustin); None without a filter."""
    if not hz:
        return None
    wn = 2 * math.pi * hz
    if zeta is None:
        alpha = 1.0 - math.exp(-wn * period)
        return [alpha], [1.0, alpha - 1.0]
    from scipy import signal

    b, a = signal.bilinear([wn * wn], [1.0, 2 * float(zeta) * wn, wn * wn], fs=1.0 / period)
    return [float(v) for v in b], [float(v) for v in a]


def _converter_step(spec: dict) -> float:
    """A command's converter resolution (its unit): 2 range / 2^bits, 0 without `bits`."""
    if "bits" not in spec:
        return 0.0
    return 2 * float(spec.get("range", spec.get("limit", 1.0))) / 2 ** int(spec["bits"])
