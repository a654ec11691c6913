"""Rig descriptions: a rig as data, for simulation and diagnosis.

A rig is a TOML file: `rig.toml` in a folder the user owns (or any NAME.toml) naming the model
(`model`: an MJCF file relative to the rig file, the name of a bundled model, models/NAME.xml, or
"datasheet": generated from its [datasheet] table by datasheet.py),
the sensor implementation, the channels (unit, kind, noise), the default controller, the
parameters that may be refit within a tolerance (knobs of effects.py) and where each catalogue
effect may attach. A rig whose sensors are in the library (`generic`: encoders, commands,
references, disturbances) needs no code.

A rig named in a sidecar or scenario (`rig = "myrig"`) is found, first match wins, in
1. the entries of WATFLEX_RIGS (os.pathsep-separated): a rig file, a rig folder (with rig.toml),
   or a folder of rigs (NAME.toml files and NAME/rig.toml folders), matched by their `name`;
2. the bundled rigs (rigs/ in the repository, watflex_sim/data/rigs/ installed).
`use_rig(PATH)` (the command line's --rig PATH) puts the file first in WATFLEX_RIGS, so worker
processes (forked, spawned or a forkserver's) resolve names the same way.
"""
from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache, cached_property
from itertools import chain
from pathlib import Path

import mujoco

from .model import ROOT, ConfigError, read_toml
from .params import CONTROL_PERIOD

RIGS_DIR = ROOT / "rigs"  # the bundled rigs
ENV = "WATFLEX_RIGS"
KINDS = ("reference", "measured", "command", "disturbance")
SENSORS = ("laser_arm", "watflex", "generic")
# SI units a channel may carry (recordings.md section 1); "1" for a dimensionless channel.
UNITS = ("rad", "m", "rad/s", "m/s", "rad/s^2", "m/s^2", "V", "A", "N", "N m", "1", "-", "deg", "deg/s", "mm")  # deg, mm: with a scale; "-" = "1"
# Controller-table keys whose (string or list-of-string) values name channels of the rig.
CHANNEL_ROLES = ("position", "reference", "command", "commands", "velocity", "deflection", "measured", "output",
                 "channel", "channels", "states", "inputs", "outputs")
# A rig file's keys; datasheet: the model's numbers, built by datasheet.py when model = "datasheet"; extends: a base
# rig whose keys this file takes unless it sets them (_raw)
KEYS = ("name", "model", "sensors", "channels", "controller", "parameters", "effects", "time_variable",
        "mat_scalars", "sidecar", "description", "mat_channels", "mat_time", "control_period_s",
        "control_jitter_s", "datasheet", "columns", "extends")
# What a generic measured channel reads (rigs.GenericRig): a joint's position (rad or m) or
# velocity, a link's tip deflection (m) or its angle (rad), the strain at x on a link, the current (A) of a
# datasheet drive (`actuator`), or an accelerometer's reading across a link at x (m/s^2; model.mount_accelerometers).
QUANTITIES = ("position", "velocity", "deflection", "deflection_angle", "strain", "current", "acceleration")
# Keys a channel may have (rigs.GenericRig reads them; the other sensor models read unit, kind, noise).
CHANNEL_KEYS = {"unit", "kind", "joint", "link", "quantity", "scale", "offset", "step", "noise", "filter_hz",
                "filter_zeta", "length", "x", "thickness", "actuator", "gain", "limit", "bits", "range",
                "current_per_unit"}  # A per command unit: a command limit also reported as a current
MAT_KEYS = {"file", "variable", "column", "scale"}
MERGED = ("channels", "parameters", "effects")  # tables a rig that `extends` another merges entry by entry
DATASHEET = "datasheet"  # model = "datasheet": the model is generated from the rig file's [datasheet]


