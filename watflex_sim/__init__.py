"""watflex_sim: MuJoCo simulator of flexible-link planar arms (Watflex, laser arm).

Public API:
    load_scenario(name, overrides) -> dict     scenario file + `key=value` overrides
    simulate(scenario) -> SimResult            run it: .recording (time, channels, meta), .frames
    run_scenario(name, **overrides) -> Recording   the two above in one call
    read_recording(path) / write_recording(rec, dir, name)
    load_model(rig, payload_kg=..., locked_joints=..., tilt_rad=...) -> mujoco.MjModel
"""
__version__ = "0.1.0"

from .engine import SimResult, SimulationError, simulate  # noqa: E402
from .model import ConfigError, load_model  # noqa: E402
from .recording import Recording, RecordingError, read_recording, write_recording  # noqa: E402
from .scenario import check, load_scenario, set_value  # noqa: E402


def run_scenario(name: str, **overrides) -> Recording:
    """Simulate scenario `name` (or a path) with overrides as keyword arguments, '__' for dots.

    Example: run_scenario("laser_arm_step", payload_kg=0.7, controller__kp=0.2).
    """
    scenario = load_scenario(name)
    for key, value in overrides.items():
        set_value(scenario, key.replace("__", "."), value)
    return simulate(check(scenario)).recording


__all__ = [
    "ConfigError", "Recording", "RecordingError", "SimResult", "SimulationError",
    "load_model", "load_scenario", "read_recording", "run_scenario", "simulate", "write_recording",
]
