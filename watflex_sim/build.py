"""Build the bundled rigs' MuJoCo models from `params.py` with `mujoco.MjSpec`: Watflex and EMPS
here, the laser arm through the datasheet builder (datasheet.py), which it fits.

Flexible beams are "rigid finite element" chains: a beam of length L is cut into N elements
of length dx = L/N; a hinge with stiffness k = EI/dx and damping c = beta k sits at the middle
of each element, so the rigid bodies are a half segment at the root (part of the parent),
N-1 full segments and a half segment at the tip. README "Discretisation" gives the
convergence of this scheme against the analytic beam.
"""
from __future__ import annotations

import math

import mujoco

from .params import GRAVITY, STICK_SOLIMP, STICK_SOLREF, Emps, LaserArm, Watflex

BEAM_RGBA = [0.75, 0.78, 0.82, 1]
RIGID_RGBA = [0.3, 0.3, 0.35, 1]
MASS_RGBA = [0.8, 0.3, 0.2, 1]


def _spec(name: str, timestep: float) -> mujoco.MjSpec:
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False  # angles in radians
    spec.compiler.autolimits = True
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0, 0, -GRAVITY]
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    return spec


def _box(body, name, x0, length, thickness, height, mass, rgba):
    """A box geom from x0 to x0+length along the body's x axis, with the given mass (kg)."""
    g = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX)
    g.pos = [x0 + length / 2, 0, 0]
    g.size = [length / 2, thickness / 2, height / 2]
    g.mass = mass
    g.rgba = rgba
    g.contype = g.conaffinity = 0
    return g


def _rigid_bar(body, name, x0, length, width=0.02):
    """A massless drawing of a rigid offset (clamps, axes) along the body's x axis."""
    g = _box(body, name, x0, length, width, width, 0.0, RIGID_RGBA)
    g.group = 1
    return g