@dataclass(frozen=True)
class RigDescription:
    name: str
    model: str  # MJCF file relative to `source`, or a bundled model's name (models/<model>.xml)
    sensors: str  # laser_arm | watflex | generic
    channels: dict  # channel -> {unit, kind, noise?, joint?, actuator?, gain?, limit?, step?}
    controller: dict  # default controller table
    parameters: dict  # name -> {knob, target, tolerance}
    effects: dict  # effect id -> [where, ...]
    time_variable: str = "time"  # .mat variable with the time in s
    mat_channels: dict | None = None  # channel -> {file, variable, column?, scale?}: one .mat file per signal
    mat_time: dict | None = None  # {file, variable, column?, scale?}: where the time is (scale to s)
    control_period_s: float = CONTROL_PERIOD  # s, the rig's sample period (controller and sensors)
    control_jitter_s: float = 0.0  # s, each command reaches the plant 0..this late (engine.ControlLoop)
    mat_scalars: tuple = ()  # 1x1 .mat variables kept for the sidecar ("mat:NAME")
    sidecar: dict | None = None  # default sidecar for files that come without one (--rig)
    description: str = ""
    source: str = ""  # the rig file
    datasheet: dict | None = None  # the checked [datasheet] table (datasheet.check), if any
    columns: dict = dataclasses.field(default_factory=dict)  # a text file's column -> (channel | "time" | "", scale)

    def units(self) -> dict[str, str]:
        return {c: spec["unit"] for c, spec in self.channels.items()}

    def period_of(self, settings: dict) -> float:
        """s: the control period a scenario or a recording's sidecar sets (its `control_period_s`), else the rig's."""
        return float(settings.get("control_period_s") or self.control_period_s)

    def of_kind(self, kind: str) -> list[str]:
        return [c for c, spec in self.channels.items() if spec["kind"] == kind]

    def start_channels(self) -> list[str]:
        """The measured channels whose first samples a run can start from (scenario `initial`, `initial_rate`): a
        generic rig's every one; the laser arm's and Watflex's encoders, the laser arm's tip sensor and the Watflex's
        strain bridges (rigs.py: these two where a run starts moving)."""
        if self.sensors == "generic":
            return self.of_kind("measured")
        return self.position_channels() + (["tip_sensor"] if self.sensors == "laser_arm" else
                                           [c for c in self.channels if c.startswith("strain_")])

    def position_channels(self) -> list[str]:
        """The measured channels that read a joint's position: a generic rig's `position` ones, the built-in rigs'
        encoders (rigs.py)."""
        if self.sensors == "generic":
            return [c for c in self.of_kind("measured") if self.channels[c].get("quantity", "position") == "position"]
        from .rigs import LaserArmRig, WatflexRig

        return list((WatflexRig if self.sensors == "watflex" else LaserArmRig).encoders)

    def parameter_knobs(self) -> dict[str, tuple[str, str]]:
        """name -> (knob, target), for effects.apply_parameters."""
        return {n: (p["knob"], p["target"]) for n, p in self.parameters.items()}

    @property
    def model_path(self) -> Path:
        """The model's MJCF file: `model` relative to the rig file, or models/<model>.xml for a bare name
        (for model = "datasheet": where `watflex-sim build-model` writes it, NAME.xml beside the rig file)."""
        if self.model == DATASHEET:
            return Path(self.source).parent / f"{self.name}.xml"
        if self.model.endswith(".xml") or "/" in self.model or os.sep in self.model:
            return Path(self.source).parent / self.model
        return ROOT / "models" / f"{self.model}.xml"

    @property
    def params(self):
        """The parameter set (params.py) of a bundled generated model (laser_arm, watflex, emps), by the
        model's name; None for a rig whose model is an MJCF file or its [datasheet]."""
        from .params import RIGS

        return RIGS.get(self.model)

    def segmented(self, n_segments: int):
        """`params` with `n_segments` segments per flexible part (0: unchanged); ConfigError if the rig
        has no generated flexible parts or the count is not an integer >= 2."""
        params = self.params
        if not n_segments:
            return params
        if not isinstance(n_segments, int) or n_segments < 2 or not hasattr(params, "n_segments"):
            raise ConfigError(f"n_segments must be an integer >= 2 on a rig with flexible parts, got {n_segments!r}")
        return dataclasses.replace(params, n_segments=n_segments)

    def effort_per_unit(self, channel: str) -> float:
        """N m (N on a slide) per unit of command `channel` at stall: its `gain` (actuator input per
        command unit) times its actuator's own gain in a generic rig's model (a datasheet voltage
        drive's N m/V; 1 for a motor taking N m); the laser arm's and Watflex's `gain` states it whole."""
        gain = float(self.channels[channel].get("gain", 1.0))
        actuator = self.channels[channel].get("actuator")
        if self.sensors != "generic" or actuator is None:
            return gain
        return gain * self._actuator_gains[str(actuator)]

    @cached_property
    def _actuator_gains(self) -> dict[str, float]:
        """actuator -> |gain| (force or torque per input) in the rig's nominal model, compiled once."""
        model = self.spec().compile()
        return {model.actuator(i).name: abs(float(model.actuator_gainprm[i, 0])) for i in range(model.nu)}

    def make_sensors(self, model: mujoco.MjModel, data: mujoco.MjData, scenario: dict, period: float):
        """The rig's sensors and actuators on (model, data) (rigs.py): the generic ones read the
        channels' tables; the laser arm's and Watflex's are their own (1 ms only)."""
        from .rigs import GenericRig, LaserArmRig, WatflexRig

        if self.sensors == "generic":
            return GenericRig(model, data, self, scenario["noise"], scenario["seed"], period)
        if period != CONTROL_PERIOD:
            raise ConfigError(f"rig {self.name!r} runs at {CONTROL_PERIOD * 1e3:g} ms only (its sensors are not generic)")
        if self.sensors == "watflex":
            return WatflexRig(model, data, self.segmented(scenario["n_segments"]), scenario["noise"], scenario["seed"],
                              locked=scenario["locked_joints"])
        return LaserArmRig(model, data, self.segmented(scenario["n_segments"]), scenario["noise"], scenario["seed"])

    def spec(self) -> mujoco.MjSpec:
        """The nominal model: generated from [datasheet] (model = "datasheet"), the MJCF file, or the
        generator's (build.py) for a bundled model not on disk."""
        from .model import kept_spec

        if self.model == DATASHEET:
            from .datasheet import model_xml

            xml = model_xml(self.datasheet, self.name)
            return kept_spec(("datasheet", xml), lambda: mujoco.MjSpec.from_string(xml))
        path = self.model_path
        if path.is_file():
            try:
                stat = path.stat()  # a file edited since is parsed again
                return kept_spec(("file", str(path), stat.st_mtime_ns, stat.st_size),
                                 lambda: mujoco.MjSpec.from_file(str(path)))
            except ValueError as exc:
                raise ConfigError(f"{path}: not a MuJoCo model ({exc})".replace("\n", " ")) from None
        from .build import BUILDERS
        from .params import RIGS

        if self.model in BUILDERS and self.model in RIGS:
            return BUILDERS[self.model](RIGS[self.model])
        raise ConfigError(f"{self.source}: model: no file {path}")


