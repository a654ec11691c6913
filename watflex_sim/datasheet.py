"""A rig's model from its datasheet: the `[datasheet]` table of a rig file, built with MjSpec.

A serial planar chain of stages, each a hub joint (hinge about z) and a link:
- hub `joint`: armature gear^2 rotor_inertia + hub_inertia (kg m^2 at the output), viscous
  `damping` (N m s/rad), the stage's `mass` (kg) at the joint (carried by the previous link's tip; a
  point: a 1 mm sphere, 4e-7 kg m^2 per kg, drawn as a massless 20 mm one); with `hub_radius` (m,
  flexible links only) the hub is a solid disc of that radius, a geom named after the joint, whose
  inertia about z is hub_inertia (mass 2 hub_inertia / hub_radius^2, carried like `mass`) instead of
  armature, so a refit `geom_mass` knob on it scales the hub inertia alone;
- link `flexible`: an RFE chain (build.add_flexible_chain: hinges of EI/dx, damping beta EI/dx with
  beta giving `damping_ratio` on the first clamped mode), with `n_segments` chosen so that the first
  three clamped modes are within 1 % of Euler-Bernoulli (beam_theory) unless given;
- link `torsional_spring`: one hinge of `stiffness` (or 3 EI / length, the cantilever's tip-load
  stiffness as a root spring) carrying its load inertia;
- `drive` `current` (actuator input: torque at the output, N m; the command channel's gain is
  efficiency x torque_constant x gear, N m/A, amplifier `limit` A) or `voltage` (a DC motor with
  back-EMF, actuator input V: tau = eta Kg Km (V - Km Kg w) / R, exactly MuJoCo's affine bias).
A value is a number in the key's SI unit (DATASHEET_KEYS) or a string "NUMBER UNIT" in that unit.
Bad input: ConfigError, one line naming the file and the key.
"""
from __future__ import annotations

import json
import math
import re
from functools import cache

import mujoco
import numpy as np
import scipy.linalg

from .beam_theory import clamped_free_frequencies
from .build import BEAM_RGBA, MASS_RGBA, RIGID_RGBA, _spec, add_flexible_chain, chain_tip_x
from .model import ConfigError
from .params import GRAVITY, STICK_SOLIMP, STICK_SOLREF, Beam, LaserArm

MODE_TOLERANCE = 0.01  # the first three clamped modes within 1 % of the closed form
MAX_SEGMENTS = 60
TINY = 1e-6  # kg, kg m^2: a body needs some mass; a hub's inertia is its joint's armature (or its disc)

# key -> (unit, required); "" unit: a name or a choice. Units as written in rig files.
TOP_KEYS = {"timestep": ("s", True), "gravity": ("m/s^2", False), "stages": ("", True)}
STAGE_KEYS = {"joint": ("", False), "hub_inertia": ("kg m^2", False), "hub_radius": ("m", False),
              "rotor_inertia": ("kg m^2", False),
              "gear": ("1", False), "damping": ("N m s/rad", False), "mass": ("kg", False),
              "drive": ("", True), "link": ("", True)}
DRIVE_KEYS = {
    "current": {"type": ("", True), "actuator": ("", False), "torque_constant": ("N m/A", True),
                "efficiency": ("1", False), "limit": ("A", False), "bits": ("1", False)},
    "voltage": {"type": ("", True), "actuator": ("", False), "torque_constant": ("N m/A", True),
                "resistance": ("ohm", True), "efficiency": ("1", False), "back_emf": ("V s/rad", False),
                "limit": ("V", False), "current_limit": ("A", False), "bits": ("1", False)},
}
_BEAM = {"type": ("", True), "name": ("", True), "length": ("m", True), "EI": ("N m^2", False),
         "E": ("Pa", False), "width": ("m", False), "thickness": ("m", False)}
