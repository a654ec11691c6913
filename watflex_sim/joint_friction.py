"""Joint friction of the plant, installed as a MuJoCo passive-force callback.

Sticking is MuJoCo's own: each hinge with friction has a `frictionloss` constraint (made
nearly hard in the model: solref 1 ms, solimp 0.9999), which holds the joint exactly under
any coupled load up to its level and slides at that level beyond it. The callback sets that
level every physics step from the friction law (break-away at rest, the Stribeck level
of the direction of motion when sliding, raised by dwell time) and applies what is not a
level (viscous, position-dependent torque) as a torque. The LuGre option replaces
both by the LuGre torque. The level set in one step acts from the next (MuJoCo builds its
constraints before the passive forces), a lag of one physics step (0.1-0.5 ms).

One physics, two drivers: the callback (single runs) and `BatchFriction` (lockstep batches) give
the same numbers to the last bit. Both add the torque to what the rig applies in `qfrc_applied`
(the callback may write it: MuJoCo reads it after the passive forces), and the callback does its
arithmetic as numpy does on arrays: `numpy.exp` and `numpy.sin` (math.exp differs from numpy's in
the last bit for ~5 % of arguments) and, in friction.stribeck_level, x * x for a square (what numpy's
`** 2.0` computes; a Python float's `** 2.0` differs for ~0.1 %). An ulp is not harmless here: stick-slip amplifies it
into another stopping point, and a diagnosis' findings then depended on which driver ran a model.

MuJoCo's callbacks are global to the process: use one simulation per process at a time and
always leave the `with` block (the callback is removed in `__exit__`).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from .friction import lugre_step, stribeck_level
from .model import ConfigError
from .params import Friction

V_REST = 1e-4  # rad/s: below this a joint is taken to be at rest (dwell timer, push direction)
LAWS = ("exponential", "lugre")


@dataclass(frozen=True)
class JointFriction:
    """Plant friction of one hinge (rigs.md §2; thesis eq. 4.5-4.6, 4.20, 4.1.6)."""

    positive: Friction  # parameters for v > 0
    negative: Friction  # parameters for v < 0
    law: str = "exponential"  # exponential (stick + Stribeck, nominal) | lugre
    sigma0: float = 259.0  # N m/rad, LuGre bristle stiffness; rigs.md §2 (thesis 4.5.4)
    sigma1: float = 10.0  # N m s/rad, LuGre bristle damping; rigs.md §2
    dwell_gain: float = 0.0  # break-away x (1 + gain (1 - exp(-t_rest / dwell_time))); thesis 4.1.6
    dwell_time: float = 1.0  # s
    ripple_amplitude: float = 0.0  # N m, torque a sin(2 pi q / ripple_period + ripple_phase)
    ripple_period: float = 2 * math.pi  # rad
    ripple_phase: float = 0.0  # rad
    spring: float = 0.0  # N m/rad, cable drag as a spring about q = 0

    def breakaway(self, direction: int, rest_time: float = 0.0) -> float:
        """Break-away torque (N m) in a direction (+1/-1) after `rest_time` (s) at rest."""
        p = self.positive if direction > 0 else self.negative
        return (p.alpha0 + p.alpha1) * (1.0 + self.dwell_gain * (1.0 - math.exp(-rest_time / self.dwell_time)))


def nominal_frictions(rig) -> dict[str, JointFriction]:
    """The nominal model's joint friction (rigs.md) of `rig` (a name or a loaded rigdesc.RigDescription):
    its parameter set's `<joint>_friction` laws (Watflex shoulder and elbow); none on other rigs."""
    from .rigdesc import load_rig

    params = (load_rig(rig) if isinstance(rig, str) else rig).params
    return {joint: JointFriction(*getattr(params, f"{joint}_friction"))
            for joint in ("shoulder", "elbow") if hasattr(params, f"{joint}_friction")}


def scenario_frictions(rig, scenario: dict) -> dict[str, JointFriction]:
    """A checked scenario's joint friction before effects: the rig's nominal laws (friction 'nominal'; none for
    'none') with its `joint_friction` table applied (`configure`)."""
    return configure(nominal_frictions(rig) if scenario["friction"] == "nominal" else {}, scenario["joint_friction"])


def configure(base: dict[str, JointFriction], overrides: dict) -> dict[str, JointFriction]:
    """Apply a scenario's `joint_friction` table ({joint: {field: value, positive: {alpha0: ..}}}).

    A joint not in `base` needs `positive` and `negative` given in full. ConfigError on an
    unknown field or law.
    """
    out = dict(base)
    for joint, fields in overrides.items():
        if not isinstance(fields, dict):
            raise ConfigError(f"joint_friction.{joint} must be a table")
        fields = dict(fields)
        try:
            for side in ("positive", "negative"):
                if side in fields:
                    given = fields.pop(side)
                    fields[side] = dataclasses.replace(getattr(out[joint], side), **given) if joint in out else Friction(**given)
            out[joint] = dataclasses.replace(out[joint], **fields) if joint in out else JointFriction(**fields)
        except TypeError as exc:
            raise ConfigError(f"joint_friction.{joint}: {exc}") from None
        if out[joint].law not in LAWS:
            raise ConfigError(f"joint_friction.{joint}.law must be one of {', '.join(LAWS)}, got {out[joint].law!r}")
    return out