def _check(raw: dict, source: str, default_name: str = "") -> RigDescription:
    from .controllers import CONTROLLERS
    from .effects import CATALOGUE, KNOBS

    def fail(why: str):
        raise ConfigError(f"{source}: {why}")

    if set(raw) - set(KEYS):
        fail(f"unknown key(s) {', '.join(sorted(set(raw) - set(KEYS)))} (known: {', '.join(KEYS)})")
    if "datasheet" in raw:
        from .datasheet import check

        datasheet = check(raw["datasheet"], source)
        raw = {"model": DATASHEET, **raw}
    for key in ("model", "sensors", "channels"):
        if key not in raw:
            fail(f"missing {key!r}")
    if raw["model"] == DATASHEET and "datasheet" not in raw:
        fail('model = "datasheet" needs a [datasheet] table')
    if not isinstance(raw.get("name", default_name), str) or not isinstance(raw["model"], str):
        fail("name and model must be strings")
    if raw["sensors"] not in SENSORS:
        fail(f"sensors must be one of {', '.join(SENSORS)}, got {raw['sensors']!r}")
    if not isinstance(raw["channels"], dict) or not raw["channels"]:
        fail("channels must be a table channel = {unit, kind, ...}")
    for channel, spec in raw["channels"].items():
        _check_channel(channel, spec, fail, raw["sensors"] == "generic")
        if spec["unit"] not in UNITS:
            fail(f"channel {channel!r}: unit {spec['unit']!r} is not one of {', '.join(UNITS)}")
    for channel, spec in {**raw.get("mat_channels", {}), "(mat_time)": raw.get("mat_time", {"file": "", "variable": ""})}.items():
        if channel != "(mat_time)" and channel not in raw["channels"]:
            fail(f"mat_channels: {channel!r} is not a channel of the rig")
        if not isinstance(spec, dict) or set(spec) - MAT_KEYS or not {"file", "variable"} <= set(spec):
            fail(f"mat_channels/mat_time {channel!r} needs file and variable (and may have column, scale)")
    if "mat_channels" in raw and "mat_time" not in raw:
        fail("mat_channels needs mat_time (where the time is)")
    period = raw.get("control_period_s", CONTROL_PERIOD)
    steps = period / CONTROL_PERIOD if isinstance(period, (int, float)) and not isinstance(period, bool) else 0
    if steps < 1 or abs(steps - round(steps)) > 1e-9:
        fail(f"control_period_s must be a whole multiple of {CONTROL_PERIOD:g} s, got {period!r}")
    jitter = raw.get("control_jitter_s", 0.0)
    if isinstance(jitter, bool) or not isinstance(jitter, (int, float)) or not 0 <= jitter < period:
        fail(f"control_jitter_s must be a number of s, >= 0 and below control_period_s ({period:g} s), got {jitter!r}")
    for name, spec in raw.get("parameters", {}).items():
        if not isinstance(spec, dict) or spec.get("knob") not in KNOBS or "target" not in spec \
                or not 0 < spec.get("tolerance", -1) < 1:
            fail(f"parameter {name!r} needs knob (one of {', '.join(KNOBS)}), target and 0 < tolerance < 1")
    for effect, places in raw.get("effects", {}).items():
        if effect not in CATALOGUE or not isinstance(places, list):
            fail(f"effects: {effect!r} is not a catalogue effect with a list of places")
    columns = _columns(raw.get("columns", {}), raw["channels"], fail)
    tables = {"controller": raw.get("controller", {"type": "none"})}
    if isinstance(raw.get("sidecar"), dict) and "controller" in raw["sidecar"]:
        tables["sidecar.controller"] = raw["sidecar"]["controller"]
    for where, table in list(tables.items()):  # a parallel controller's parts checked as tables of their own
        if isinstance(table, dict) and table.get("type") == "parallel" and isinstance(table.get("parts"), list):
            tables |= {f"{where}.parts[{i}]": part for i, part in enumerate(table["parts"])}
    for where, table in tables.items():
        if not isinstance(table, dict) or table.get("type") not in ("none", "open_loop", "parallel", *CONTROLLERS):
            fail(f"{where}: type must be one of none, open_loop, parallel, {', '.join(CONTROLLERS)}, "
                 f"got {table.get('type') if isinstance(table, dict) else table!r}")
        for role in CHANNEL_ROLES:
            value = table.get(role)
            for name in [value] if isinstance(value, str) else value if isinstance(value, list) else []:
                name = name.removeprefix("rate:") if isinstance(name, str) else name  # a channel's rate (state_feedback)
                if raw["sensors"] == "generic" and name != "" and name not in raw["channels"]:  # "": none (pid reference 0)
                    fail(f"{where}.{role}: unknown channel {name!r} (channels: {', '.join(raw['channels'])})")
    description = RigDescription(
        name=raw.get("name", default_name), model=raw["model"], sensors=raw["sensors"], channels=raw["channels"],
        controller=tables["controller"], parameters=raw.get("parameters", {}),
        effects=raw.get("effects", {}), time_variable=raw.get("time_variable", "time"),
        mat_scalars=tuple(raw.get("mat_scalars", ())), sidecar=raw.get("sidecar"),
        description=raw.get("description", ""), source=source, mat_channels=raw.get("mat_channels"),
        mat_time=raw.get("mat_time"), control_period_s=float(period), control_jitter_s=float(jitter),
        datasheet=datasheet if "datasheet" in raw else None, columns=columns,
    )
    if description.model == DATASHEET:
        _command_defaults(description, fail)
    elif any(spec.get("quantity") == "current" for spec in description.channels.values()):
        fail("quantity 'current' reads a datasheet drive: the rig needs a [datasheet]")
    if description.sensors == "generic":
        _check_model(description, fail)
    return description