def add_flexible_chain(parent, prefix: str, beam, n_segments: int, x0: float):
    """Attach a flexible beam along the parent's x axis from x0 (m); return the tip body.

    Joints are named `{prefix}_j01..`, bodies `{prefix}_seg01..`; each hinge bends about z
    with stiffness EI/dx (N m/rad) and damping beta*EI/dx (N m s/rad).
    """
    dx = beam.length / n_segments
    k = beam.EI / dx
    mass = beam.mass_per_length * dx
    _box(parent, f"{prefix}_seg00", x0, dx / 2, beam.thickness, beam.height, mass / 2, BEAM_RGBA)
    body, pos = parent, [x0 + dx / 2, 0, 0]
    for i in range(1, n_segments + 1):
        body = body.add_body(name=f"{prefix}_seg{i:02d}", pos=pos)
        j = body.add_joint(name=f"{prefix}_j{i:02d}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
        j.stiffness = [k, 0, 0]  # N m/rad (linear term only)
        j.damping = [beam.damping_beta * k, 0, 0]  # N m s/rad
        length = dx if i < n_segments else dx / 2
        _box(body, f"{prefix}_seg{i:02d}", 0.0, length, beam.thickness, beam.height, beam.mass_per_length * length, BEAM_RGBA)
        pos = [dx, 0, 0]
    return body


def chain_tip_x(beam, n_segments: int) -> float:
    """x (m) of the beam's free end in the frame of the chain's last body."""
    return beam.length / n_segments / 2


def build_laser_arm(p: LaserArm) -> mujoco.MjSpec:
    """The laser arm (rigs.md §1): the datasheet model (datasheet.build) of datasheet.laser_arm_datasheet(p)."""
    from . import datasheet  # datasheet.py builds on this module's chain

    return datasheet.build(datasheet.laser_arm_datasheet(p), "laser_arm")


def _bearing(body, name: str, mass: float, p: Watflex):
    """An air-bearing puck carrying a point mass (kg): vertical slide joint, frictionless contact sphere."""
    body.add_joint(name=f"{name}_float", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
    g = body.add_geom(name=f"{name}_bearing", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[p.bearing_radius, 0, 0])
    g.mass = 0.0
    g.rgba = MASS_RGBA
    g.contype, g.conaffinity, g.condim = 1, 0, 1
    g.solref = [p.bearing_timeconst, 1.0]
    g.friction = [0, 0, 0]
    # rigs.md §2 [choice: point mass]: a 1 mm sphere, rotary inertia 4e-7 kg m^2 per kg
    m = body.add_geom(name=f"{name}_mass", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[1e-3, 0, 0])
    m.mass = mass
    m.contype = m.conaffinity = 0
    m.group = 3


def _sticking_friction(joint, friction) -> None:
    """Native dry friction that holds the joint exactly: level = break-away (N m), made nearly hard.

    The friction callback (joint_friction.py) resets the level every physics step from the
    friction law; the value here is the positive-direction break-away.
    """
    joint.frictionloss = friction.alpha0 + friction.alpha1
    joint.solref_friction = list(STICK_SOLREF)
    joint.solimp_friction = list(STICK_SOLIMP)


def _driven_link(body, joint_name: str, actuator, friction, prefix: str, beam, root: float, end: float, p: Watflex):
    """On `body`: the actuated hinge, the rigid root clamp (m), the flexible chain and the rigid end
    clamp (m); returns the chain's last body."""
    j = body.add_joint(name=joint_name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    j.armature = actuator.inertia  # kg m^2 at the output, thesis 4.5.6
    _sticking_friction(j, friction)
    _rigid_bar(body, f"{prefix}_root_clamp", 0.0, root)
    tip = add_flexible_chain(body, prefix, beam, p.n_segments, root)
    _rigid_bar(tip, f"{prefix}_end_clamp", chain_tip_x(beam, p.n_segments), end)
    return tip


def build_watflex(p: Watflex) -> mujoco.MjSpec:
    """Watflex: shoulder fixed to the table, two flexible links, elbow and end effector on air bearings."""
    spec = _spec("watflex", p.timestep)
    # Two frictionless contacts are the only constraints: PGS gives Newton's answer (to 1e-17 in
    # the scenarios) for 30-40 % less time per step (tools/bench.py).
    spec.option.solver = mujoco.mjtSolver.mjSOL_PGS
    spec.worldbody.add_light(name="top", pos=[0.6, 0, 3], dir=[0, 0, -1])
    glass = spec.worldbody.add_geom(name="glass", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.01])
    glass.rgba = [0.6, 0.75, 0.85, 1]
    glass.contype, glass.conaffinity, glass.condim = 0, 1, 1
    glass.friction = [0, 0, 0]
    z = p.bearing_radius  # arm plane height: the bearing spheres rest on the glass

    shoulder = spec.worldbody.add_body(name="shoulder_body", pos=[0, 0, z])
    tip1 = _driven_link(shoulder, "shoulder", p.shoulder, p.shoulder_friction[0], "link1", p.link1, p.l1a, p.l1c, p)
    elbow_housing = tip1.add_body(name="elbow_housing", pos=[chain_tip_x(p.link1, p.n_segments) + p.l1c, 0, 0])
    _bearing(elbow_housing, "elbow", p.elbow.mass, p)
    link2 = elbow_housing.add_body(name="link2_root")
    tip2 = _driven_link(link2, "elbow", p.elbow, p.elbow_friction[0], "link2", p.link2, p.l2a, p.l2c, p)
    ee = tip2.add_body(name="end_effector", pos=[chain_tip_x(p.link2, p.n_segments) + p.l2c, 0, 0])
    _bearing(ee, "end_effector", p.end_effector_mass, p)
    ee.add_site(name="tip", size=[0.01, 0, 0])

    for name, (link, x_gauge, _k) in p.gauges.items():
        beam = p.link1 if link == 1 else p.link2
        dx = beam.length / p.n_segments
        # body holding x_gauge: the root stub (before the first hinge) or segment i
        i = min(int(math.floor(x_gauge / dx + 0.5)), p.n_segments)
        body = spec.body(f"link{link}_seg{i:02d}") if i > 0 else (shoulder if link == 1 else link2)
        x_local = x_gauge - (i - 0.5) * dx if i > 0 else (p.l1a if link == 1 else p.l2a) + x_gauge
        body.add_site(name=f"strain_{name}", pos=[x_local, 0, 0], size=[0.004, 0, 0], rgba=[1, 1, 0, 1])

    for name, act in (("shoulder", p.shoulder), ("elbow", p.elbow)):
        motor = spec.add_actuator(name=f"{name}_motor", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        motor.ctrlrange = [-act.torque_limit, act.torque_limit]  # N m, converter range
    spec.add_key(name="home")
    return spec


def make_single_link(spec: mujoco.MjSpec) -> None:
    """Turn a Watflex spec into the single-link set-up (rigs.md §2, thesis 5.2.4): link 1's
    hinges go (a rigid link) and so does the elbow housing's air-bearing slide, its contact made
    inert (the cross beam to the wall holds the housing), so the elbow drives link 2 and the end
    effector, still on its own air bearing, from a fixed base. The shoulder hinge is the caller's
    to lock (model.load_model)."""
    for joint in [j for j in spec.joints if j.name.startswith("link1_j") or j.name == "elbow_float"]:
        spec.delete(joint)
    bearing = spec.geom("elbow_bearing")
    bearing.contype = bearing.conaffinity = 0  # kept (named) so an effect on it is a no-op, not an error


def build_emps(p: Emps) -> mujoco.MjSpec:
    """EMPS: a carriage of mass M on a slide `carriage` (x, m) with viscous friction, driven by force."""
    spec = _spec("emps", p.timestep)
    spec.worldbody.add_light(name="top", pos=[0, 0, 2], dir=[0, 0, -1])
    rail = spec.worldbody.add_geom(name="rail", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.15, 0.01, 0.005], pos=[0.12, 0, 0])
    rail.contype = rail.conaffinity = 0
    rail.rgba = RIGID_RGBA
    carriage = spec.worldbody.add_body(name="carriage_body", pos=[0, 0, 0.03])
    j = carriage.add_joint(name="carriage", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    j.damping = [p.viscous, 0, 0]  # N s/m
    j.solref_friction = list(STICK_SOLREF)
    j.solimp_friction = list(STICK_SOLIMP)
    g = carriage.add_geom(name="carriage", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.03, 0.02])
    g.mass = p.mass  # kg, all moving parts referred to the load
    g.contype = g.conaffinity = 0
    g.rgba = MASS_RGBA
    carriage.add_site(name="tip", size=[0.005, 0, 0])
    drive = spec.add_actuator(name="drive", target="carriage", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    limit = p.drive_gain * p.command_limit
    drive.ctrlrange = [-limit, limit]  # N
    spec.add_key(name="home")
    return spec


BUILDERS = {"laser_arm": build_laser_arm, "watflex": build_watflex, "emps": build_emps}
