"""Load a rig's nominal model (the MJCF file its description names) with a scenario's payload, locks and tilt."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, Sequence

import mujoco
import numpy as np

from .build import BUILDERS, make_single_link
from .latest import Latest
from .params import GRAVITY

_PACKAGE = Path(__file__).resolve().parent
# The folder holding models/, rigs/, scenarios/, sweeps/: watflex_sim/data/ when installed from a
# wheel (pyproject.toml maps them there), else the repository beside the package (editable install).
ROOT = _PACKAGE / "data" if (_PACKAGE / "data" / "rigs").is_dir() else _PACKAGE.parent
MODELS_DIR = ROOT / "models"


class ConfigError(ValueError):
    """A scenario or option that cannot be simulated; the message is one line."""


def read_toml(path: Path, what: str) -> dict:
    """A TOML file's contents; FileNotFoundError passes through (callers name what is missing),
    any other failure is a one-line ConfigError naming the file and `what` it should be."""
    import tomllib

    try:
        return tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read {what}: {exc}".replace("\n", " ")) from None


def rig_params(rig: str):
    """The parameter set (params.py) of rig `rig`'s generated model (laser_arm, watflex, emps); None for
    a rig described by its file alone; ConfigError if the rig is unknown."""
    from .rigdesc import load_rig

    return load_rig(rig).params


SPECS_KEPT = 16  # model specs (`kept_spec`) kept: a diagnosis simulates a few discretisations of one rig
_SPECS = Latest(SPECS_KEPT)


def kept_spec(key: tuple, build: Callable[[], mujoco.MjSpec]) -> mujoco.MjSpec:
    """build() as a fresh spec: a copy of the one built before under `key` (the SPECS_KEPT latest). A Watflex
    generator's build costs ~15 ms and a model file's parse ~0.6 ms, a copy 0.01-0.1 ms, and a diagnosis or a sweep
    sets up thousands of simulations of one model."""
    spec = _SPECS.get(key)
    if spec is None:
        spec = build()
        _SPECS.put(key, spec)
    return spec.copy()


def load_model(
    rig,
    payload_kg: float = 0.0,
    locked_joints: dict[str, float] | None = None,
    tilt_rad: float = 0.0,
    tilt_azimuth_rad: float = 0.0,
    timestep: float | None = None,
    actuator_bench: str = "",
    edits: Sequence[Callable[[mujoco.MjSpec], None]] = (),
    n_segments: int = 0,
    single_link: bool = True,
) -> mujoco.MjModel:
    """Compile `rig` (a name or a loaded rigdesc.RigDescription) with an extra tip mass (kg), joints locked at angles (rad) and a tilted table.

    A locked joint is removed and its body turned to the lock angle, so it is exactly rigid.
    Tilt turns gravity by `tilt_rad` towards the azimuth `tilt_azimuth_rad` (rad from +x).
    `actuator_bench` names a joint to test alone, as thesis section 4.5 tests the actuators:
    the flexible chain it drives (and all it carries) is removed, so the joint moves its own
    identified inertia (armature) and clamps only; the other joints are locked at 0.
    `edits` change the spec first (effects and refit parameters, effects.Patch). `n_segments`
    (0: the committed model's) rebuilds the flexible parts with that many segments each.
    A Watflex lock on the shoulder is the single-link set-up of rigs.md §2 (link 1 rigid, elbow
    housing fixed: build.make_single_link); `single_link=False` locks the hinge alone and keeps
    link 1 flexible under the elbow on its air bearing (a different rig, for model tests).
    Raises ConfigError for a negative payload, an unknown joint, a bad timestep or segment count.
    """
    from .rigdesc import load_rig

    description = load_rig(rig) if isinstance(rig, str) else rig
    rig = description.name
    if n_segments and description.model not in BUILDERS:
        raise ConfigError(f"n_segments: rig {rig!r} has no model generator (its model is an MJCF file)")
    params = description.segmented(n_segments)
    spec = (description.spec() if not n_segments
            else kept_spec((description.model, repr(params)), lambda: BUILDERS[description.model](params)))
    for edit in edits:
        edit(spec)
    if actuator_bench:
        joint = spec.joint(actuator_bench)
        if joint is None or joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            raise ConfigError(f"actuator_bench: no hinge joint {actuator_bench!r} in {rig}")
        if actuator_bench in (locked_joints or {}):
            raise ConfigError(f"actuator_bench {actuator_bench!r} is also in locked_joints: the bench joint must be free")
        carried = [b for b in joint.parent.bodies]  # the flexible chain and everything on it
        for body in carried:
            spec.delete(body)
        others = {j.name: 0.0 for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_HINGE
                  and j.name != actuator_bench and "_j" not in j.name}
        locked_joints = {**others, **(locked_joints or {})}
    if payload_kg < 0:
        raise ConfigError(f"payload_kg must be >= 0, got {payload_kg}")
    if payload_kg > 0:
        site = spec.site("payload") or spec.site("tip")
        body = spec.body(site.parent.name)
        g = body.add_geom(name="payload", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0], pos=site.pos)
        g.mass = payload_kg
        g.contype = g.conaffinity = 0
        g.rgba = [0.9, 0.6, 0.1, 1]
    for name, angle in (locked_joints or {}).items():
        joint = spec.joint(name)
        if joint is None or joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            raise ConfigError(f"cannot lock {name!r}: no such hinge joint in {rig}")
        body = joint.parent
        spec.delete(joint)
        body.quat = [math.cos(angle / 2), 0, 0, math.sin(angle / 2)]
        for act in [a for a in spec.actuators if a.target == name]:
            spec.delete(act)
    if single_link and getattr(params, "single_link", None) and params.single_link(locked_joints):
        make_single_link(spec)
    if timestep is not None:
        if timestep <= 0:
            raise ConfigError(f"timestep must be > 0 s, got {timestep}")
        spec.option.timestep = timestep
    if tilt_rad:
        spec.option.gravity = [
            GRAVITY * math.sin(tilt_rad) * math.cos(tilt_azimuth_rad),
            GRAVITY * math.sin(tilt_rad) * math.sin(tilt_azimuth_rad),
            -GRAVITY * math.cos(tilt_rad),
        ]
    mount_accelerometers(spec, description)
    model = spec.compile()
    if not collidable(model):  # collision detection would find nothing, every step: skip it (same physics)
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return model


def mount_accelerometers(spec: mujoco.MjSpec, description) -> None:
    """For each measured channel of quantity `acceleration`: a site `accelerometer_CHANNEL` at `x` (m, default the
    link's `length`) along its `link` from the link's first hinge, its x axis along the link as it stands in the
    reference pose, z along the hinge axis, and MuJoCo's accelerometer there (specific force: acceleration less
    gravity, in the site's frame; rigs.GenericRig reads its y, across the link in the plane of motion). A link the
    model lacks (an actuator bench) gets none."""
    wanted = {c: s for c, s in description.channels.items()
              if s.get("quantity") == "acceleration" and s["kind"] == "measured"}
    if not wanted:
        return
    from .rigs import link_joints

    model = spec.copy().compile()  # the reference pose: the links straight
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)  # xanchor, xaxis
    for channel, s in wanted.items():
        ids = link_joints(model, s["link"])
        if not ids:
            continue
        anchors = data.xanchor[ids]
        body = int(model.jnt_bodyid[ids[0]])
        along = anchors[-1] - anchors[0] if len(ids) > 1 else data.xmat[body].reshape(3, 3)[:, 0]
        along = along / np.linalg.norm(along)
        x = float(s.get("x", s["length"]))
        at = max(k for k in range(len(ids)) if np.linalg.norm(anchors[k] - anchors[0]) <= x + 1e-12)
        body = int(model.jnt_bodyid[ids[at]])
        frame = data.xmat[body].reshape(3, 3)  # columns: the body's axes in the world
        normal = data.xaxis[ids[at]]
        axes = frame.T @ np.column_stack([along, np.cross(normal, along), normal])  # the site's axes in the body's
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, axes.flatten())
        site = f"accelerometer_{channel}"
        spec.body(model.body(body).name).add_site(name=site, pos=frame.T @ (anchors[0] + x * along - data.xpos[body]),
                                                  quat=quat, size=[0.004, 0, 0])
        spec.add_sensor(name=site, type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objtype=mujoco.mjtObj.mjOBJ_SITE,
                        objname=site)


def collidable(model: mujoco.MjModel) -> bool:
    """Whether any two geoms of `model` can touch: an explicit contact pair, or two geoms whose contype and
    conaffinity bits meet (the laser arm has none: its step then skips ~0.3 us of 3.2 us of collision checks)."""
    if model.npair:
        return True
    kind, affinity = model.geom_contype, model.geom_conaffinity
    meets = (kind[:, None] & affinity[None, :]) | (affinity[:, None] & kind[None, :])
    np.fill_diagonal(meets, 0)
    return bool(meets.any())