def patched(frictions: dict[str, JointFriction], changes: dict[str, dict], additions: dict[str, dict]) -> dict[str, JointFriction]:
    """Apply effects (effects.Patch.friction / friction_add) to joint frictions.

    `changes`: joint -> JointFriction fields to set (and "scale": all levels times a ratio);
    `additions`: joint -> {(side, field): delta} added to a direction's parameters. A joint
    without friction starts from zero friction (v_s 0.03 rad/s).
    """
    out = dict(frictions)
    zero = Friction(alpha0=0.0, alpha1=0.0, alpha2=0.0, v_s=0.03)
    for joint in set(changes) | set(additions):
        law = out.get(joint, JointFriction(zero, zero))
        fields = dict(changes.get(joint, {}))
        scale = fields.pop("scale", 1.0)
        v_s = fields.pop("v_s", None)
        sides = {}
        for side in ("positive", "negative"):
            p = getattr(law, side)
            p = Friction(p.alpha0 * scale, p.alpha1 * scale, p.alpha2 * scale, v_s or p.v_s)
            for (s, name), delta in additions.get(joint, {}).items():
                if s == side:
                    p = dataclasses.replace(p, **{name: getattr(p, name) + delta})
            sides[side] = p
        out[joint] = dataclasses.replace(law, **sides, **fields)
    return out