LINK_KEYS = {
    "flexible": {**_BEAM, "mass_per_length": ("kg/m", True), "height": ("m", False), "tip_mass": ("kg", False),
                 "tip_inertia": ("kg m^2", False), "damping_ratio": ("1", False), "n_segments": ("1", False),
                 "root_clamp": ("m", False), "tip_clamp": ("m", False)},
    "torsional_spring": {**_BEAM, "stiffness": ("N m/rad", False), "damping": ("N m s/rad", False),
                         "inertia": ("kg m^2", False), "total_inertia": ("kg m^2", False),
                         "tip_mass": ("kg", False), "tip_distance": ("m", False), "tip_inertia": ("kg m^2", False),
                         "tip_size": ("m", False)},
}
NAMES = {"type", "name", "joint", "actuator"}
MAY_BE_ZERO = {"damping", "mass", "tip_mass", "tip_inertia", "hub_inertia", "rotor_inertia", "root_clamp",
               "tip_clamp", "inertia", "damping_ratio"}


def _number(value, where: str, unit: str) -> float:
    """A number in `unit`: a TOML number, or a string "NUMBER UNIT" whose unit is `unit`."""
    if isinstance(value, str):
        m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*(.*?)\s*", value)
        try:
            number = float(m.group(1))
        except (AttributeError, ValueError):
            raise ConfigError(f"{where}: {value!r} is not a number (in {unit})") from None
        if " ".join(m.group(2).split()) != unit:
            raise ConfigError(f"{where}: unit {m.group(2)!r}, expected {unit}")
        return number
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where}: must be a number in {unit}, got {value!r}")
    return float(value)


