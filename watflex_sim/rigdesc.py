"""Rig descriptions (`rigs/<rig>.toml`): a rig as data, for simulation and diagnosis.

A description names the model, the sensor implementation, the channels (unit, kind, noise),
the default controller, the parameters that may be refit within a tolerance (knobs of
effects.py) and where each catalogue effect may attach. Adding a rig whose sensors are in
the library (`generic`: encoders, commands, references, disturbances) needs no code.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from .model import ROOT, ConfigError, read_toml
from .params import CONTROL_PERIOD

RIGS_DIR = ROOT / "rigs"
KINDS = ("reference", "measured", "command", "disturbance")
SENSORS = ("laser_arm", "watflex", "generic")
# What a generic measured channel reads (rigs.GenericRig): a joint's position (rad or m) or
# velocity, a link's tip deflection (m) or its angle (rad), or the strain at x on a link.
QUANTITIES = ("position", "velocity", "deflection", "deflection_angle", "strain")
# Keys a channel may have (rigs.GenericRig reads them; the other sensor models read unit, kind, noise).
CHANNEL_KEYS = {"unit", "kind", "joint", "link", "quantity", "scale", "offset", "step", "noise", "filter_hz",
                "filter_zeta", "length", "x", "thickness", "actuator", "gain", "limit", "bits", "range"}
MAT_KEYS = {"file", "variable", "column", "scale"}


@dataclass(frozen=True)
class RigDescription:
    name: str
    model: str  # models/<model>.xml
    sensors: str  # laser_arm | watflex | generic
    channels: dict  # channel -> {unit, kind, noise?, joint?, actuator?, gain?, limit?, step?}
    controller: dict  # default controller table
    parameters: dict  # name -> {knob, target, tolerance}
    effects: dict  # effect id -> [where, ...]
    time_variable: str = "time"  # .mat variable with the time in s
    mat_channels: dict | None = None  # channel -> {file, variable, column?, scale?}: one .mat file per signal
    mat_time: dict | None = None  # {file, variable, column?, scale?}: where the time is (scale to s)
    control_period_s: float = CONTROL_PERIOD  # s, the rig's sample period (controller and sensors)
    mat_scalars: tuple = ()  # 1x1 .mat variables kept for the sidecar ("mat:NAME")
    sidecar: dict | None = None  # default sidecar for files that come without one (--rig)
    description: str = ""

    def units(self) -> dict[str, str]:
        return {c: spec["unit"] for c, spec in self.channels.items()}

    def of_kind(self, kind: str) -> list[str]:
        return [c for c, spec in self.channels.items() if spec["kind"] == kind]

    def parameter_knobs(self) -> dict[str, tuple[str, str]]:
        """name -> (knob, target), for effects.apply_parameters."""
        return {n: (p["knob"], p["target"]) for n, p in self.parameters.items()}


def _check(raw: dict, source: str) -> RigDescription:
    from .effects import CATALOGUE, KNOBS

    def fail(why: str):
        raise ConfigError(f"{source}: {why}")

    for key in ("name", "model", "sensors", "channels"):
        if key not in raw:
            fail(f"missing {key!r}")
    if raw["sensors"] not in SENSORS:
        fail(f"sensors must be one of {', '.join(SENSORS)}, got {raw['sensors']!r}")
    for channel, spec in raw["channels"].items():
        _check_channel(channel, spec, fail, raw["sensors"] == "generic")
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
    for name, spec in raw.get("parameters", {}).items():
        if spec.get("knob") not in KNOBS or "target" not in spec or not 0 < spec.get("tolerance", -1) < 1:
            fail(f"parameter {name!r} needs knob (one of {', '.join(KNOBS)}), target and 0 < tolerance < 1")
    for effect, places in raw.get("effects", {}).items():
        if effect not in CATALOGUE or not isinstance(places, list):
            fail(f"effects: {effect!r} is not a catalogue effect with a list of places")
    known = {"name", "model", "sensors", "channels", "controller", "parameters", "effects", "time_variable",
             "mat_scalars", "sidecar", "description", "mat_channels", "mat_time", "control_period_s",
             "datasheet"}  # datasheet: free numbers a model generator reads (tools/build_quanser.py)
    if set(raw) - known:
        fail(f"unknown key(s) {', '.join(sorted(set(raw) - known))}")
    return RigDescription(
        name=raw["name"], model=raw["model"], sensors=raw["sensors"], channels=raw["channels"],
        controller=raw.get("controller", {"type": "none"}), parameters=raw.get("parameters", {}),
        effects=raw.get("effects", {}), time_variable=raw.get("time_variable", "time"),
        mat_scalars=tuple(raw.get("mat_scalars", ())), sidecar=raw.get("sidecar"),
        description=raw.get("description", ""), mat_channels=raw.get("mat_channels"), mat_time=raw.get("mat_time"),
        control_period_s=float(period),
    )


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
    if "joint" not in spec and "link" not in spec:
        fail(f"channel {channel!r}: a measured channel needs a joint (position, velocity) or a link (deflection, strain)")
    if quantity in ("deflection", "deflection_angle", "strain") and "link" not in spec:
        fail(f"channel {channel!r}: quantity {quantity!r} needs a link")
    if quantity in ("position", "velocity") and "joint" not in spec:
        fail(f"channel {channel!r}: quantity {quantity!r} needs a joint")
    if quantity == "strain" and not {"thickness", "length"} <= set(spec):
        fail(f"channel {channel!r}: a strain needs the link's thickness and length (m)")
    if quantity == "deflection" and "length" not in spec:
        fail(f"channel {channel!r}: a tip deflection needs the link's length (m)")


@cache
def load_rig(name: str) -> RigDescription:
    """The description of rig `name` (rigs/<name>.toml); ConfigError if missing or malformed."""
    path = RIGS_DIR / f"{name}.toml"
    if not path.exists():
        raise ConfigError(f"unknown rig {name!r} (known: {', '.join(known_rigs())})")
    return _check(read_toml(path, "rig description"), str(path))


def known_rigs() -> list[str]:
    return sorted(p.stem for p in RIGS_DIR.glob("*.toml"))


def channel_units() -> dict[str, dict[str, str]]:
    """rig -> {channel: unit} over every description: the recording vocabulary."""
    return {name: load_rig(name).units() for name in known_rigs()}
