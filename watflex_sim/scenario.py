"""Scenarios: TOML data files in `scenarios/`, any key overridable (`--set key=value`)."""
from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

from .model import ROOT, ConfigError, read_toml
from .params import CONTROL_PERIOD

SCENARIOS_DIR = ROOT / "scenarios"

# Every top-level key a scenario may have, with its default (None: required).
DEFAULTS = {
    "rig": None,  # laser_arm | watflex
    "experiment": None,  # a name, informative
    "duration_s": None,  # s, recorded length
    "controller": None,  # table: type (a registered law, or none) and its parameters; absent: the rig's [controller]
    "reference": [],  # table(s): channel, kind (step|staircase|triangle|constant), parameters
    "command": [],  # table(s) for open loop: channel, kind, parameters
    "direction": "positive",  # positive | negative: sign of references and open-loop commands
    "payload_kg": 0.0,  # kg extra tip mass
    "locked_joints": {},  # joint -> angle (rad)
    "actuator_bench": "",  # a joint tested alone, its flexible chain removed (thesis 4.5)
    "tilt_rad": 0.0,  # rad, table tilt (watflex)
    "tilt_azimuth_rad": 0.0,  # rad, downhill direction from +x
    "timestep": 0.0,  # s physics step; 0 = the model's own
    "n_segments": 0,  # segments per flexible part; 0 = the committed model's
    "friction": "nominal",  # nominal (rigs.md joint friction) | none
    "joint_friction": {},  # joint -> JointFriction fields overriding/adding (joint_friction.py)
    "noise": True,  # measurement noise of rigs.md §3
    "seed": 0,  # seed of every random draw
    "frame_rate_hz": 50.0,  # Hz, arm drawings sent to rerun
    "effects": [],  # catalogue effects added to the nominal model (effects.py, recordings.md)
    "parameters": {},  # refit parameters: name -> ratio to nominal (effects.py knobs)
    "control_period_s": 0.0,  # s, sample period of sensors and controller; 0 = the rig's (rigs/<rig>.toml)
    "initial": {},  # channel -> value: the run starts in that state (the laser arm's and Watflex's encoders, rad)
    "initial_rate": {},  # channel -> its rate of change (unit/s): the run starts moving (rigs.Rig.start_at)
    "initial_acceleration": {},  # channel -> unit/s^2: with initial_rate, the past the controller is warmed up on
    "controller_state": {},  # name -> value: the controller's state at the start (its `state()` names and units)
    "notes": "",
}


MAX_DURATION_S = 1000.0  # s: a 1 ms loop records 1000 samples per second per channel (~8 MB/min of memory)

# Physical ranges of the numeric top-level keys: key -> (low, high, unit, low included).
RANGES = {
    "duration_s": (0.0, MAX_DURATION_S, "s", False),
    "payload_kg": (0.0, 5.0, "kg", True),  # rigs.md experiments: 0-1.6 kg at the tip
    "tilt_rad": (-0.5, 0.5, "rad", True),  # table tilt, about +-29 degrees
    "tilt_azimuth_rad": (-2 * math.pi, 2 * math.pi, "rad", True),
    "timestep": (0.0, CONTROL_PERIOD, "s", True),  # 0: the model's own
    "frame_rate_hz": (0.0, 1 / CONTROL_PERIOD, "Hz", False),
}
MIN_TIMESTEP = 1e-6  # s: below this a 1 ms period takes over 1000 physics steps
MAX_SEGMENTS = 100  # segments per flexible part
GAIN_KEYS = ("kp", "kd", "kv", "ki", "k")  # controller gains (and k_*): >= 0


def _number_in(key: str, value, low: float, high: float, unit: str, low_included: bool = True) -> None:
    """ConfigError (one line, with the range and unit) unless `value` is a finite number in range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{key} must be a number in {unit}, got {value!r}")
    left = "[" if low_included else "("
    if not math.isfinite(value) or value < low or (value == low and not low_included) or value > high:
        raise ConfigError(f"{key} must be a finite number in {left}{low:g}, {high:g}] {unit}, got {value!r}")


def _finite(value, where: str) -> None:
    """ConfigError naming the dotted key of the first NaN or infinite number at any depth."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{where} must be a finite number, got {value!r}")
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        _finite(v, f"{where}.{k}" if where else str(k))