def _table(raw, keys: dict, where: str) -> dict:
    """`raw` checked against `keys` (unknown, missing, units, signs); numbers as floats."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: must be a table")
    unknown = sorted(set(raw) - set(keys))
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}: unknown key (known: {', '.join(keys)})")
    for key, (_unit, required) in keys.items():
        if required and key not in raw:
            raise ConfigError(f"{where}.{key}: missing")
    out = {}
    for key, value in raw.items():
        unit = keys[key][0]
        if key in NAMES:
            if not isinstance(value, str) or not value:
                raise ConfigError(f"{where}.{key}: must be a name, got {value!r}")
            out[key] = value
        elif key in ("drive", "link", "stages"):
            out[key] = value
        elif key == "tip_size":
            if not isinstance(value, list) or len(value) != 2:
                raise ConfigError(f"{where}.{key}: must be [a, b] in m")
            out[key] = [_number(v, f"{where}.{key}", unit) for v in value]
        else:
            number = _number(value, f"{where}.{key}", unit)
            if not math.isfinite(number) or number < 0 or (number == 0 and key not in MAY_BE_ZERO):
                raise ConfigError(f"{where}.{key}: must be {'>= 0' if key in MAY_BE_ZERO else '> 0'}, got {value!r}")
            out[key] = number
    return out


def _choice(raw, kinds: dict, where: str) -> dict:
    if not isinstance(raw, dict) or raw.get("type") not in kinds:
        got = raw.get("type") if isinstance(raw, dict) else raw
        raise ConfigError(f"{where}.type: must be one of {', '.join(kinds)}, got {got!r}")
    return _table(raw, kinds[raw["type"]], where)


def _bending_stiffness(link: dict, where: str) -> float:
    """EI (N m^2): given, or E w t^3 / 12."""
    if "EI" in link:
        return link["EI"]
    if {"E", "width", "thickness"} <= set(link):
        return link["E"] * link["width"] * link["thickness"] ** 3 / 12
    raise ConfigError(f"{where}.EI: missing (or E, width and thickness)")


def check(raw, source: str) -> dict:
    """The `[datasheet]` table of rig file `source`, checked; ConfigError (one line) if malformed."""
    where = f"{source}: datasheet"
    d = _table(raw, TOP_KEYS, where)
    if not isinstance(d["stages"], list) or not d["stages"]:
        raise ConfigError(f"{where}.stages: must be a list of stage tables ([[datasheet.stages]])")
    stages = []
    for n, raw_stage in enumerate(d["stages"], 1):
        at = f"{where}.stages[{n}]"
        stage = _table(raw_stage, STAGE_KEYS, at)
        stage.setdefault("joint", f"drive{n}")
        stage["drive"] = _choice(stage["drive"], DRIVE_KEYS, f"{at}.drive")
        stage["drive"].setdefault("actuator", f"motor{n}")
        if stage["drive"].get("bits", 1) != int(stage["drive"].get("bits", 1)):
            raise ConfigError(f"{at}.drive.bits: must be a whole number, got {stage['drive']['bits']!r}")
        link = stage["link"] = _choice(stage["link"], LINK_KEYS, f"{at}.link")
        if link["type"] == "flexible":
            link["EI"] = _bending_stiffness(link, f"{at}.link")
            if "n_segments" in link and (link["n_segments"] != int(link["n_segments"]) or link["n_segments"] < 2):
                raise ConfigError(f"{at}.link.n_segments: must be a whole number >= 2, got {link['n_segments']!r}")
            if "hub_radius" in stage and "hub_inertia" not in stage:
                raise ConfigError(f"{at}.hub_radius: the hub disc carries hub_inertia, which is missing")
        elif "hub_radius" in stage:
            raise ConfigError(f"{at}.hub_radius: a hub disc only on a flexible link's stage")
        elif "stiffness" not in link:
            link["stiffness"] = 3 * _bending_stiffness(link, f"{at}.link") / link["length"]
        if link["type"] == "torsional_spring" and "inertia" in link and "total_inertia" in link:
            raise ConfigError(f"{at}.link.total_inertia: give inertia or total_inertia, not both")
        stages.append(stage)
    d["stages"] = stages
    names = [s["joint"] for s in stages] + [s["drive"]["actuator"] for s in stages] + [s["link"]["name"] for s in stages]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}.stages: joint, actuator and link names must differ")
    for n in range(len(stages)):
        outboard_mass(stages, n)  # total_inertia less what it carries must stay > 0
    return d


# --- quantities the model is made of -------------------------------------------------------------


def armature(stage: dict) -> float:
    """Hub inertia at the output (kg m^2): gear^2 rotor_inertia + hub_inertia (unless a hub disc carries it)."""
    hub = 0.0 if "hub_radius" in stage else stage.get("hub_inertia", 0.0)
    return stage.get("gear", 1.0) ** 2 * stage.get("rotor_inertia", 0.0) + hub


def disc_mass(stage: dict) -> float:
    """Mass (kg) of the hub disc (`hub_radius`): a solid disc of inertia hub_inertia, 2 J / r^2; 0 without one."""
    return 2 * stage["hub_inertia"] / stage["hub_radius"] ** 2 if "hub_radius" in stage else 0.0


def torque_per_amp(stage: dict) -> float:
    """Output torque per amplifier current (N m/A): efficiency x torque_constant x gear."""
    drive = stage["drive"]
    return drive.get("efficiency", 1.0) * drive["torque_constant"] * stage.get("gear", 1.0)


def back_emf(stage: dict) -> float:
    """Back-EMF per output speed (V s/rad): `back_emf`, else torque_constant x gear."""
    drive = stage["drive"]
    return drive.get("back_emf", drive["torque_constant"] * stage.get("gear", 1.0))


def current_law(stage: dict) -> tuple[float, float, float]:
    """(Ke V s/rad, A per actuator input, current limit A) with i = (u - Ke w) x per_input, u the actuator
    input after its range, w the joint speed (rad/s): a current drive's u is the output torque (N m, Ke 0,
    per_input 1 / (eta Kt Kg)); a voltage drive's u is V, i = (V - Ke w) / R, clipped at current_limit."""
    drive = stage["drive"]
    if drive["type"] == "current":
        return 0.0, 1.0 / torque_per_amp(stage), math.inf
    return back_emf(stage), 1.0 / drive["resistance"], drive.get("current_limit", math.inf)


