"""Scenarios: TOML data files in `scenarios/`, any key overridable (`--set key=value`)."""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path

from .model import ROOT, ConfigError, read_toml

SCENARIOS_DIR = ROOT / "scenarios"

# Every top-level key a scenario may have, with its default (None: required).
DEFAULTS = {
    "rig": None,  # laser_arm | watflex
    "experiment": None,  # a name, informative
    "duration_s": None,  # s, recorded length
    "controller": None,  # table: type = pd_tip | pd_joint | none, and its parameters
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
    "initial": {},  # channel -> first recorded value: the run starts in that state (generic rigs)
    "notes": "",
}


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
    return check(scenario)


def check(scenario: dict) -> dict:
    """Validate types and required keys; normalise reference/command to lists of tables."""
    missing = [k for k, v in DEFAULTS.items() if v is None and scenario.get(k) is None]
    if missing:
        raise ConfigError(f"scenario is missing {', '.join(missing)}")
    for key in ("duration_s", "payload_kg", "tilt_rad", "tilt_azimuth_rad", "timestep", "frame_rate_hz", "control_period_s"):
        value = scenario[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"scenario parameter {key!r} must be a number, got {value!r}")
    if scenario["duration_s"] <= 0:
        raise ConfigError(f"duration_s must be > 0 s, got {scenario['duration_s']}")
    if scenario["direction"] not in ("positive", "negative"):
        raise ConfigError(f"direction must be 'positive' or 'negative', got {scenario['direction']!r}")
    if not isinstance(scenario["seed"], int) or isinstance(scenario["seed"], bool):
        raise ConfigError(f"seed must be an integer, got {scenario['seed']!r}")
    if not isinstance(scenario["noise"], bool):
        raise ConfigError(f"noise must be true or false, got {scenario['noise']!r}")
    if not isinstance(scenario["controller"], dict) or "type" not in scenario["controller"]:
        raise ConfigError("scenario needs a [controller] table with a 'type'")
    if scenario["friction"] not in ("nominal", "none"):
        raise ConfigError(f"friction must be 'nominal' or 'none', got {scenario['friction']!r}")
    if not isinstance(scenario["joint_friction"], dict):
        raise ConfigError("joint_friction must be a table joint = {field = value}")
    if not isinstance(scenario["effects"], list) or not all(isinstance(e, dict) for e in scenario["effects"]):
        raise ConfigError("effects must be a list of tables {effect = ..., where = ..., <parameters>}")
    if not isinstance(scenario["parameters"], dict):
        raise ConfigError("parameters must be a table name = ratio")
    if scenario["control_period_s"] < 0:
        raise ConfigError(f"control_period_s must be >= 0 s (0: the rig's), got {scenario['control_period_s']}")
    if not isinstance(scenario["initial"], dict):
        raise ConfigError("initial must be a table channel = value")
    if not isinstance(scenario["locked_joints"], dict):
        raise ConfigError("locked_joints must be a table joint = angle (rad)")
    for key in ("reference", "command"):
        tables = scenario[key]
        tables = [tables] if isinstance(tables, dict) else tables
        if not isinstance(tables, list) or not all(isinstance(t, dict) and "channel" in t for t in tables):
            raise ConfigError(f"{key} must be a table (or list of tables) each with a 'channel'")
        scenario[key] = tables
    return scenario