def _columns(table, channels: dict, fail) -> dict[str, tuple[str, float]]:
    """The [columns] table: a recording file's column name -> (the channel it holds, "time", or "" to
    ignore it; the scale to the channel's unit, or to s for the time). A value is a name or
    {channel, scale}."""
    if not isinstance(table, dict):
        fail("columns must be a table: file column = channel or { channel, scale }")
    out = {}
    for column, spec in table.items():
        spec = {"channel": spec} if isinstance(spec, str) else spec
        if not isinstance(spec, dict) or set(spec) - {"channel", "scale"} or not isinstance(spec.get("channel"), str):
            fail(f"columns.{column!r}: must be a channel name or {{ channel, scale }}")
        if spec["channel"] not in ("time", "", *channels):
            fail(f"columns.{column!r}: {spec['channel']!r} is not a channel of the rig, \"time\" or \"\" (ignored)")
        scale = spec.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or scale == 0 or not math.isfinite(scale):
            fail(f"columns.{column!r}: scale must be a non-zero number, got {scale!r}")
        out[column] = (spec["channel"], float(scale))
    return out


def _command_defaults(description: RigDescription, fail) -> None:
    """A command channel driving a datasheet drive takes its gain (N m/A or 1), limit and bits from
    the drive where it gives none; a gain it gives must be the datasheet's within 0.1 %."""
    from .datasheet import command_defaults

    drives = command_defaults(description.datasheet)
    for channel, spec in description.channels.items():
        if spec.get("quantity") == "current" and spec["kind"] == "measured" and spec["actuator"] not in drives:
            fail(f"channel {channel!r}: actuator {spec['actuator']!r} is not a datasheet drive (drives: {', '.join(drives)})")
        if spec["kind"] != "command" or spec.get("actuator") not in drives:
            continue
        drive = drives[spec["actuator"]]
        if "gain" in spec and abs(spec["gain"] / drive["gain"] - 1) > 1e-3:
            fail(f"channel {channel!r}: gain {spec['gain']} is not the datasheet drive's {drive['gain']:.6g} "
                 "(N m/A: efficiency x torque_constant x gear; 1 for a voltage drive)")
        for key, value in drive.items():
            spec.setdefault(key, value)


