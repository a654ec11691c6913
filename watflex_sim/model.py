"""Load a rig's nominal model (`models/<rig>.xml`) with a scenario's payload, locks and tilt."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Callable, Sequence

import mujoco

from .build import BUILDERS
from .params import GRAVITY, RIGS

ROOT = Path(__file__).resolve().parent.parent
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
    """The parameter set of `rig` ('laser_arm' or 'watflex'); ConfigError if unknown."""
    if rig not in RIGS:
        raise ConfigError(f"unknown rig {rig!r} (known: {', '.join(RIGS)})")
    return RIGS[rig]


def segmented(rig: str, n_segments: int):
    """The rig's parameters with `n_segments` segments per flexible part (0: unchanged)."""
    params = rig_params(rig)
    if not n_segments:
        return params
    if not isinstance(n_segments, int) or n_segments < 2 or not hasattr(params, "n_segments"):
        raise ConfigError(f"n_segments must be an integer >= 2 on a rig with flexible parts, got {n_segments!r}")
    return dataclasses.replace(params, n_segments=n_segments)


def nominal_spec(rig: str) -> mujoco.MjSpec:
    """The committed nominal model of `rig`, or the generator's if the XML is not there."""
    if rig not in RIGS:  # a rig from its description alone: models/<model>.xml, generated outside the code
        from .rigdesc import load_rig

        path = MODELS_DIR / f"{load_rig(rig).model}.xml"
        if not path.exists():
            raise ConfigError(f"rig {rig!r}: model file {path} not found")
        return mujoco.MjSpec.from_file(str(path))
    params = rig_params(rig)
    path = MODELS_DIR / f"{rig}.xml"
    return mujoco.MjSpec.from_file(str(path)) if path.exists() else BUILDERS[rig](params)


def load_model(
    rig: str,
    payload_kg: float = 0.0,
    locked_joints: dict[str, float] | None = None,
    tilt_rad: float = 0.0,
    tilt_azimuth_rad: float = 0.0,
    timestep: float | None = None,
    actuator_bench: str = "",
    edits: Sequence[Callable[[mujoco.MjSpec], None]] = (),
    n_segments: int = 0,
) -> mujoco.MjModel:
    """Compile `rig` with an extra tip mass (kg), joints locked at angles (rad) and a tilted table.

    A locked joint is removed and its body turned to the lock angle, so it is exactly rigid.
    Tilt turns gravity by `tilt_rad` towards the azimuth `tilt_azimuth_rad` (rad from +x).
    `actuator_bench` names a joint to test alone, as thesis section 4.5 tests the actuators:
    the flexible chain it drives (and all it carries) is removed, so the joint moves its own
    identified inertia (armature) and clamps only; the other joints are locked at 0.
    `edits` change the spec first (effects and refit parameters, effects.Patch). `n_segments`
    (0: the committed model's) rebuilds the flexible parts with that many segments each.
    Raises ConfigError for a negative payload, an unknown joint, a bad timestep or segment count.
    """
    spec = nominal_spec(rig) if not n_segments else BUILDERS[rig](segmented(rig, n_segments))
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
    return spec.compile()
