"""What moves in the recordings, and the sizes catalogue parameters are measured in.

Contract: `motion_channel(rec, rig)` names the joint position that moves most in a recording (a reference where the
moving joint's encoder is not recorded); `motions(data)` gives each recording's (name, positions), simulated on the
nominal model where only a reference says it; `peak_speed` its peak rate; `scale_of(data, param, where)` the size a
scaled catalogue parameter is measured in (peak effort, effort per speed, a command's peak, a channel's spread, the
motion's range), the effort simulated on the nominal model where no command is recorded (`simulated_effort`); `peak`
a robust peak of any signal.
"""
from __future__ import annotations

import numpy as np

from ..effects import CATALOGUE
from ..engine import SimulationError, simulate
from ..model import ConfigError
from ..recording import Recording
from ..resim import scenario_from_recording
from ..rigdesc import RigDescription
from .data import Data

def peak(x: np.ndarray) -> float:
    """Robust peak |x| (99.5th percentile, NaN ignored): what a signal reaches, not its outliers."""
    x = np.abs(x[np.isfinite(x)])
    return float(np.percentile(x, 99.5)) if x.size else 0.0


def motion_channel(rec: Recording, rig: RigDescription) -> str | None:
    """The joint position (rad or m) that moves most in the recording: what 'motion' means. A measured one,
    unless none moves a tenth as far as a reference does (a locked joint's encoder, the moving joint's left
    out: a rig seen through its strains only); then the reference."""
    measured, reference = _position_spreads(rec, rig, "measured"), _position_spreads(rec, rig, "reference")
    if reference and max(reference.values()) > 10 * max(measured.values(), default=0.0):
        return max(reference, key=reference.get)
    return max(measured, key=measured.get, default=None)


def _position_spreads(rec: Recording, rig: RigDescription, kind: str) -> dict[str, float]:
    """The spread (std, rad or m) of each joint position of `kind` ("measured", "reference") the recording has."""
    return {c: float(np.nanstd(rec.channels[c])) for c in rig.of_kind(kind) if c in rec.channels
            and rig.channels[c]["unit"] in ("rad", "m") and not c.startswith("tip_") and np.isfinite(rec.channels[c]).any()}


def scale_of(data: Data, param, where: str) -> float:
    """The size a scaled catalogue parameter is measured in (effects.Param.scale), from the data:
    "effort" the peak actuator force or torque (recorded, else `simulated_effort`), "effort/speed" that over the
    peak speed,
    "command" the peak of command channel `where`, "channel" the spread of channel `where`,
    "motion" the range of the motion channel."""
    if not param.scale:
        return 1.0
    efforts, values, ranges = [], [], []
    for rec in data.recordings:
        for c in data.rig.of_kind("command"):
            if c in rec.channels:
                efforts.append(peak(rec.channels[c]) * data.rig.effort_per_unit(c))
        motion = motion_channel(rec, data.rig)
        if motion:
            ranges.append(float(np.nanmax(rec.channels[motion]) - np.nanmin(rec.channels[motion])))
        if where in rec.channels:
            values.append(peak(rec.channels[where]) if param.scale == "command" else float(np.nanstd(rec.channels[where])))
    effort = max(efforts, default=0.0) or simulated_effort(data)
    if param.scale == "motion":
        return max(ranges, default=1.0) or 1.0
    if param.scale == "effort":
        return effort
    if param.scale == "effort/speed":
        return effort / (peak_speed(data) or 1.0)
    return max(values, default=1.0) or 1.0


def neutral_values(data: Data, effect: dict) -> dict[str, float]:
    """The values at which the effect's parameters that have one vanish (effects.Param.neutral: a friction side's 0,
    a ratio's 1), in the data's units (`scale_of`; a neutral 0 is 0 in any)."""
    return {p.name: p.neutral and p.neutral * scale_of(data, p, effect["where"])
            for p in CATALOGUE[effect["effect"]][1] if p.neutral is not None}


def simulated_effort(data: Data) -> float:
    """The peak actuator force or torque (N, N m) the nominal model commands in the recordings' experiments, where
    no command is recorded (a lab that logged its arm's angles only); 1 where none can be simulated. A friction's
    bounds scale with it: a fixed 1 N m held a Quanser drive's 100:1 harmonic drive (5 N m at 0.6 A) to a break-away
    of at most 1 N m, which the fits of the lab's runs then sat on. Simulated once per Data, the first time asked."""
    if data.effort_memo is None:
        efforts = []
        for rec in data.recordings:
            try:
                sim = simulate(scenario_from_recording(rec, data.rig), rig=data.rig).recording
            except (ConfigError, SimulationError):
                continue
            efforts += [peak(sim.channels[c]) * data.rig.effort_per_unit(c) for c in data.rig.of_kind("command")
                        if c in sim.channels]
        data.effort_memo = max(efforts, default=0.0) or 1.0
    return data.effort_memo


def motions(data: Data) -> list[tuple[str, np.ndarray] | None]:
    """Per recording, what moves (motion_channel) as (its name, its positions at the recording's samples; rad or m),
    None where nothing does. Where that is a reference (the moving joint's encoder not recorded), the joint as the
    nominal model moves it ("simulated elbow_angle"): a stepped reference's own rate says nothing of the joint's, 0 at
    its 99.5th percentile and 1/dt at its top (seed 73's watflex-349124fc, elbow angle not recorded: an elbow viscous
    friction's bounds came out at +-1e15 N m s/rad and it never screened; every window read "at rest"). Simulated once
    per Data, the first time it is asked."""
    if data.motion_memo is None:
        data.motion_memo = []
        for rec in data.recordings:
            name = motion_channel(rec, data.rig)
            simulated = _simulated_motion(rec, data.rig) if name and data.rig.channels[name]["kind"] == "reference" else None
            data.motion_memo.append(simulated or ((name, rec.channels[name]) if name else None))
    return data.motion_memo


def peak_speed(data: Data) -> float:
    """The motion's peak speed over the recordings (rad/s or m/s; 0 if nothing moves): the robust peak rate of each
    recording's `motions`."""
    return max((peak(np.gradient(m[1], rec.time)) for rec, m in zip(data.recordings, motions(data)) if m), default=0.0)


def _simulated_motion(rec: Recording, rig: RigDescription) -> tuple[str, np.ndarray] | None:
    """The joint position that moves most (motion_channel's measured kind) when `rec`'s experiment is simulated on
    the nominal model with every channel, sampled at rec's times; None where the recording cannot be simulated."""
    try:
        sim = simulate(scenario_from_recording(rec, rig), rig=rig).recording
    except (ConfigError, SimulationError):
        return None
    spread = _position_spreads(sim, rig, "measured")
    if not spread:
        return None
    name = max(spread, key=spread.get)
    return f"simulated {name}", np.interp(rec.time - rec.time[0], sim.time, sim.channels[name])