def _check_model(description: RigDescription, fail) -> None:
    """The generic sensors' joints and actuators exist in the model; joint angles in rad, slides in m."""
    try:
        model = description.spec().compile()
    except ConfigError:
        raise
    except ValueError as exc:
        fail(f"model {description.model_path}: does not compile ({exc})".replace("\n", " "))
    expected = {int(mujoco.mjtJoint.mjJNT_HINGE): "rad", int(mujoco.mjtJoint.mjJNT_SLIDE): "m"}
    for channel, spec in description.channels.items():
        for key, kind in (("joint", mujoco.mjtObj.mjOBJ_JOINT), ("actuator", mujoco.mjtObj.mjOBJ_ACTUATOR)):
            if key in spec and mujoco.mj_name2id(model, kind, str(spec[key])) < 0:
                fail(f"channel {channel!r}: {key} {spec[key]!r} is not in the model {description.model_path.name}")
        if spec["kind"] == "measured" and "joint" in spec and set(spec) <= {"unit", "kind", "joint", "noise", "step"}:
            unit = expected.get(int(model.jnt_type[model.joint(spec["joint"]).id]))
            if unit and spec["unit"] != unit:
                fail(f"channel {channel!r}: unit {spec['unit']!r} for the position of joint {spec['joint']!r}, "
                     f"which is measured in {unit}")