class FrictionCallback:
    """Installs the friction of `frictions` (joint name -> JointFriction) on (model, data).

    Use as `with FrictionCallback(model, data, frictions): mj_step(...)`. Joints missing from
    the model (locked ones) are skipped. State per joint: time at rest (s), LuGre z (rad).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, frictions: dict[str, JointFriction]):
        self.model, self.data = model, data
        self.dt = model.opt.timestep
        self.joints = []  # [dof, qpos address, JointFriction, state]
        for name, law in frictions.items():
            jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                continue
            dof = int(model.jnt_dofadr[jid])
            self.joints.append([dof, int(model.jnt_qposadr[jid]), law, {"rest": 0.0, "z": 0.0}])
            model.dof_frictionloss[dof] = law.breakaway(+1) if law.law == "exponential" else 0.0
        self.applied = {dof: float(data.qfrc_applied[dof]) for dof, *_ in self.joints}  # N m: what the rig applies
        self._previous = None
        self._time = math.nan  # simulation time of the last evaluation (s)

    def __enter__(self) -> "FrictionCallback":
        self._previous = mujoco.get_mjcb_passive()
        if self.joints:  # no friction to apply: no per-step Python call at all
            mujoco.set_mjcb_passive(self)
        return self

    def __exit__(self, *exc) -> None:
        if self.joints:
            mujoco.set_mjcb_passive(self._previous)
            self.restore_applied()

    def take_applied(self) -> None:
        """Note what the rig applies at the friction's joints (`qfrc_applied`, N m) before a tick's steps."""
        for dof in self.applied:
            self.applied[dof] = self.data.qfrc_applied[dof].item()

    def restore_applied(self) -> None:
        """Leave `qfrc_applied` as the rig set it (the friction's torque is added to it during steps only)."""
        for dof, value in self.applied.items():
            self.data.qfrc_applied[dof] = value

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        if d is not self.data:
            return
        # States advance once per physics step, however often MuJoCo evaluates passive forces
        # (RK4, an extra mj_forward): a repeated evaluation at the same time reuses them.
        advance = d.time != self._time
        self._time = d.time
        dt = self.dt
        for joint in self.joints:
            dof, qadr, law, state = joint
            v = d.qvel[dof].item()
            torque = 0.0  # N m, added to the joint (the friction felt, i.e. -F)
            if law.law == "lugre":
                if advance:
                    state["F"], state["z"] = lugre_step(v, state["z"], dt, law.sigma0, law.sigma1, law.positive, law.negative)
                torque -= state.get("F", 0.0)
            else:
                if v > V_REST:
                    direction = 1
                elif v < -V_REST:
                    direction = -1
                else:  # at rest: the direction the joint is pushed, against the holding force
                    direction = 1 if d.qfrc_constraint[dof] <= 0 else -1
                p = law.positive if direction > 0 else law.negative
                speed = abs(v)
                if advance:
                    state["rest"] = state["rest"] + dt if speed < V_REST else 0.0
                level = stribeck_level(speed, p)
                if law.dwell_gain:
                    level = level * (1.0 + law.dwell_gain * (1.0 - float(np.exp(-state["rest"] / law.dwell_time))))
                m.dof_frictionloss[dof] = level
                torque -= p.alpha2 * v
            if law.ripple_amplitude or law.spring:
                q = d.qpos[qadr].item()
                torque -= law.ripple_amplitude * float(np.sin(2 * np.pi * q / law.ripple_period + law.ripple_phase))
                torque -= law.spring * q
            d.qfrc_applied[dof] = self.applied[dof] + torque


class BatchFriction:
    """The same friction for many simulations at once, on arrays (lockstep.simulate_batch).

    `members[i]` is simulation i's FrictionCallback (built, never installed). `step(qpos, qvel,
    qfrc_constraint)` is called once before each physics step with the (nsim, n) state and the
    previous step's constraint force; it returns the (nsim, nv) torque for `qfrc_applied` and
    writes the level into the expanded `dof_frictionloss`. As in the callback, the level computed
    before step j acts from step j + 1 (MuJoCo builds its constraints before the passive forces).
    """

    def __init__(self, members: list[FrictionCallback], frictionloss: np.ndarray, nv: int):
        rows = [(i, dof, qadr, law, state) for i, m in enumerate(members) for dof, qadr, law, state in m.joints]
        self.frictionloss, self.torque = frictionloss, np.zeros((len(members), nv))
        self.sim = np.array([r[0] for r in rows], dtype=int)
        self.dt = np.array([members[i].dt for i in self.sim], dtype=float)  # s, each simulation's physics step
        self.dof = np.array([r[1] for r in rows], dtype=int)
        self.qadr = np.array([r[2] for r in rows], dtype=int)
        laws = [r[3] for r in rows]
        self.lugre = [(k, law, state) for k, (_i, _d, _q, law, state) in enumerate(rows) if law.law == "lugre"]
        self.exp = np.array([law.law == "exponential" for law in laws], dtype=bool)
        self.all_exp = bool(self.exp.all())
        col = lambda f: np.array([f(law) for law in laws], dtype=float)  # noqa: E731
        self.side = {s: np.array([col(lambda law, s=s, name=name: getattr(getattr(law, s), name))  # (4, n): alpha0,
                                  for name in ("alpha0", "alpha1", "alpha2", "v_s")]) for s in ("positive", "negative")}  # 1, 2, v_s
        self.dwell_gain, self.dwell_time = col(lambda law: law.dwell_gain), col(lambda law: law.dwell_time)
        self.ripple = col(lambda law: law.ripple_amplitude)
        self.ripple_period, self.ripple_phase = col(lambda law: law.ripple_period), col(lambda law: law.ripple_phase)
        self.spring = col(lambda law: law.spring)
        self.positional = bool((self.ripple != 0).any() or (self.spring != 0).any())
        self.rest = np.zeros(len(rows))  # s at rest
        self.pending = frictionloss[self.sim, self.dof].copy()  # N m: the level for the next step

    def __len__(self) -> int:
        return len(self.sim)

    def step(self, qpos: np.ndarray, qvel: np.ndarray, qfrc_constraint: np.ndarray) -> np.ndarray:
        """Levels and torques (N m) for the coming physics step; returns the torque array."""
        sim, dof = self.sim, self.dof
        v = qvel[sim, dof]
        self.frictionloss[sim, dof] = self.pending  # the level the callback set during the last step
        forward = (v > V_REST) | (~(v < -V_REST) & (qfrc_constraint[sim, dof] <= 0))  # at rest: the push's way
        alpha0, alpha1, alpha2, v_s = np.where(forward, self.side["positive"], self.side["negative"])
        speed = np.abs(v)
        self.rest = np.where(speed < V_REST, self.rest + self.dt, 0.0)
        level = alpha0 + alpha1 * np.exp(-((speed / v_s) ** 2.0))
        dwell = self.dwell_gain != 0
        if dwell.any():
            level = np.where(dwell, level * (1.0 + self.dwell_gain * (1.0 - np.exp(-self.rest / self.dwell_time))), level)
        if self.all_exp:
            self.pending, tau = level, -alpha2 * v
        else:
            self.pending = np.where(self.exp, level, self.pending)
            tau = np.where(self.exp, -alpha2 * v, 0.0)
        for k, law, state in self.lugre:
            state["F"], state["z"] = lugre_step(float(v[k]), state["z"], float(self.dt[k]), law.sigma0, law.sigma1, law.positive, law.negative)
            tau[k] = -state["F"]
        if self.positional:
            q = qpos[sim, self.qadr]
            tau = tau - self.ripple * np.sin(2 * np.pi * q / self.ripple_period + self.ripple_phase) - self.spring * q
        self.torque[sim, dof] = tau
        return self.torque