def _non_negative_gains(table: dict, where: str) -> None:
    """Controller gains (kp, kd, kv, ki, k, k_*; numbers or lists) must be >= 0."""
    for key, value in table.items():
        if isinstance(value, dict):
            _non_negative_gains(value, f"{where}.{key}")
        elif key in GAIN_KEYS or key.startswith("k_"):
            for v in value if isinstance(value, list) else [value]:
                if isinstance(v, (int, float)) and not isinstance(v, bool) and v < 0:
                    raise ConfigError(f"{where}.{key} is a gain: it must be >= 0, got {v!r}")


def available() -> list[str]:
    """Names of the scenarios shipped in `scenarios/`."""
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))


def parse_value(text: str):
    """A --set value: a TOML literal (number, bool, list, quoted string) or else a plain string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_value(scenario: dict, key: str, value) -> None:
    """Set a (dotted) key: 'payload_kg', 'controller.kp'. ConfigError for an unknown top-level key."""
    path = key.strip().split(".")
    if path[0] not in DEFAULTS:
        raise ConfigError(f"unknown scenario parameter {path[0]!r} (known: {', '.join(DEFAULTS)})")
    node = scenario
    for part in path[:-1]:
        if isinstance(node.get(part), list) and len(node[part]) == 1:
            node[part] = node[part][0]  # a single reference/command table
        if not isinstance(node.setdefault(part, {}), dict):
            raise ConfigError(f"cannot set {key}: {part!r} is not a table")
        node = node[part]
    node[path[-1]] = value


def apply_override(scenario: dict, assignment: str) -> None:
    """Apply one command-line 'key=value' (dotted keys reach into tables: controller.kp=0.2)."""
    key, sep, text = assignment.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"--set expects key=value, got {assignment!r}")
    set_value(scenario, key, parse_value(text))


def load_scenario(name_or_path: str, overrides: list[str] = ()) -> dict:
    """Read a scenario by name (scenarios/NAME.toml) or path, apply overrides, fill defaults.

    Raises ConfigError (one line) for a missing file, bad TOML, unknown or missing keys, or
    wrongly typed values.
    """
    path = Path(name_or_path)
    if not path.suffix:
        path = SCENARIOS_DIR / f"{name_or_path}.toml"
    try:
        raw = read_toml(path, "scenario")
    except FileNotFoundError:
        raise ConfigError(f"no scenario {name_or_path!r} (known: {', '.join(available())})") from None
    unknown = set(raw) - set(DEFAULTS)
    if unknown:
        raise ConfigError(f"{path}: unknown scenario parameter(s) {', '.join(sorted(unknown))}")
    scenario = copy.deepcopy(DEFAULTS) | raw
    scenario["name"] = path.stem
    for assignment in overrides:
        apply_override(scenario, assignment)
    if scenario.get("controller") is None and isinstance(scenario.get("rig"), str):  # the rig's own law
        from .rigdesc import load_rig

        scenario["controller"] = copy.deepcopy(load_rig(scenario["rig"]).controller)
    return check(scenario)


def check(scenario: dict) -> dict:
    """Validate types, finiteness and physical ranges (RANGES, gains >= 0) and required keys;
    normalise reference/command to lists of tables. ConfigError (one line, range and unit)."""
    missing = [k for k, v in DEFAULTS.items() if v is None and scenario.get(k) is None]
    if missing:
        raise ConfigError(f"scenario is missing {', '.join(missing)}")
    for key, (low, high, unit, included) in RANGES.items():
        _number_in(key, scenario[key], low, high, unit, included)
    if 0 < scenario["timestep"] < MIN_TIMESTEP:
        raise ConfigError(f"timestep must be 0 (the model's own) or in [{MIN_TIMESTEP:g}, {CONTROL_PERIOD:g}] s, "
                          f"got {scenario['timestep']!r}")
    if scenario["timestep"]:
        n = round(CONTROL_PERIOD / scenario["timestep"])
        if abs(n * scenario["timestep"] - CONTROL_PERIOD) > 1e-9 * CONTROL_PERIOD:
            raise ConfigError(f"timestep {scenario['timestep']!r} s: the {CONTROL_PERIOD * 1e3:g} ms control period is "
                              "not a whole multiple of it (use 0 for the model's own, or 1 ms / N: 1e-4, 5e-4 s)")
    n_seg = scenario["n_segments"]
    if isinstance(n_seg, bool) or not isinstance(n_seg, int) or not (n_seg == 0 or 2 <= n_seg <= MAX_SEGMENTS):
        raise ConfigError(f"n_segments must be 0 (the model's own) or an integer in [2, {MAX_SEGMENTS}], got {n_seg!r}")
    seed = scenario["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise ConfigError(f"seed must be an integer in [0, 2^63), got {seed!r}")
    _finite({k: v for k, v in scenario.items() if k not in ("notes", "reference", "command")}, "")
    for key in ("reference", "command"):  # their scalars; replayed samples may hold NaN (missing)
        for i, table in enumerate(scenario[key] if isinstance(scenario[key], list) else [scenario[key]]):
            if isinstance(table, dict):
                _finite({k: v for k, v in table.items() if not isinstance(v, list)}, f"{key}.{i}")
    if scenario["direction"] not in ("positive", "negative"):
        raise ConfigError(f"direction must be 'positive' or 'negative', got {scenario['direction']!r}")
    if not isinstance(scenario["noise"], bool):
        raise ConfigError(f"noise must be true or false, got {scenario['noise']!r}")
    if not isinstance(scenario["controller"], dict) or "type" not in scenario["controller"]:
        raise ConfigError("scenario needs a [controller] table with a 'type'")
    _non_negative_gains(scenario["controller"], "controller")
    if scenario["friction"] not in ("nominal", "none"):
        raise ConfigError(f"friction must be 'nominal' or 'none', got {scenario['friction']!r}")
    if not isinstance(scenario["joint_friction"], dict):
        raise ConfigError("joint_friction must be a table joint = {field = value}")
    if not isinstance(scenario["effects"], list) or not all(isinstance(e, dict) for e in scenario["effects"]):
        raise ConfigError("effects must be a list of tables {effect = ..., where = ..., <parameters>}")
    if not isinstance(scenario["parameters"], dict):
        raise ConfigError("parameters must be a table name = ratio")
    for name, ratio in scenario["parameters"].items():
        _number_in(f"parameters.{name}", ratio, 0.0, 1e3, "(ratio to nominal)", False)
    period = scenario["control_period_s"]
    if isinstance(period, bool) or not isinstance(period, (int, float)) or not (0 <= period <= 1.0):
        raise ConfigError(f"control_period_s must be 0 (the rig's) or a number of seconds in (0, 1], got {period!r}")
    for key, what in (("initial", "value"), ("initial_rate", "rate (unit/s)"),
                      ("initial_acceleration", "acceleration (unit/s^2)"), ("controller_state", "value")):
        if not isinstance(scenario[key], dict):
            raise ConfigError(f"{key} must be a table channel = {what}")
        for channel, value in scenario[key].items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{key}.{channel} must be a finite number ({what}), got {value!r}")
    if not isinstance(scenario["locked_joints"], dict):
        raise ConfigError("locked_joints must be a table joint = angle (rad)")
    for key in ("reference", "command"):
        tables = scenario[key]
        tables = [tables] if isinstance(tables, dict) else tables
        if not isinstance(tables, list) or not all(isinstance(t, dict) and "channel" in t for t in tables):
            raise ConfigError(f"{key} must be a table (or list of tables) each with a 'channel'")
        scenario[key] = tables
    return scenario