def command_gain(stage: dict) -> float:
    """Actuator input per command unit: N m/A for a current drive, 1 (V/V) for a voltage drive."""
    return torque_per_amp(stage) if stage["drive"]["type"] == "current" else 1.0


def tip_inertia(link: dict) -> float:
    """Own inertia of a link's tip body about its centre (kg m^2): tip_inertia or m (a^2 + b^2) / 12."""
    if "tip_size" in link:
        a, b = link["tip_size"]
        return link.get("tip_mass", 0.0) * (a * a + b * b) / 12
    return link.get("tip_inertia", 0.0)


def link_mass(link: dict) -> float:
    """Mass (kg) of the link and its tip load."""
    own = link["mass_per_length"] * link["length"] if link["type"] == "flexible" else 0.0
    return own + link.get("tip_mass", 0.0)


def reach(link: dict) -> float:
    """Distance (m) from the link's joint to where the next stage sits."""
    if link["type"] == "flexible":
        return link.get("root_clamp", 0.0) + link["length"] + link.get("tip_clamp", 0.0)
    return link["length"]


def outboard_mass(stages: list[dict], n: int) -> float:
    """Mass (kg) that link n (0-based) carries at its tip: its tip load and every later stage."""
    later = sum(s.get("mass", 0.0) + disc_mass(s) + link_mass(s["link"]) for s in stages[n + 1:])
    return stages[n]["link"].get("tip_mass", 0.0) + later


def _outboard_inertia(stages: list[dict], n: int) -> float:
    """Inertia (kg m^2) about joint n's link hinge of link n's tip load and the later stages, straight."""
    link = stages[n]["link"]
    x_tip = link.get("tip_distance", link["length"])
    total = link.get("tip_mass", 0.0) * x_tip**2 + tip_inertia(link)
    x = reach(link)
    for s in stages[n + 1:]:
        nxt = s["link"]
        total += (s.get("mass", 0.0) + disc_mass(s)) * x**2 + (s["hub_inertia"] if "hub_radius" in s else 0.0)
        if nxt["type"] == "torsional_spring":
            xt = x + nxt.get("tip_distance", nxt["length"])
            total += nxt.get("tip_mass", 0.0) * xt**2 + tip_inertia(nxt) + nxt.get("inertia", 0.0)
        else:
            r0, L = x + nxt.get("root_clamp", 0.0), nxt["length"]
            total += nxt["mass_per_length"] * ((r0 + L) ** 3 - r0**3) / 3 + nxt.get("tip_mass", 0.0) * (r0 + L + nxt.get("tip_clamp", 0.0)) ** 2
        x += reach(nxt)
    return total


def own_inertia(stages: list[dict], n: int) -> float:
    """A torsional-spring link's own inertia about its hinge (kg m^2): `inertia`, or `total_inertia`
    (everything the link carries at the straight pose, as Quanser's J12) less its tip load and later stages."""
    link = stages[n]["link"]
    if "total_inertia" not in link:
        return link.get("inertia", 0.0)
    own = link["total_inertia"] - _outboard_inertia(stages, n)
    if own <= 0:
        raise ConfigError(f"datasheet.stages[{n + 1}].link.total_inertia: {link['total_inertia']} kg m^2 is less than "
                          f"what the link carries ({_outboard_inertia(stages, n):.4g})")
    return own


def beam(link: dict, carried: float) -> Beam:
    """The flexible link as a params.Beam; `carried` (kg), at the end of its `tip_clamp`, places the first mode for the
    damping rule."""
    return Beam(length=link["length"], EI=link["EI"], mass_per_length=link["mass_per_length"],
                thickness=link.get("thickness", 0.01), height=link.get("height", link.get("width", 0.02)),
                tip_mass_for_damping=carried, damping_ratio=link.get("damping_ratio", 0.01),
                tip_offset_for_damping=link.get("tip_clamp", 0.0))