def _check_channel(channel: str, spec, fail, generic: bool) -> None:
    """One channel table: unit, kind, known keys; a measured generic channel names what it reads."""
    if not isinstance(spec, dict) or "unit" not in spec or spec.get("kind") not in KINDS:
        fail(f"channel {channel!r} needs a unit and a kind among {', '.join(KINDS)}")
    unknown = set(spec) - CHANNEL_KEYS
    if unknown:
        fail(f"channel {channel!r}: unknown key(s) {', '.join(sorted(unknown))}")
    for key in ("scale", "offset", "step", "noise", "filter_hz", "filter_zeta", "length", "x", "thickness", "gain", "limit",
                "range", "bits"):
        if key in spec and (isinstance(spec[key], bool) or not isinstance(spec[key], (int, float))):
            fail(f"channel {channel!r}: {key} must be a number, got {spec[key]!r}")
    for key in ("step", "noise", "filter_hz"):
        if spec.get(key, 0) < 0:
            fail(f"channel {channel!r}: {key} must be >= 0, got {spec[key]!r}")
    for key in ("filter_zeta", "length", "thickness", "limit", "range", "bits"):
        if spec.get(key, 1) <= 0:
            fail(f"channel {channel!r}: {key} must be > 0, got {spec[key]!r}")
    if spec.get("scale", 1) == 0:
        fail(f"channel {channel!r}: scale must not be 0")
    quantity = spec.get("quantity", "position")
    if quantity not in QUANTITIES:
        fail(f"channel {channel!r}: quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    if not generic or spec["kind"] != "measured":
        return
    if quantity == "current":
        if "actuator" not in spec:
            fail(f"channel {channel!r}: quantity 'current' needs the actuator of a datasheet drive")
        return
    if "joint" not in spec and "link" not in spec:
        fail(f"channel {channel!r}: a measured channel needs a joint (position, velocity) or a link "
             "(deflection, strain, acceleration)")
    if quantity in ("deflection", "deflection_angle", "strain", "acceleration") and "link" not in spec:
        fail(f"channel {channel!r}: quantity {quantity!r} needs a link")
    if quantity in ("position", "velocity") and "joint" not in spec:
        fail(f"channel {channel!r}: quantity {quantity!r} needs a joint")
    if quantity == "strain" and not {"thickness", "length"} <= set(spec):
        fail(f"channel {channel!r}: a strain needs the link's thickness and length (m)")
    if quantity in ("deflection", "acceleration") and "length" not in spec:
        fail(f"channel {channel!r}: a tip deflection or an acceleration needs the link's length (m)")


@cache
def _load(path: str, mtime_ns: int) -> RigDescription:
    """A rig file, checked (cached per file version)."""
    p = Path(path)
    default = p.parent.name if p.name == "rig.toml" else p.stem
    return _check(_raw(p), path, default)


def _raw(path: Path, seen: tuple = ()) -> dict:
    """A rig file's table with what it `extends` filled in: a base rig (a name, or a path relative to this file)
    whose keys it takes unless it sets them; [channels], [parameters] and [effects] are merged entry by entry, any
    other key it sets (a file layout, [controller], [sidecar], [datasheet]) replaces the base's whole. The base's
    model file stays its own (made absolute); `name` is never inherited."""
    try:
        raw = read_toml(path, "rig description")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such rig file") from None
    if "extends" not in raw:
        return raw
    base_name = raw.pop("extends")
    if not isinstance(base_name, str) or not base_name:
        raise ConfigError(f"{path}: extends must name a rig or a rig file, got {base_name!r}")
    if _is_path(base_name):
        base_path = (path.parent / Path(base_name).expanduser()).resolve()
        base_path = base_path / "rig.toml" if base_path.is_dir() else base_path
    else:
        try:
            base_path = rig_file(base_name).resolve()
        except ConfigError as err:
            raise ConfigError(f"{path}: extends: {err}") from None
    if base_path in seen or base_path == path.resolve():
        raise ConfigError(f"{path}: extends {base_name!r}, which extends it again (a cycle)")
    base = _raw(base_path, (*seen, path.resolve()))
    base.pop("name", None)
    model = base.get("model")
    if isinstance(model, str) and (model.endswith(".xml") or "/" in model or os.sep in model):
        base["model"] = str((base_path.parent / model).resolve())
    merged = {**base, **raw}
    for key in MERGED:
        if isinstance(base.get(key), dict) and isinstance(raw.get(key), dict):
            merged[key] = {**base[key], **raw[key]}
    return merged


@cache
def _name_of(path: str, mtime_ns: int) -> str:
    """The `name` a rig file declares; the folder (rig.toml) or file stem if it declares none or is
    unreadable (load_rig then says why); "" for a TOML file with neither `model` nor `sensors` (not a rig)."""
    p = Path(path)
    default = p.parent.name if p.name == "rig.toml" else p.stem
    try:
        raw = tomllib.loads(p.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return default
    if "model" not in raw and "sensors" not in raw and "extends" not in raw:
        return ""
    return raw["name"] if isinstance(raw.get("name"), str) else default


def _version(path: Path) -> int:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return 0


def _candidates(entry: Path):
    """Rig files an entry of WATFLEX_RIGS offers: the file itself, or a folder's rig.toml, *.toml, */rig.toml."""
    if entry.is_file():
        yield entry
    elif entry.is_dir():
        if (entry / "rig.toml").is_file():
            yield entry / "rig.toml"
        yield from sorted(p for p in entry.glob("*.toml") if p.name != "rig.toml")
        yield from sorted(entry.glob("*/rig.toml"))


def _search_path() -> list[Path]:
    return [Path(e).expanduser() for e in os.environ.get(ENV, "").split(os.pathsep) if e.strip()]


def rig_file(name: str) -> Path:
    """The file of rig `name` (WATFLEX_RIGS, then the bundled rigs); ConfigError if none."""
    if not name or _is_path(name) or name.startswith("."):
        raise ConfigError(f"a rig name is a plain name (a path goes to --rig), got {name!r}")
    for entry in _search_path():
        quick = [entry / f"{name}.toml", entry / name / "rig.toml"] if entry.is_dir() else []
        for path in chain(quick, _candidates(entry)):  # the folder is listed only if the quick look fails
            if path.is_file() and _name_of(str(path), _version(path)) == name:
                return path
    bundled = RIGS_DIR / f"{name}.toml"
    if bundled.is_file():
        return bundled
    where = f"; {ENV} = {os.environ[ENV]}" if os.environ.get(ENV) else f" (set {ENV} or pass --rig PATH for your own)"
    raise ConfigError(f"unknown rig {name!r} (known: {', '.join(known_rigs())}){where}")


def _is_path(text: str) -> bool:
    return text.endswith(".toml") or "/" in text or os.sep in text


def load_rig(name: str) -> RigDescription:
    """The description of rig `name` (or of the rig file or folder `name` is a path to, if it
    ends in .toml or has a '/'); ConfigError (one line naming the file and key) if unknown or malformed."""
    if not isinstance(name, str):
        raise ConfigError(f"a rig is named by a string, got {name!r}")
    if _is_path(name):
        path = Path(name).expanduser()
        path = path / "rig.toml" if path.is_dir() else path
        if not path.is_file():
            raise ConfigError(f"{name}: no rig file (a rig is a NAME.toml file or a folder with rig.toml)")
    else:
        path = rig_file(name)
    return _load(str(path.resolve()), _version(path))


def use_rig(name_or_path: str) -> RigDescription:
    """Load a rig by name or path (also a bare folder name here, with rig.toml); a path is put first
    in WATFLEX_RIGS so that its name resolves to it here and in worker processes (a sidecar's
    "rig": "myrig" after --rig /path/to/myrig)."""
    by_path = _is_path(name_or_path) or (Path(name_or_path) / "rig.toml").is_file()
    description = load_rig(str(Path(name_or_path).resolve()) if by_path else name_or_path)
    if by_path:
        entries = [e for e in os.environ.get(ENV, "").split(os.pathsep) if e and e != description.source]
        os.environ[ENV] = os.pathsep.join([description.source, *entries])
    return description


def known_rigs() -> list[str]:
    """Names of the rigs found: WATFLEX_RIGS's and the bundled ones."""
    names = {_name_of(str(p), _version(p)) for e in _search_path() for p in _candidates(e)} - {""}
    return sorted(names | {p.stem for p in RIGS_DIR.glob("*.toml")})


class _ChannelUnits(Mapping):
    """rig -> {channel: unit}, resolved when asked (a rig found later, by WATFLEX_RIGS, is in it)."""

    def __getitem__(self, rig: str) -> dict[str, str]:
        return load_rig(rig).units()

    def __contains__(self, rig) -> bool:
        if not isinstance(rig, str):
            return False
        try:
            rig_file(rig)
        except ConfigError:
            return False
        return True

    def __iter__(self):
        return iter(known_rigs())

    def __len__(self) -> int:
        return len(known_rigs())


def channel_units() -> Mapping[str, dict[str, str]]:
    """rig -> {channel: unit} over every description: the recording vocabulary."""
    return _ChannelUnits()
