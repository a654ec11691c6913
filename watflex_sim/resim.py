"""Re-simulate a recording: the same experiment on a (possibly patched) model, noise off."""
from __future__ import annotations

import copy

import numpy as np

from .engine import simulate
from .model import ConfigError
from .recording import Recording
from .rigdesc import load_rig
from .scenario import DEFAULTS, check


def scenario_from_recording(rec: Recording) -> dict:
    """A scenario that repeats `rec`'s experiment: its references and disturbances replayed as
    recorded; closed loop re-runs the sidecar's controller, open loop replays the commands.

    Raises ConfigError when the recording cannot drive a simulation (no controller, no command).
    """
    meta, description = rec.meta, load_rig(rec.rig)
    scenario = copy.deepcopy(DEFAULTS)
    time = rec.time - rec.time[0]
    period = float(meta.get("control_period_s") or description.control_period_s)  # s: the sidecar's, else the rig's
    scenario.update(
        rig=rec.rig, experiment=meta.get("experiment", "recording"), name=meta.get("experiment", "recording"),
        duration_s=float(round(time[-1] / period) + 1) * period,
        payload_kg=float(meta.get("payload_kg", 0.0)), locked_joints=dict(meta.get("locked_joints", {})),
        noise=False, seed=0, control_period_s=period,
    )
    for key in ("tilt_rad", "actuator_bench", "friction", "joint_friction", "timestep"):
        if key in meta.get("scenario", {}):  # our own recordings say how they were made
            scenario[key] = meta["scenario"][key]
    if description.sensors == "generic":  # start where the recording starts (its first finite samples)
        scenario["initial"] = {c: _first(rec.channels[c]) for c in description.of_kind("measured") if c in rec.channels}
    inputs = [c for c in description.of_kind("reference") + description.of_kind("disturbance") if c in rec.channels]
    scenario["reference"] = [_samples(c, time, rec.channels[c]) for c in inputs]
    mode = meta.get("mode", "closed_loop")
    controller = dict(meta.get("controller") or description.controller)
    if mode == "open_loop" or controller.get("type") in ("none", "open_loop"):
        commands = [c for c in description.of_kind("command") if c in rec.channels]
        if not commands:
            raise ConfigError(f"open-loop recording has no command channel ({', '.join(description.of_kind('command'))})")
        scenario["controller"] = {"type": "none"}
        scenario["command"] = [_samples(c, time, rec.channels[c]) for c in commands]
    else:
        scenario["controller"] = controller
    return check(scenario)


def _first(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite[0]) if finite.size else float("nan")


def _samples(channel: str, time: np.ndarray, values: np.ndarray) -> dict:
    return {"channel": channel, "kind": "samples", "time_s": time.tolist(), "values": values.tolist()}


def resimulate(rec: Recording, effects: list[dict] = (), parameters: dict | None = None,
               until: float | None = None, noise_seed: int | None = None) -> Recording:
    """Simulate `rec`'s experiment with `effects` and refit `parameters`; channels sampled at rec.time.

    With `until` (s from the start) the simulation stops there; later samples hold its last value.
    With `noise_seed` the rig's measurement noise is on (fed back through the controller as on the rig)."""
    scenario = scenario_from_recording(rec)
    if noise_seed is not None:
        scenario.update(noise=True, seed=int(noise_seed))
    if until is not None:
        scenario["duration_s"] = min(scenario["duration_s"], until + 2 * scenario["control_period_s"])
    scenario["effects"] = list(effects)
    scenario["parameters"] = dict(parameters or {})
    sim = simulate(scenario, parameter_names=load_rig(rec.rig).parameter_knobs()).recording
    t = rec.time - rec.time[0]
    channels = {c: np.interp(t, sim.time, v) for c, v in sim.channels.items() if c in rec.channels}
    return Recording(rec.time.copy(), channels, sim.meta)