def clamped_modes(b: Beam, n_segments: int, tip_mass: float, n_modes: int = 3) -> np.ndarray:
    """First `n_modes` frequencies (rad/s) of the RFE chain of `b` clamped at its root, a point
    `tip_mass` (kg) at its free end: K v = w^2 M v at the straight pose."""
    spec = mujoco.MjSpec()
    root = spec.worldbody.add_body(name="clamp")
    last = add_flexible_chain(root, "beam", b, n_segments, 0.0)
    if tip_mass > 0:
        g = last.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[1e-4, 0, 0], pos=[chain_tip_x(b, n_segments), 0, 0])
        g.mass = tip_mass
    model = spec.compile()
    return chain_frequencies(model, np.arange(model.nv), n_modes)


def chain_dofs(model: mujoco.MjModel, prefix: str) -> np.ndarray:
    """Dof indices of the hinges `{prefix}_jNN` of an RFE chain (build.add_flexible_chain), root to tip."""
    return np.array([model.jnt_dofadr[j] for j in range(model.njnt) if model.joint(j).name.startswith(f"{prefix}_j")],
                    dtype=int)


def chain_frequencies(model: mujoco.MjModel, dofs: np.ndarray, n_modes: int = 3) -> np.ndarray:
    """First `n_modes` natural frequencies (rad/s) of K v = w^2 M v over `dofs` at the model's reference
    pose (K = diag(hinge stiffness), M = mj_fullM restricted to `dofs`: every other dof held)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    stiffness = np.diag(model.jnt_stiffness[model.dof_jntid[dofs]])
    return np.sqrt(scipy.linalg.eigh(stiffness, mass[np.ix_(dofs, dofs)], eigvals_only=True)[:n_modes])


@cache
def segments_for(b: Beam, tip_mass: float, tolerance: float = MODE_TOLERANCE) -> int:
    """Fewest RFE segments whose first three clamped modes (tip point mass `tip_mass` kg) are within
    `tolerance` of beam_theory.clamped_free_frequencies."""
    exact = clamped_free_frequencies(b, tip_mass, 3)
    for n in range(3, MAX_SEGMENTS + 1):
        if np.all(np.abs(clamped_modes(b, n, tip_mass) / exact - 1) < tolerance):
            return n
    raise ConfigError(f"datasheet: link of length {b.length} m needs more than {MAX_SEGMENTS} segments for 1 % modes")


# --- the model -------------------------------------------------------------------------------------


def _hinge(body, name: str, damping: float = 0.0, stiffness: float = 0.0, arm: float = 0.0):
    j = body.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    j.damping, j.stiffness, j.armature = [damping, 0, 0], [stiffness, 0, 0], arm
    j.solref_friction, j.solimp_friction = list(STICK_SOLREF), list(STICK_SOLIMP)  # dry friction an effect adds sticks hard
    return j


def _inertial(body, mass: float, x: float, izz: float) -> None:
    body.explicitinertial = True
    body.mass, body.ipos, body.inertia = mass, [x, 0, 0], [izz, izz, izz]


def _geom(body, name: str, kind, size: list[float], mass: float, rgba):
    """A geom that collides with nothing: `size` (m) as MuJoCo's, `mass` (kg)."""
    g = body.add_geom(name=name, type=kind, size=size + [0.0] * (3 - len(size)))
    g.mass, g.rgba, g.contype, g.conaffinity = mass, rgba, 0, 0
    return g


def _bar(body, name: str, length: float, width: float) -> None:
    """A massless drawing of a link, `width` m wide."""
    _geom(body, name, mujoco.mjtGeom.mjGEOM_BOX, [length / 2, width / 2, 0.005], 0.0, BEAM_RGBA).pos = [length / 2, 0, 0]


