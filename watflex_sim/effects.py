"""The effect catalogue of recordings.md and the parameter knobs, as changes to a simulation.

A `Patch` collects what effects and refit parameters change: model edits (MjSpec, before
compiling), model values (after compiling), joint friction, sensor and actuator transforms,
delays. `ControlLoop` applies it. Every effect reuses the simulator's own physics: friction
goes through `joint_friction`, compliance and backlash are extra hinges in the model, bearing
friction is MuJoCo contact friction.

Scenario keys: `effects = [{effect = "coulomb_friction", where = "hub", torque_positive = 2.7,
torque_negative = 0.9}, ...]` and `parameters = {knob_name = value}` where knobs are named by
the rig description (rigs/<rig>.toml) or directly as "<knob>:<target>" (e.g.
"chain_stiffness:beam" = 1.03, a ratio to nominal).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import mujoco

from .model import ConfigError
from .params import CONTROL_PERIOD, GRAVITY


@dataclass
class Patch:
    """Everything effects and refit parameters change in one simulation."""

    spec_edits: list[Callable[[mujoco.MjSpec], None]] = field(default_factory=list)
    model_edits: list[Callable[[mujoco.MjModel], None]] = field(default_factory=list)
    friction: dict[str, dict] = field(default_factory=dict)  # joint -> JointFriction field changes
    friction_add: dict[str, dict] = field(default_factory=dict)  # joint -> {(side, field): delta}
    sensor: dict[str, list[float]] = field(default_factory=dict)  # channel -> [gain, offset]
    sensor_delay: dict[str, int] = field(default_factory=dict)  # channel -> ticks
    actuator: dict[str, list[float]] = field(default_factory=dict)  # command channel -> [gain, offset, limit]
    command_delay: int = 0  # ticks
    payload_kg: float = 0.0  # kg added to the declared payload
    tilt_rad: float = 0.0


@dataclass(frozen=True)
class Param:
    """A fitted parameter: name, unit, bounds and a starting value (never at a bound).

    With a `scale`, low/high/start/neutral are multiples of a size taken from the data
    (diagnose.py): "effort" the RMS actuator force or torque, "effort/speed" that over the RMS
    speed, "command" the peak of the command channel `where`, "channel" the spread of channel
    `where`, "motion" the range of the joint's motion. `neutral` is the value at which the effect vanishes (None: no such value, e.g. a
    stiffness, or a shape parameter such as a time constant); `log` fits it on a log scale.
    """

    name: str
    unit: str
    low: float
    high: float
    start: float
    scale: str = ""
    neutral: float | None = None
    log: bool = False
    wide: bool = False  # the diagnosis probes it at start and 4x further from neutral (strongly nonlinear)
    quantum: float = 0.0  # it acts in whole steps of this (a delay in control periods): fitted by trying steps
    periodic: bool = False  # the period of `amplitude` sin(2 pi x / period + `phase`) in the same effect: fitted from a
    # scan of periods (the residual is far from convex in it)
    cyclic: bool = False  # an angle (a ripple's phase; low..high one turn): fitted within half a turn either side of
    # its value, so no wall holds a fit that wants to cross +-pi, and reported within (low, high] (canonical)
    profiled: bool = False  # a log-scaled parameter with no neutral that the final refit also restarts from along
    # its own short profile, and whose 95 % interval walks it, as a shape's (level.levels): Levenberg-Marquardt stops
    # short in its valley on a rough cost (seed 121, watflex-c6b358de: presliding's bristle damping 19.87 N m s/rad
    # left at 9.93, its 10.0 start, the staircase's strain 2.3 x its noise there; at 19.87, the rest refit, |r|^2 a third)
    variants: tuple[float, ...] = ()  # a shape parameter (no neutral) the screening also probes the effect's neutral
    # parameters at (at each of their levels), as these multiples of its start: the signature changes with it beyond
    # what a linear picture follows (a dwell's time constant; a Stribeck velocity: seed 107, a one-way shoulder
    # break-away of 1.088 N m decaying by 0.0103 rad/s screened at 1.3 % with the 0.03 rad/s start, 80 % at 0.009)


# --- knobs: what a refit parameter or an effect turns, by MuJoCo element name --------------


def _chain_joints(spec: mujoco.MjSpec, prefix: str) -> list:
    joints = [j for j in spec.joints if j.name.startswith(f"{prefix}_j")]
    if not joints:
        raise ConfigError(f"no flexible chain {prefix!r} in the model")
    return joints


def knob_chain_stiffness(patch: Patch, target: str, ratio: float) -> None:
    """Bending stiffness EI of chain `target` times `ratio` (hinge stiffness and its beta*k damping)."""
    def edit(spec):
        for j in _chain_joints(spec, target):
            j.stiffness = [j.stiffness[0] * ratio, 0, 0]
            j.damping = [j.damping[0] * ratio, 0, 0]
    patch.spec_edits.append(edit)


def knob_chain_damping(patch: Patch, target: str, ratio: float) -> None:
    """Structural damping of chain `target` times `ratio` (damping ratio scales with it)."""
    def edit(spec):
        for j in _chain_joints(spec, target):
            j.damping = [j.damping[0] * ratio, 0, 0]
    patch.spec_edits.append(edit)


def _joint(spec: mujoco.MjSpec, name: str):
    j = spec.joint(name)
    if j is None:
        raise ConfigError(f"no joint {name!r} in the model")
    return j


def knob_armature(patch: Patch, target: str, ratio: float) -> None:
    """Rotor/identified inertia (armature) of joint `target` times `ratio`."""
    def edit(spec):
        j = _joint(spec, target)
        j.armature *= ratio
    patch.spec_edits.append(edit)


def knob_body_inertia(patch: Patch, target: str, ratio: float) -> None:
    """Mass (and so inertia) of geom `target` times `ratio` (e.g. the laser hub cylinder)."""
    def edit(spec):
        g = spec.geom(target)
        if g is None:
            raise ConfigError(f"no geom {target!r} in the model")
        g.mass *= ratio
    patch.spec_edits.append(edit)


def knob_damping(patch: Patch, target: str, ratio: float) -> None:
    """Viscous damping of joint `target` times `ratio`."""
    def edit(spec):
        j = _joint(spec, target)
        j.damping = [j.damping[0] * ratio, 0, 0]
    patch.spec_edits.append(edit)


def knob_friction(patch: Patch, target: str, ratio: float) -> None:
    """All friction parameters of joint `target` (levels and viscous) times `ratio`."""
    patch.friction.setdefault(target, {})["scale"] = ratio


def knob_sensor_gain(patch: Patch, target: str, ratio: float) -> None:
    """Channel `target` reads `ratio` times the true value."""
    patch.sensor.setdefault(target, [1.0, 0.0])[0] *= ratio


def knob_actuator_gain(patch: Patch, target: str, ratio: float) -> None:
    """Command channel `target` acts with `ratio` times the commanded value."""
    patch.actuator.setdefault(target, [1.0, 0.0, math.inf])[0] *= ratio


KNOBS = {
    "chain_stiffness": knob_chain_stiffness,
    "chain_damping": knob_chain_damping,
    "armature": knob_armature,
    "geom_mass": knob_body_inertia,
    "damping": knob_damping,
    "friction": knob_friction,
    "sensor_gain": knob_sensor_gain,
    "actuator_gain": knob_actuator_gain,
}


def apply_parameters(patch: Patch, parameters: dict[str, float], named: dict[str, tuple[str, str]]) -> None:
    """Turn knobs: `parameters` maps a rig-description name (see `named`: name -> (knob, target))
    or "knob:target" to a ratio (1 = nominal)."""
    for name, value in parameters.items():
        if name in named:
            knob, target = named[name]
        else:
            knob, _, target = name.partition(":")
        if knob not in KNOBS or not target:
            raise ConfigError(f"unknown parameter {name!r} (known: {', '.join(named) or 'knob:target names'})")
        KNOBS[knob](patch, target, float(value))


# --- the effect catalogue (recordings.md) -----------------------------------------------------


def _side_add(patch: Patch, joint: str, side: str, field_name: str, delta: float) -> None:
    patch.friction_add.setdefault(joint, {})[(side, field_name)] = (
        patch.friction_add.get(joint, {}).get((side, field_name), 0.0) + delta)


def coulomb_friction(patch, where, torque_positive, torque_negative=None):
    """Sliding friction that sticks below it: +torque (N m) per direction on joint `where`."""
    _side_add(patch, where, "positive", "alpha0", torque_positive)
    _side_add(patch, where, "negative", "alpha0", torque_positive if torque_negative is None else torque_negative)


def stribeck_friction(patch, where, breakaway_positive, breakaway_negative=None, v_s=0.03):
    """Break-away excess alpha1 (N m) per direction above the sliding level, decaying with v_s (rad/s)."""
    _side_add(patch, where, "positive", "alpha1", breakaway_positive)
    _side_add(patch, where, "negative", "alpha1", breakaway_positive if breakaway_negative is None else breakaway_negative)
    patch.friction.setdefault(where, {})["v_s"] = v_s


def viscous_friction(patch, where, coefficient, coefficient_negative=None):
    """Extra viscous friction (N m s/rad; N s/m on a slide) on joint `where`, per direction if
    `coefficient_negative` is given."""
    _side_add(patch, where, "positive", "alpha2", coefficient)
    _side_add(patch, where, "negative", "alpha2", coefficient if coefficient_negative is None else coefficient_negative)


def presliding(patch, where, sigma0, sigma1=10.0):
    """LuGre bristles on joint `where`: stiffness sigma0 (N m/rad), damping sigma1 (N m s/rad)."""
    patch.friction.setdefault(where, {}).update(law="lugre", sigma0=sigma0, sigma1=sigma1)


def dwell_time_stiction(patch, where, gain, time_constant):
    """Break-away x (1 + gain (1 - exp(-t_rest / time_constant))) on joint `where` (s)."""
    patch.friction.setdefault(where, {}).update(dwell_gain=gain, dwell_time=time_constant)


def position_dependent_friction(patch, where, amplitude, period=2 * math.pi, phase=0.0, spring=0.0):
    """Torque a sin(2 pi q / period + phase) + spring q on joint `where` (N m, rad, N m/rad)."""
    patch.friction.setdefault(where, {}).update(
        ripple_amplitude=amplitude, ripple_period=period, ripple_phase=phase, spring=spring)


def canonical_moves(effect: dict) -> dict[str, tuple[float, float]]:
    """Per parameter, (sign, shift) taking `effect` to the one form reported where a catalogue parameterisation has
    more (value -> sign * value + shift; empty where it is in that form): a position-dependent friction's
    a sin(x + phase) with a < 0 is |a| sin(x + phase + pi), and a cyclic parameter (a phase) is reported within its
    catalogue turn (low, high] (a fit may carry it past, Param.cyclic)."""
    moves, turned = {}, dict(effect)
    if effect.get("effect") == "position_dependent_friction" and effect.get("amplitude", 0.0) < 0:
        moves["amplitude"] = (-1.0, 0.0)
        turned["phase"] = effect.get("phase", 0.0) + math.pi
    for p in CATALOGUE[effect["effect"]][1] if effect.get("effect") in CATALOGUE else ():
        if p.cyclic and p.name in turned:
            value = turned[p.name]
            if not p.low < value <= p.high:
                value = p.high - (p.high - value) % (p.high - p.low)
            if value != effect.get(p.name, 0.0):
                moves[p.name] = (1.0, value - effect.get(p.name, 0.0))
    return moves


def canonical(effect: dict) -> dict:
    """`effect` in its one reported form (canonical_moves): the same physics."""
    moves = canonical_moves(effect)
    return {**effect, **{n: sign * effect.get(n, 0.0) + shift for n, (sign, shift) in moves.items()}} if moves else effect


EXTRA_HINGE_ARMATURE = 5e-3  # kg m^2: the clamp between the two hinges in series [ours]; keeps
# sqrt(k / armature) * dt < 1 for k up to 2e4 N m/rad at Watflex's 0.5 ms (5e5 at the laser's 0.1 ms)
LIMIT_SOLREF = [0.002, 1.0]  # s, damping ratio: a hard dead-band stop (MuJoCo's default 0.02 s is a soft spring)


def _extra_hinge(spec: mujoco.MjSpec, where: str, name: str):
    """A hinge about z in series with the first hinge of the flexible chain that joint `where` drives.

    Both sit at the chain's first hinge; the small armature between them is the clamp."""
    joint = _joint(spec, where)
    chain_bodies = [b for b in joint.parent.bodies if "_seg" in b.name]
    if not chain_bodies:
        raise ConfigError(f"joint {where!r} drives no flexible chain to put {name} on")
    extra = chain_bodies[0].add_joint(name=f"{where}_{name}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    extra.armature = EXTRA_HINGE_ARMATURE
    return extra


def joint_compliance(patch, where, stiffness, damping_ratio=0.05):
    """Torsional spring (N m/rad) between joint `where` and its link (gear flexspline, root clamp)."""
    def edit(spec):
        j = _extra_hinge(spec, where, "compliance")
        j.stiffness = [stiffness, 0, 0]
        j.damping = [2 * damping_ratio * math.sqrt(stiffness * EXTRA_HINGE_ARMATURE), 0, 0]
    patch.spec_edits.append(edit)


def backlash(patch, where, width, position=0.0):
    """Dead band of `width` (rad) between joint `where` and its link, hard stops at +-width/2; the
    link starts at `position` x width/2 within it (+1: against the positive stop, so only a
    positive drive can open the band: a bolted root that slips one way, tightened the other)."""
    def edit(spec):
        j = _extra_hinge(spec, where, "backlash")
        j.ref = position * width / 2
        j.range = [-width / 2, width / 2]
        j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        j.solref_limit = LIMIT_SOLREF
        j.damping = [1e-2, 0, 0]  # N m s/rad: the slip is not free of losses [ours]
    patch.spec_edits.append(edit)


def payload(patch, where, mass):
    """Tip mass (kg) added to the declared payload (negative: less than declared)."""
    patch.payload_kg += mass


def link_stiffness_change(patch, where, ratio):
    """Bending stiffness of link `where` (chain prefix) times `ratio` (outside the tolerance)."""
    knob_chain_stiffness(patch, where, ratio)


def structural_damping(patch, where, ratio):
    """Beam damping of link `where` times `ratio`."""
    knob_chain_damping(patch, where, ratio)


def actuator_gain(patch, where, ratio):
    """Command channel `where` acts with `ratio` times the commanded torque/voltage/force."""
    knob_actuator_gain(patch, where, ratio)


def actuator_offset(patch, where, offset):
    """Constant bias added to command channel `where` in the plant (its unit: N m, V, ...)."""
    patch.actuator.setdefault(where, [1.0, 0.0, math.inf])[1] += offset


def current_saturation(patch, where, limit):
    """Command channel `where` saturates at +-limit (its unit) in the plant."""
    patch.actuator.setdefault(where, [1.0, 0.0, math.inf])[2] = limit


def sensor_gain(patch, where, ratio):
    """Channel `where` reads `ratio` times the true value."""
    knob_sensor_gain(patch, where, ratio)


def sensor_offset(patch, where, offset):
    """Channel `where` reads the true value plus `offset` (its unit)."""
    patch.sensor.setdefault(where, [1.0, 0.0])[1] += offset


def delay(patch, where, seconds):
    """Transport delay (s, whole control periods) of the commands (where='command') or of a channel."""
    ticks = max(0, int(round(seconds / CONTROL_PERIOD)))
    if where == "command":
        patch.command_delay = ticks
    else:
        patch.sensor_delay[where] = ticks


def bearing_friction(patch, where, force):
    """An air bearing touching down: sliding friction `force` (N) at bearing geom `where`."""
    def edit(model):
        g = model.geom(where)
        body = g.bodyid[0]
        mass = model.body_subtreemass[body]
        g.condim[0] = 3
        g.friction[0] = force / (mass * GRAVITY)
    patch.model_edits.append(edit)


def table_tilt(patch, where, angle):
    """Gravity component in the plane of motion: the table tilted by `angle` (rad)."""
    patch.tilt_rad += angle


P = Param
CATALOGUE: dict[str, tuple[Callable, tuple[Param, ...], str]] = {
    # id: (apply, parameters, what `where` names)
    "coulomb_friction": (coulomb_friction, (P("torque_positive", "N m", 0.0, 1.0, 0.1, "effort", 0.0), P("torque_negative", "N m", 0.0, 1.0, 0.1, "effort", 0.0)), "joint"),
    "stribeck_friction": (stribeck_friction, (P("breakaway_positive", "N m", 0.0, 1.0, 0.05, "effort", 0.0), P("breakaway_negative", "N m", 0.0, 1.0, 0.05, "effort", 0.0), P("v_s", "rad/s", 1e-3, 1.0, 0.03, log=True, variants=(0.3, 3.0))), "joint"),
    "viscous_friction": (viscous_friction, (P("coefficient", "N m s/rad", -0.5, 2.0, 0.05, "effort/speed", 0.0), P("coefficient_negative", "N m s/rad", -0.5, 2.0, 0.05, "effort/speed", 0.0)), "joint"),
    "presliding": (presliding, (P("sigma0", "N m/rad", 1e2, 1e6, 1e4, log=True),
                                P("sigma1", "N m s/rad", 0.1, 100.0, 10.0, log=True, profiled=True)), "joint"),
    "dwell_time_stiction": (dwell_time_stiction, (P("gain", "-", 0.0, 3.0, 0.5, neutral=0.0), P("time_constant", "s", 0.05, 30.0, 2.0, log=True, variants=(0.2, 5.0))), "joint"),
    "position_dependent_friction": (position_dependent_friction, (P("amplitude", "N m", -0.5, 0.5, 0.05, "effort", 0.0), P("period", "rad", 0.2, 200.0, 3.0, "motion", log=True, periodic=True), P("phase", "rad", -math.pi, math.pi, 0.0, cyclic=True), P("spring", "N m/rad", -50.0, 50.0, 0.0, neutral=0.0)), "joint"),
    "backlash": (backlash, (P("width", "rad", 1e-5, 0.5, 0.15, "motion", log=True), P("position", "-", -1.0, 1.0, 0.0)), "joint"),
    "joint_compliance": (joint_compliance, (P("stiffness", "N m/rad", 10.0, 3e4, 1e4, log=True),), "joint"),
    "payload": (payload, (P("mass", "kg", -2.0, 10.0, 0.2, neutral=0.0),), "tip"),
    "link_stiffness_change": (link_stiffness_change, (P("ratio", "-", 0.02, 1000.0, 0.9, neutral=1.0, log=True, wide=True),), "link"),  # a cracked link to a rigid one
    "structural_damping": (structural_damping, (P("ratio", "-", 0.5, 30.0, 2.0, neutral=1.0, wide=True),), "link"),
    "actuator_gain": (actuator_gain, (P("ratio", "-", 0.1, 5.0, 0.9, neutral=1.0),), "command"),
    "actuator_offset": (actuator_offset, (P("offset", "command unit", -0.5, 0.5, 0.02, "command", 0.0),), "command"),
    "current_saturation": (current_saturation, (P("limit", "command unit", 0.1, 1.5, 0.7, "command"),), "command"),
    "sensor_gain": (sensor_gain, (P("ratio", "-", -2.0, 2.0, 0.95, neutral=1.0),), "channel"),  # negative: a wiring sign error
    "sensor_offset": (sensor_offset, (P("offset", "channel unit", -0.5, 0.5, 0.02, "channel", 0.0),), "channel"),
    "delay": (delay, (P("seconds", "s", 0.0, 0.05, 0.001, neutral=0.0, wide=True, quantum=CONTROL_PERIOD),), "command or channel"),
    "bearing_friction": (bearing_friction, (P("force", "N", 0.0, 50.0, 1.0, neutral=0.0),), "bearing geom"),
    "table_tilt": (table_tilt, (P("angle", "rad", -0.05, 0.05, 0.001, neutral=0.0),), "rig"),
}


def apply_effects(patch: Patch, effects: list[dict]) -> None:
    """Add scenario `effects` (list of {effect, where, <parameters>}) to `patch`; ConfigError if malformed."""
    for spec in effects:
        spec = dict(spec)
        name = spec.pop("effect", None)
        if name not in CATALOGUE:
            raise ConfigError(f"unknown effect {name!r} (catalogue: {', '.join(CATALOGUE)})")
        where = spec.pop("where", "")
        spec.pop("direction", None)  # informative only: the parameters say it
        apply, params, _ = CATALOGUE[name]
        try:
            apply(patch, where, **spec)
        except TypeError as exc:
            raise ConfigError(f"effect {name!r}: {exc} (parameters: {', '.join(p.name for p in params)})") from None
