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

RIGS_DIR = ROOT / "rigs"
KINDS = ("reference", "measured", "command", "disturbance")
SENSORS = ("laser_arm", "watflex", "generic")


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
        if not isinstance(spec, dict) or "unit" not in spec or spec.get("kind") not in KINDS:
            fail(f"channel {channel!r} needs a unit and a kind among {', '.join(KINDS)}")
    for name, spec in raw.get("parameters", {}).items():
        if spec.get("knob") not in KNOBS or "target" not in spec or not 0 < spec.get("tolerance", -1) < 1:
            fail(f"parameter {name!r} needs knob (one of {', '.join(KNOBS)}), target and 0 < tolerance < 1")
    for effect, places in raw.get("effects", {}).items():
        if effect not in CATALOGUE or not isinstance(places, list):
            fail(f"effects: {effect!r} is not a catalogue effect with a list of places")
    known = {"name", "model", "sensors", "channels", "controller", "parameters", "effects", "time_variable",
             "mat_scalars", "sidecar", "description"}
    if set(raw) - known:
        fail(f"unknown key(s) {', '.join(sorted(set(raw) - known))}")
    return RigDescription(
        name=raw["name"], model=raw["model"], sensors=raw["sensors"], channels=raw["channels"],
        controller=raw.get("controller", {"type": "none"}), parameters=raw.get("parameters", {}),
        effects=raw.get("effects", {}), time_variable=raw.get("time_variable", "time"),
        mat_scalars=tuple(raw.get("mat_scalars", ())), sidecar=raw.get("sidecar"),
        description=raw.get("description", ""),
    )


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