def n_segments(stages: list[dict], n: int) -> int:
    """RFE segments of flexible link n (0-based): given, or chosen for 1 % on three modes."""
    link = stages[n]["link"]
    if "n_segments" in link:
        return int(link["n_segments"])
    carried = outboard_mass(stages, n)
    return segments_for(beam(link, carried), carried)


def _flexible(hub, stages: list[dict], n: int):
    """Flexible link n on `hub`: its RFE chain and tip load; returns (body, x) where the next stage sits."""
    link = stages[n]["link"]
    b, n_seg = beam(link, outboard_mass(stages, n)), n_segments(stages, n)
    last = add_flexible_chain(hub, link["name"], b, n_seg, link.get("root_clamp", 0.0))
    x_end = chain_tip_x(b, n_seg)
    x_tip = x_end + link.get("tip_clamp", 0.0)  # the load sits at the end of the rigid tip clamp
    if link.get("tip_mass", 0.0) > 0:
        tip = last.add_body(name=f"{link['name']}_tip", pos=[x_tip, 0, 0])
        _inertial(tip, link["tip_mass"], 0.0, max(tip_inertia(link), TINY * link["tip_mass"]))
    last.add_site(name=f"{link['name']}_end", pos=[x_end, 0, 0], size=[0.005, 0, 0])
    return last, x_tip


def _torsional(hub, stages: list[dict], n: int):
    """Torsional-spring link n on `hub`: one hinge `{name}_j01` carrying its load; (body, x) of the next stage."""
    link = stages[n]["link"]
    body = hub.add_body(name=f"{link['name']}_seg01")  # "_seg": a one-segment chain, so chain effects apply
    _hinge(body, f"{link['name']}_j01", link.get("damping", 0.0), stiffness=link["stiffness"])
    own = own_inertia(stages, n)  # about the hinge: added at the tip body's centre, the parallel axes add m d^2 to both
    if link.get("tip_mass", 0.0) > 0:
        _inertial(body, link["tip_mass"], link.get("tip_distance", link["length"]), max(tip_inertia(link) + own, TINY))
    else:
        _inertial(body, TINY, 0.0, max(own, TINY))
    _bar(body, link["name"], link["length"], link.get("width", 0.03) / 3)
    return body, link["length"]


def build(d: dict, name: str = "datasheet_rig") -> mujoco.MjSpec:
    """The MjSpec of a checked datasheet (`check`): stage hubs `joint`, links, actuators, a `tip` site."""
    spec = _spec(name, d["timestep"])
    spec.option.gravity = [0, 0, -d.get("gravity", 9.81)]  # hinges are vertical: the arm moves in the horizontal plane
    spec.worldbody.add_light(name="top", pos=[0, 0, 2], dir=[0, 0, -1])
    stages, parent, x = d["stages"], spec.worldbody, 0.0
    for n, stage in enumerate(stages):
        hub = parent.add_body(name=f"hub{n + 1}", pos=[x, 0, 0])
        _hinge(hub, stage["joint"], stage.get("damping", 0.0), arm=armature(stage))
        link = stage["link"]
        if link["type"] == "flexible":
            if "hub_radius" in stage:  # a solid disc about z, 60 mm thick: m r^2 / 2 = hub_inertia
                disc = [stage["hub_radius"], 0.03]
                _geom(hub, stage["joint"], mujoco.mjtGeom.mjGEOM_CYLINDER, disc, disc_mass(stage), RIGID_RGBA)
            if stage.get("mass", 0.0) > 0:  # a point mass (1 mm sphere), drawn as a massless 20 mm one
                _geom(hub, f"hub{n + 1}", mujoco.mjtGeom.mjGEOM_SPHERE, [1e-3], stage["mass"], MASS_RGBA).group = 3
                _geom(hub, f"hub{n + 1}_drawing", mujoco.mjtGeom.mjGEOM_SPHERE, [0.02], 0.0, MASS_RGBA)
            parent, x = _flexible(hub, stages, n)
        else:
            _inertial(hub, stage["mass"] if stage.get("mass", 0.0) > 0 else TINY, 0.0, TINY)
            parent, x = _torsional(hub, stages, n)
    last = stages[-1]["link"]
    x_tip = x if last["type"] == "flexible" else last.get("tip_distance", last["length"])
    parent.add_site(name="tip", pos=[x_tip, 0, 0], size=[0.01, 0, 0])
    for stage in stages:
        _actuator(spec, stage)
    spec.add_key(name="home")
    return spec


def _actuator(spec: mujoco.MjSpec, stage: dict) -> None:
    """Current drive: input the output torque (N m; the command channel's gain is N m/A). Voltage drive:
    input V, tau = eta Kg Km (V - Ke w) / R as gain V + bias w (Ke = back_emf), torque clipped at the current limit."""
    drive = stage["drive"]
    act = spec.add_actuator(name=drive["actuator"], target=stage["joint"], trntype=mujoco.mjtTrn.mjTRN_JOINT)
    if drive["type"] == "voltage":
        per_volt = torque_per_amp(stage) / drive["resistance"]  # N m/V
        act.gainprm[0] = per_volt
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        act.biasprm[2] = -per_volt * back_emf(stage)  # N m s/rad
        if "current_limit" in drive:
            act.forcerange = [-torque_per_amp(stage) * drive["current_limit"], torque_per_amp(stage) * drive["current_limit"]]
        if "limit" in drive:
            act.ctrlrange = [-drive["limit"], drive["limit"]]
    elif "limit" in drive:
        act.ctrlrange = [-torque_per_amp(stage) * drive["limit"], torque_per_amp(stage) * drive["limit"]]


def command_defaults(d: dict) -> dict[str, dict]:
    """actuator -> what its command channel takes from the datasheet: gain, limit, bits."""
    out = {}
    for stage in d["stages"]:
        drive = stage["drive"]
        out[drive["actuator"]] = {"gain": command_gain(stage), **{k: drive[k] for k in ("limit", "bits") if k in drive}}
    return out


def model_xml(d: dict, name: str) -> str:
    """The MJCF text of a checked datasheet (`check`), built once per process."""
    return _xml(json.dumps(d, sort_keys=True), name)


@cache
def _xml(d_json: str, name: str) -> str:
    return build(json.loads(d_json), name).to_xml()


def laser_arm_datasheet(p: LaserArm) -> dict:
    """The laser arm of params.py (rigs.md §1) as a checked datasheet: hub `hub` (reflected motor N^2 J_e
    as armature, J_hub as a disc of `hub_radius`), voltage drive `motor`, flexible link `beam` with the tip
    sensor as its tip mass and p.n_segments segments."""
    b = p.beam
    stage = {"joint": "hub", "gear": p.gear_ratio, "rotor_inertia": p.motor_inertia, "hub_inertia": p.hub_inertia,
             "hub_radius": p.hub_radius, "damping": p.hub_viscous,
             "drive": {"type": "voltage", "actuator": "motor", "torque_constant": p.torque_constant,
                       "resistance": p.resistance, "efficiency": p.gear_efficiency, "back_emf": p.back_emf,
                       "limit": p.voltage_limit, "current_limit": p.current_limit},
             "link": {"type": "flexible", "name": "beam", "length": b.length, "EI": b.EI,
                      "mass_per_length": b.mass_per_length, "thickness": b.thickness, "height": b.height,
                      "tip_mass": p.tip_sensor_mass, "damping_ratio": b.damping_ratio, "n_segments": p.n_segments}}
    return check({"timestep": p.timestep, "gravity": GRAVITY, "stages": [stage]}, "params.py LaserArm")
