"""Generate a public benchmark of concealed effects for `watflex-sim diagnose`.

Usage: python tools/make_benchmark.py --out DIR [--seed 0] [--rigs laser_arm,watflex]
           [--per-effect 1] [--clean 3] [--hard 2] [--pairs 2] [--effects a,b] [--duration 6] [--segments 30 --step-divisor 2]
           [--range stribeck_friction.v_s=0.1:0.3]

A case is what a user would bring: three simulated recordings (noise on, a seed each) of one
rig with one catalogue effect added, listed in a shuffled order (the diagnosis must not depend on it):
  laser_arm: 2.5 mm tip step positive, negative (0.7 kg), then a step at another paper payload;
  watflex (shoulder locked): elbow step +0.5 rad, -0.5 rad, then the 0.1 rad staircase;
  watflex with `--watflex-setup two_joint`: both links flexible, both joints moving: three steps of
    the observer control of thesis 5.2.5 (shoulder +-0.3-0.5 rad, elbow +-0.6-1.0 rad, signs drawn).
Each effect gets a place (`where`) the rig description allows, at random (Watflex single-link: the
places the elbow experiments excite: elbow-side ones, link 1 and its strain bridges 1A-1C, which the
swinging elbow shakes; two-joint: every place), and a magnitude from RANGES: visible above the rig
noise but modest.
One concealment per case (CONCEALMENTS). `--clean` cases per rig have no effect, only the
rig's parameters perturbed within their tolerances. `--hard` cases per rig and kind (issue 14):
  clean_rest: clean, but the last experiment is one in which nothing moves (an uninformative file);
  out_of_tolerance: a rig parameter far outside its tolerance (the link's EI x0.25-0.4 or x2.5-4, or
    a monitored sensor wired with the wrong sign): the right answer is the catalogue's closest effect
    (link_stiffness_change, sensor_gain with a negative ratio);
  outside_catalogue: physics the catalogue does not have (a monitored sensor with a cubic
    nonlinearity, 30-60 % extra at its peak): the right answer is the verdict `unexplained`.
`--pairs N` cases per rig carry two different effects at once (each at its own place and magnitude, no
concealment but each other), as a real rig has more than one defect: the right answer finds both
(truth.json: the first as `effect`, the second in `others`).

`--segments N` / `--step-divisor K` record with another discretisation of the same datasheet (N segments per
flexible part, a K x finer physics step), which the sidecars do not tell: what recordings from an independent
implementation of rigs.md look like to ours (truth.json "recorder").

Written: DIR/cases/<id>/<stem>.csv + .json (sidecars carry no effect, parameters or notes;
case ids are opaque) and DIR/truth.json (the answers; schema in `make_cases`). DIR must not
already hold a benchmark. Same seed, same arguments: byte-identical files.

Skipped (SKIPPED, listed with the reason at the end of --help): laser_arm presliding and
dwell_time_stiction (no nominal hub friction to act on), laser_arm structural_damping (does
not show within the catalogue's bounds); Watflex places the locked-shoulder experiments do
not excite (the shoulder, its angle and torque command, the elbow bearing; the two-joint set-up
excites them); effects a rig description does not allow.
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import json
import math
import sys
import time
import zlib
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from watflex_sim import SimulationError, check, load_scenario, simulate, write_recording  # noqa: E402
from watflex_sim.effects import CATALOGUE  # noqa: E402
from watflex_sim.model import ConfigError  # noqa: E402
from watflex_sim.resim import model_timestep  # noqa: E402
from watflex_sim.rigdesc import load_rig  # noqa: E402

FORMAT = "flexarm-benchmark/1"
RIGS = ("laser_arm", "watflex")
MAX_DRAWS = 4  # magnitude draws before a case whose simulation diverges is skipped
SMALL = 0.2  # "small against noise": magnitudes from the weakest 20 % of the range

# Magnitudes: rig -> effect (or "effect:where") -> {parameter: (kind, weak, strong)}.
# kind "+": uniform weak..strong; "±": that with a random sign; "×": a ratio weak..strong (> 1)
# or its inverse, at random; "~": uniform, not a magnitude; "=": fixed at `weak`.
# Chosen by simulating each effect at both ends on the three 6 s recordings, noise-free, against
# the nominal noise-free run: at the weak end the mean NRMSE over the compared channels is about
# the noise floor (laser 0.07, Watflex 0.03) and the most affected channel moves by several times
# its rig noise (rigs/*.toml); at the strong end the mean NRMSE stays below ~0.4. Every value
# lies within the catalogue's bounds (effects.CATALOGUE; a scaled one times its size from the
# data, diagnose.scale_of, noted below as "bound"), and current_saturation limits between 0.3
# and 0.9 x the robust peak command.
RANGES = {
    "laser_arm": {  # motor torque RMS 0.5 N m over the 0.4 s transient, 0.2 N m over 6 s; hub 2 mrad
        "coulomb_friction": {"torque_positive": ("+", 0.03, 0.12), "torque_negative": ("+", 0.03, 0.12)},  # N m
        "stribeck_friction": {"breakaway_positive": ("+", 0.04, 0.15), "breakaway_negative": ("+", 0.04, 0.15),
                              "v_s": ("~", 0.005, 0.03)},  # N m, rad/s
        "viscous_friction": {"coefficient": ("+", 5.0, 20.0), "coefficient_negative": ("+", 5.0, 20.0)},  # N m s/rad
        "position_dependent_friction": {"amplitude": ("±", 0.04, 0.1), "period": ("~", 0.012, 0.05),
                                        "phase": ("~", -math.pi, math.pi), "spring": ("=", 0.0)},  # N m, rad
        "backlash": {"width": ("+", 3e-5, 1.5e-4)},  # rad: mean NRMSE 0.14..0.34 (0.10 as the width -> 0:
        # the clamp's armature alone moves motor_current)
        "joint_compliance": {"stiffness": ("+", 1.5e4, 3e3)},  # N m/rad: mean NRMSE 0.11..0.37; bound 3e4
        "payload": {"mass": ("+", 0.2, 1.0)},  # kg
        "link_stiffness_change": {"ratio": ("+", 0.65, 0.45)},  # softer (cracked/loose): stiffer hardly shows
        "actuator_gain": {"ratio": ("×", 1.1, 1.4)},
        "actuator_offset": {"offset": ("±", 0.008, 0.03)},  # V (robust peak command 0.8 V: bound 0.4 V)
        "current_saturation": {"limit": ("+", 0.75, 0.55)},  # V: 0.87..0.6 x the robust peak command
        # (0.86..0.92 V once saturated; 0.8 V nominal, 1.05 V at most); mean NRMSE 0.17..0.41
        "sensor_gain:tip_sensor": {"ratio": ("×", 1.08, 1.25)},  # tolerance 2 %
        "sensor_gain:hub_angle": {"ratio": ("×", 1.05, 1.2)},
        "sensor_gain:motor_current": {"ratio": ("×", 1.4, 1.9)},  # monitored only: mean NRMSE 0.07..0.12,
        # 0.29..0.47 on it (RMS change 1.6..3.7 x its noise over 6 s)
        "sensor_offset:tip_sensor": {"offset": ("±", 0.12, 0.3)},  # V: the loop hides it, the hub shows it;
        # bound 0.33 V (half the tip's spread)
        "sensor_offset:hub_angle": {"offset": ("±", 4e-5, 1.3e-4)},  # rad: 2-7 encoder counts; bound 1.6e-4
        "sensor_offset:motor_current": {"offset": ("±", 0.004, 0.007)},  # A: 1..1.75 x noise, the most the
        # bound allows (half the current's 0.0165 A spread: 0.0082 A); NRMSE 0.27..0.47 on it
        "delay": {"seconds": ("+", 0.002, 0.008)},  # s
        "delay:tip_sensor": {"seconds": ("+", 0.001, 0.005)},  # s (1 ms ticks): mean NRMSE 0.16..0.35
    },
    "watflex": {  # elbow: break-away ~5.5 N m, RMS torque 4.5 N m, peak 30 N m, RMS speed 0.23 rad/s
        "coulomb_friction": {"torque_positive": ("+", 0.4, 1.5), "torque_negative": ("+", 0.4, 1.5)},  # N m
        "stribeck_friction": {"breakaway_positive": ("+", 0.5, 2.0), "breakaway_negative": ("+", 0.5, 2.0),
                              "v_s": ("~", 0.01, 0.05)},  # N m, rad/s
        "viscous_friction": {"coefficient": ("+", 1.0, 4.0), "coefficient_negative": ("+", 1.0, 4.0)},  # nominal ~1
        "presliding": {"sigma0": ("+", 1e4, 1e3), "sigma1": ("~", 5.0, 20.0)},  # N m/rad, N m s/rad
        "dwell_time_stiction": {"gain": ("+", 0.3, 0.8), "time_constant": ("~", 0.3, 1.0)},  # -, s; > 0.8 sticks
        "position_dependent_friction": {"amplitude": ("±", 0.5, 2.0), "period": ("~", 0.3, 1.5),
                                        "phase": ("~", -math.pi, math.pi), "spring": ("=", 0.0)},  # N m, rad
        "backlash": {"width": ("+", 2e-3, 2.5e-2)},  # rad: mean NRMSE 0.035..0.3
        "joint_compliance": {"stiffness": ("+", 3e3, 4e2)},  # N m/rad: mean NRMSE 0.026..0.18; bound 3e4
        "payload": {"mass": ("+", 0.15, 1.0)},  # kg on the 8.1 kg end effector
        "link_stiffness_change": {"ratio": ("×", 1.25, 1.6)},  # link 2; tolerance 5 %
        "structural_damping": {"ratio": ("+", 5.0, 20.0)},  # link 2; less damping hardly shows
        "actuator_gain": {"ratio": ("×", 1.1, 1.35)},
        "actuator_offset": {"offset": ("±", 0.4, 1.5)},  # N m (robust peak command 27.5 N m: bound 13.7)
        "current_saturation": {"limit": ("+", 22.0, 12.0)},  # N m: 0.77..0.41 x the robust peak command
        # (27.5 N m nominal, 28-29.6 saturated)
        "sensor_gain:elbow_angle": {"ratio": ("×", 1.05, 1.2)},
        "sensor_gain": {"ratio": ("×", 1.1, 1.3)},  # strain bridges
        "sensor_offset:elbow_angle": {"offset": ("±", 5e-3, 2e-2)},  # rad; bound 0.08
        "sensor_offset": {"offset": ("±", 0.04, 0.2)},  # V on strain bridges of 1-2 V spread (noise 2 mV;
        # bound: half the spread, 0.48 V on 2B)
        "delay": {"seconds": ("+", 0.005, 0.02)},  # s
        "bearing_friction": {"force": ("+", 0.1, 0.8)},  # N at the end effector, 0.7 m from the elbow
        "table_tilt": {"angle": ("±", 5e-3, 2e-2)},  # rad
    },
}
# Watflex places the elbow experiments excite (the single-link set-up of rigs.md §2: link 1 rigid,
# its bridges not mounted, the elbow housing fixed); laser arm: all.
EXCITED = {"watflex": {"elbow", "link2", "tip", "elbow_torque_cmd", "elbow_angle", "strain_2A", "strain_2B",
                       "command", "end_effector_bearing", "table"}}
SKIPPED = {  # (rig, effect) or (rig, effect, where): why no case is made
    ("laser_arm", "presliding"): "the hub has no nominal friction for LuGre bristles to act on: no change",
    ("laser_arm", "dwell_time_stiction"): "the hub has no nominal friction for dwell time to raise: no change",
    ("laser_arm", "structural_damping"): "30x beam damping (the catalogue's top) moves the tip by 0.6x its "
                                         "noise (NRMSE 0.009), 0.5x (its bottom) by nothing",
}
DIRECTIONAL = {"coulomb_friction": ("torque_positive", "torque_negative"),
               "stribeck_friction": ("breakaway_positive", "breakaway_negative"),
               "viscous_friction": ("coefficient", "coefficient_negative")}
HARD_KINDS = ("clean_rest", "out_of_tolerance", "outside_catalogue")
WATFLEX_SETUPS = ("single_link", "two_joint")  # the elbow experiments (shoulder locked), or both joints moving
MONITORED = {"laser_arm": "motor_current", "watflex": "strain_2B"}  # a sensor no controller reads
STIFFNESS_PLACE = {"laser_arm": "beam", "watflex": "link2"}
CONCEALMENTS = ("closed loop", "one direction only", "mixed with parameter error", "small against noise",
                "indirect channel")
NEUTRAL_NOTES = "benchmark recording"
DROPPED_SCENARIO_KEYS = ("effects", "parameters", "notes", "name",  # the truth never goes in a sidecar,
                         "n_segments", "timestep")  # nor the discretisation of the simulator that recorded it


def _rng(seed: int, key: str) -> np.random.Generator:
    """A generator per case, so a case does not depend on which other cases are made."""
    return np.random.default_rng([seed, zlib.crc32(key.encode())])


def draw(ranges: dict, rng: np.random.Generator, small: bool) -> dict[str, float]:
    """Parameter values from a RANGES entry; `small`: magnitudes from the weakest SMALL of the range."""
    out = {}
    for name, (kind, *span) in ranges.items():
        if kind == "=":
            out[name] = float(span[0])
            continue
        lo, hi = span
        u = rng.uniform(0.0, SMALL if small and kind != "~" else 1.0)
        value = lo + u * (hi - lo)
        if kind == "±" and rng.random() < 0.5:
            value = -value
        if kind == "×" and rng.random() < 0.5:
            value = 1.0 / value
        out[name] = float(f"{value:.4g}")
    return out


def in_whole_quanta(effect: str, parameters: dict[str, float]) -> dict[str, float]:
    """`parameters` with each quantised one (a delay) in whole steps, at least one: the truth is what the
    simulator does."""
    for param in CATALOGUE[effect][1]:
        if param.quantum and param.name in parameters:
            parameters[param.name] = max(1, round(parameters[param.name] / param.quantum)) * param.quantum
    return parameters


def perturbed_parameters(rig: str, rng: np.random.Generator) -> dict[str, float]:
    """Every rig parameter's ratio drawn uniformly within its tolerance (rigs/<rig>.toml)."""
    return {name: float(f"{1.0 + rng.uniform(-p['tolerance'], p['tolerance']):.4g}")
            for name, p in load_rig(rig).parameters.items()}


def experiments(rig: str, duration: float, rng: np.random.Generator, rest_last: bool = False,
                recorder: dict | None = None, setup: str = "single_link") -> list[tuple[str, dict]]:
    """The three recordings of a case as (stem, scenario without effects); with `rest_last` the third is
    an experiment in which nothing moves (laser: a zero step; Watflex: the sub-break-away triangle, or
    two-joint steps of zero). `recorder`: scenario keys of the simulator that records them (recorder_of);
    `setup`: the Watflex set-up (WATFLEX_SETUPS)."""
    if rig == "laser_arm":
        third = float(rng.choice([0.0, 1.15]))  # kg: a paper payload besides the 0.7 kg of the steps
        plan = [("step_positive", "positive", 0.7), ("step_negative", "negative", 0.7),
                (f"step_payload_{third:g}kg", str(rng.choice(["positive", "negative"])), third)]
        runs = [(stem, load_scenario("laser_arm_step") | {"direction": d, "payload_kg": m}) for stem, d, m in plan]
    elif setup == "two_joint":
        runs = [(f"two_joint_{k}", two_joint_steps(*_signed(rng, (0.3, 0.5), (0.6, 1.0)), duration)) for k in "abc"]
    else:
        runs = []
        for stem, direction in (("step_positive", "positive"), ("step_negative", "negative")):
            sc = load_scenario("watflex_elbow_step") | {"direction": direction}
            sc["reference"][0]["time_s"] = min(0.5, duration / 5)  # s
            runs.append((stem, sc))
        sc = load_scenario("watflex_elbow_staircase")  # 0.1 rad steps: near the elbow's break-away
        sc["direction"] = str(rng.choice(["positive", "negative"]))
        sc["reference"][0]["times_s"] = [round(duration * f, 3) for f in (0.2, 0.4, 0.6, 0.8)]  # s
        runs.append(("staircase", sc))
    if rest_last:
        if rig == "laser_arm":
            sc = load_scenario("laser_arm_step") | {"payload_kg": 0.7}
            sc["reference"][0]["arc_m"] = 0.0
        elif setup == "two_joint":
            sc = two_joint_steps(0.0, 0.0, duration)
        else:
            sc = load_scenario("watflex_elbow_triangle")
        runs[-1] = ("at_rest", sc)
    for _, sc in runs:
        sc.update(duration_s=float(duration), noise=True, seed=int(rng.integers(2**31)), **(recorder or {}))
    return runs


def _signed(rng: np.random.Generator, *spans: tuple[float, float]) -> list[float]:
    """One value drawn uniformly within each (low, high) span, each with a random sign."""
    return [float(f"{rng.choice([-1.0, 1.0]) * rng.uniform(*span):.3g}") for span in spans]


def two_joint_steps(shoulder: float, elbow: float, duration: float) -> dict:
    """The observer control of both joints (scenario watflex_observer_two_joint), steps of `shoulder` and
    `elbow` rad at min(0.5 s, duration / 5)."""
    sc = copy.deepcopy(load_scenario("watflex_observer_two_joint"))
    for ref, amplitude in zip(sc["reference"], (shoulder, elbow)):
        ref.update(amplitude=amplitude, time_s=min(0.5, duration / 5))  # rad, s
    return sc


def places(rig: str, effect: str, setup: str = "single_link") -> list[str]:
    """Where `effect` may go on `rig`: allowed by the rig description, excited, not SKIPPED."""
    allowed = load_rig(rig).effects.get(effect, [])
    excited = EXCITED.get(rig) if setup == "single_link" else None
    return [w for w in allowed if (excited is None or w in excited) and (rig, effect, w) not in SKIPPED]


def why_skipped(rig: str, effect: str, setup: str = "single_link") -> str | None:
    """Why `effect` gets no case on `rig` (in the Watflex `setup`), or None if it gets cases."""
    if (rig, effect) in SKIPPED:
        return SKIPPED[(rig, effect)]
    if effect not in load_rig(rig).effects:
        return "the rig description does not allow it"
    if not places(rig, effect, setup):
        return "no place the experiments excite"
    return None


def _ranges(rig: str, effect: str, where: str) -> dict:
    return RANGES[rig].get(f"{effect}:{where}") or RANGES[rig][effect]


def _units(rig: str, effect: str, where: str) -> dict[str, str]:
    """Parameter units, 'command unit'/'channel unit' resolved to the channel's unit."""
    channel_unit = load_rig(rig).channels.get(where, {}).get("unit", "")
    return {p.name: channel_unit if p.unit.endswith(" unit") else p.unit for p in CATALOGUE[effect][1]
            if p.name in _ranges(rig, effect, where)}


def _sidecar_meta(meta: dict) -> dict:
    """The sidecar of a benchmark recording: what a user would write, without the truth."""
    meta = dict(meta, notes=NEUTRAL_NOTES)
    meta["scenario"] = {k: v for k, v in meta["scenario"].items() if k not in DROPPED_SCENARIO_KEYS}
    return meta


def simulate_case(runs: list, effects: list, parameters: dict, drop: tuple = ()) -> list:
    """[(stem, Recording)] of a case's runs with `effects` and refit `parameters`, without `drop` channels."""
    out = []
    for stem, scenario in runs:
        rec = simulate(check(dict(scenario, effects=effects, parameters=parameters))).recording
        rec.channels = {c: v for c, v in rec.channels.items() if c not in drop}
        rec.meta = _sidecar_meta(rec.meta)
        out.append((stem, rec))
    return out


def recorder_of(rig: str, segments: int = 0, step_divisor: int = 1) -> dict:
    """Scenario keys of a recording simulator other than ours, of the same datasheet: `segments` per
    flexible part (0: ours) and a physics step `step_divisor` x finer. The diagnosis re-simulates with
    its own (the sidecars do not say), as it would recordings from an independent implementation."""
    out = {"n_segments": segments} if segments else {}
    if step_divisor != 1:
        out["timestep"] = model_timestep(load_rig(rig)) / step_divisor  # s
    return out


def _key(rig: str, setup: str, rest: str) -> str:
    """A case's key: its draws' seed and its id (the single-link set-up's as before the two-joint one)."""
    return f"{rig}/{rest}" if rig != "watflex" or setup == "single_link" else f"{rig}/{setup}/{rest}"


def make_case(rig: str, effect: str | None, k: int, seed: int, duration: float,
              recorder: dict | None = None, setup: str = "single_link") -> tuple[dict, list] | None:
    """One case: (truth entry without recordings, [(stem, Recording)]), or None if it always diverged.

    `effect` None: a clean case (rig parameters perturbed within tolerance only). `recorder`: recorder_of;
    `setup`: the Watflex set-up (WATFLEX_SETUPS)."""
    key = _key(rig, setup, f"{effect or 'clean'}/{k}")
    rng = _rng(seed, key)
    kind = effect if effect in HARD_KINDS else ("clean" if effect is None else "effect")
    truth = dict(id=f"{rig}-{zlib.crc32(f'{seed}/{key}'.encode()):08x}", rig=rig, kind=kind, effect=effect, where=None,
                 parameters={}, units={}, refit_parameters={}, concealment=None, duration_s=float(duration))
    runs = experiments(rig, duration, rng, rest_last=kind == "clean_rest", recorder=recorder, setup=setup)
    if kind in HARD_KINDS:
        return make_hard_case(truth, rig, kind, runs, rng)
    if effect is None:
        truth["refit_parameters"] = perturbed_parameters(rig, rng)
        return truth, simulate_case(runs, [], truth["refit_parameters"])
    where = str(rng.choice(places(rig, effect, setup)))
    options = [c for c in CONCEALMENTS if c != "one direction only"
               and (c != "indirect channel" or (rig == "watflex" and where != "elbow_angle"))]
    one_side = effect in DIRECTIONAL and rng.random() < 0.5  # else 3 effects of ~35 would rarely get it
    concealment = "one direction only" if one_side else str(rng.choice(options))
    drop = ("elbow_angle",) if concealment == "indirect channel" else ()
    for _ in range(MAX_DRAWS):
        parameters = in_whole_quanta(effect, draw(_ranges(rig, effect, where), rng, small=concealment == "small against noise"))
        if one_side:
            parameters[DIRECTIONAL[effect][int(rng.integers(2))]] = 0.0
        refit = perturbed_parameters(rig, rng) if concealment == "mixed with parameter error" else {}
        try:
            recordings = simulate_case(runs, [dict(effect=effect, where=where, **parameters)], refit, drop)
        except SimulationError as exc:
            print(f"  {key}: diverged with {parameters} ({exc}); drawing again", file=sys.stderr)
            continue
        truth.update(where=where, parameters=parameters, units=_units(rig, effect, where),
                     refit_parameters=refit, concealment=concealment)
        return truth, recordings
    print(f"  {key}: skipped, diverged {MAX_DRAWS} times", file=sys.stderr)
    return None


def make_hard_case(truth: dict, rig: str, kind: str, runs: list, rng: np.random.Generator) -> tuple[dict, list]:
    """A case of HARD_KINDS (module docstring): its truth and recordings."""
    refit = perturbed_parameters(rig, rng)
    truth.update(effect=None, refit_parameters=refit, concealment=kind.replace("_", " "))
    if kind == "clean_rest":
        return truth, simulate_case(runs, [], refit)
    if kind == "out_of_tolerance":
        if rng.random() < 0.5:
            ratio = float(f"{rng.uniform(2.5, 4.0) if rng.random() < 0.5 else rng.uniform(0.25, 0.4):.4g}")
            effect = dict(effect="link_stiffness_change", where=STIFFNESS_PLACE[rig], ratio=ratio)
        else:
            effect = dict(effect="sensor_gain", where=MONITORED[rig], ratio=-1.0)
        truth.update(effect=effect["effect"], where=effect["where"], parameters={"ratio": effect["ratio"]},
                     units={"ratio": "-"})
        return truth, simulate_case(runs, [effect], refit)
    channel, extra = MONITORED[rig], float(f"{rng.uniform(0.3, 0.6):.3g}")
    recordings = simulate_case(runs, [], refit)
    for _, rec in recordings:  # y = x (1 + extra (x / peak)^2): +extra at the channel's peak
        x = rec.channels[channel]
        rec.channels[channel] = x * (1 + extra * (x / np.nanmax(np.abs(x))) ** 2)
    truth.update(where=channel, parameters={"cubic_extra_at_peak": extra}, units={"cubic_extra_at_peak": "-"})
    return truth, recordings


def make_pair_case(rig: str, effects: list[str], k: int, seed: int, duration: float,
                   recorder: dict | None = None, setup: str = "single_link") -> tuple[dict, list] | None:
    """A case with two different effects of `effects` (each where `places` allows, at a magnitude of its
    RANGES): (truth entry, [(stem, Recording)]), or None if the effects cannot be drawn or always diverge."""
    key = _key(rig, setup, f"pair/{k}")
    rng = _rng(seed, key)
    usable = [e for e in effects if not why_skipped(rig, e, setup)]
    if len(usable) < 2:
        return None
    truth = dict(id=f"{rig}-{zlib.crc32(f'{seed}/{key}'.encode()):08x}", rig=rig, kind="pair", effect=None, where=None,
                 parameters={}, units={}, refit_parameters={}, concealment="two effects", duration_s=float(duration))
    runs = experiments(rig, duration, rng, recorder=recorder, setup=setup)
    for _ in range(MAX_DRAWS):
        chosen = [str(e) for e in rng.choice(usable, size=2, replace=False)]
        entries = []
        for effect in chosen:
            where = str(rng.choice(places(rig, effect, setup)))
            parameters = in_whole_quanta(effect, draw(_ranges(rig, effect, where), rng, small=False))
            entries.append(dict(effect=effect, where=where, parameters=parameters, units=_units(rig, effect, where)))
        try:
            recordings = simulate_case(runs, [dict(effect=e["effect"], where=e["where"], **e["parameters"]) for e in entries], {})
        except (SimulationError, ConfigError) as exc:
            print(f"  {key}: {chosen} failed ({exc}); drawing again", file=sys.stderr)
            continue
        first, second = entries
        truth.update(effect=first["effect"], where=first["where"], parameters=first["parameters"], units=first["units"],
                     others=[second])
        return truth, recordings
    print(f"  {key}: skipped, diverged {MAX_DRAWS} times", file=sys.stderr)
    return None


def make_cases(out, seed: int = 0, rigs=RIGS, effects=None, per_effect: int = 1, clean: int = 3,
               duration: float = 6.0, log=lambda line: print(line, flush=True), hard: int = 0,
               segments: int = 0, step_divisor: int = 1, pairs: int = 0, setup: str = "single_link",
               ranges: dict[str, tuple[float, float]] | None = None) -> dict:
    """Write the benchmark into `out` (cases/<id>/<stem>.csv/.json, truth.json); return the truth.
    `segments`, `step_divisor`: the recording simulator's discretisation (recorder_of; default ours);
    `setup`: the Watflex set-up (WATFLEX_SETUPS); `ranges`: "effect.parameter" -> (low, high) drawn from
    instead of RANGES' span on every rig (`wider_ranges`; the draw's kind kept).

    truth.json: {"format", "seed", "generator", "cases": [{"id", "rig", "kind" (effect, clean, pair or one of
    HARD_KINDS), "recordings" (paths relative to `out`, shuffled), "effect" | null, "where" | null, "parameters",
    "units", "refit_parameters" (rig parameter -> ratio), "concealment" | null, "duration_s", and for a pair
    "others": [{"effect", "where", "parameters", "units"}]}],
    "skipped": [{"rig", "effect", "why"}], "recorder": {"segments", "step_divisor"}, "watflex_setup", and with `ranges`
    "ranges": {"effect.parameter": [low, high]}}. `effects` None: the whole catalogue.
    """
    out = Path(out)
    if (out / "truth.json").exists() or (out / "cases").exists():
        raise ValueError(f"{out} already holds a benchmark (truth.json or cases/): choose another directory")
    effects = list(CATALOGUE) if effects is None else list(effects)
    plan, skipped = [], []
    for rig in rigs:
        for effect in effects:
            why = why_skipped(rig, effect, setup)
            if why:
                skipped.append({"rig": rig, "effect": effect, "why": why})
            else:
                plan += [(rig, effect, k) for k in range(per_effect)]
        plan += [(rig, None, k) for k in range(clean)]
        plan += [(rig, kind, k) for kind in HARD_KINDS for k in range(hard)]
        plan += [(rig, "pair", k) for k in range(pairs)]
    cases = []
    with wider_ranges(ranges or {}):
        for n, (rig, effect, k) in enumerate(plan, 1):
            start = time.perf_counter()
            recorder = recorder_of(rig, segments, step_divisor)
            made = (make_pair_case(rig, effects, k, seed, duration, recorder, setup) if effect == "pair"
                    else make_case(rig, effect, k, seed, duration, recorder, setup))
            if made is None:
                skipped.append({"rig": rig, "effect": effect, "why": "diverged at every magnitude drawn"})
                continue
            truth, recordings = made
            directory = out / "cases" / truth["id"]
            paths = [write_recording(rec, directory, stem) for stem, rec in recordings]
            order = _rng(seed, f"order/{truth['id']}").permutation(len(paths))  # the diagnosis must not depend on it
            truth["recordings"] = [paths[i].relative_to(out).as_posix() for i in order]
            cases.append(truth)
            named = "+".join(e["effect"] for e in [truth, *truth.get("others", [])]) if effect == "pair" else effect
            log(f"[{n}/{len(plan)}] {truth['id']}: {named or 'clean'}"
                f"{'@' + truth['where'] if truth['where'] else ''} ({truth['concealment'] or 'parameters only'}) "
                f"{time.perf_counter() - start:.1f} s")
    order = ("id", "rig", "kind", "recordings", "effect", "where", "parameters", "units", "refit_parameters",
             "concealment", "duration_s", "others")
    truth = {"format": FORMAT, "seed": seed, "generator": "tools/make_benchmark.py",
             "cases": [{k: c[k] for k in order if k in c} for c in sorted(cases, key=lambda c: c["id"])], "skipped": skipped,
             "recorder": {"segments": segments, "step_divisor": step_divisor}, "watflex_setup": setup}
    if ranges:
        truth["ranges"] = {name: list(span) for name, span in ranges.items()}
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth


def _drawing(effect: str, param: str, rigs) -> list[dict]:
    """The RANGES entries of `rigs` (any place) that draw `effect`'s parameter `param`."""
    return [entry for rig in rigs for key, entry in RANGES[rig].items() if key.partition(":")[0] == effect and param in entry]


@contextlib.contextmanager
def wider_ranges(ranges: dict[str, tuple[float, float]]):
    """RANGES with each "effect.parameter" -> (low, high) of `ranges` drawn from instead, on every rig and place that
    has it, while the block runs (a probe beyond the benchmark's magnitudes: a Stribeck velocity of 0.1-0.5 rad/s)."""
    saved = copy.deepcopy(RANGES)
    try:
        for name, (low, high) in ranges.items():
            effect, _, param = name.partition(".")
            for entry in _drawing(effect, param, RANGES):
                entry[param] = (entry[param][0], low, high)
        yield
    finally:
        RANGES.clear()
        RANGES.update(saved)


def parse_range(text: str, rigs: list[str]) -> tuple[str, tuple[float, float]]:
    """"effect.parameter=low:high" -> ("effect.parameter", (low, high)), checked against the catalogue's bounds and the
    benchmark's draws of `rigs`; ValueError (one line) otherwise."""
    name, _, span = text.partition("=")
    effect, _, param = name.partition(".")
    params = {p.name: p for p in CATALOGUE.get(effect, (None, ()))[1]}
    if param not in params:
        raise ValueError(f"--range {text!r}: not EFFECT.PARAM=LOW:HIGH with a catalogue effect and its parameter")
    try:
        low, high = (float(v) for v in span.split(":"))
    except ValueError:
        raise ValueError(f"--range {text!r}: LOW:HIGH must be two numbers") from None
    p = params[param]
    if not (math.isfinite(low) and math.isfinite(high) and low < high) or not p.scale and not p.low <= low < high <= p.high:
        raise ValueError(f"--range {text!r}: need LOW < HIGH within the catalogue's {p.low:g} .. {p.high:g} {p.unit}")
    if not _drawing(effect, param, rigs):
        raise ValueError(f"--range {text!r}: the benchmark draws no {name} on {', '.join(rigs)}")
    return name, (low, high)


def main(argv=None) -> int:
    first, _, rest = __doc__.partition("\n\n")
    skipped = "\n".join(f"  {'/'.join(k)}: {why}" for k, why in SKIPPED.items())
    parser = argparse.ArgumentParser(description=first, epilog=rest.split("\n\n", 1)[1] + "\nskipped:\n" + skipped,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.error = lambda message: (print(f"make_benchmark: {message}", file=sys.stderr), sys.exit(2))
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory (must not hold a benchmark yet)")
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="seed of every draw (default 0)")
    parser.add_argument("--rigs", default=",".join(RIGS), metavar="LIST", help=f"comma-separated rigs (default {','.join(RIGS)})")
    parser.add_argument("--per-effect", type=int, default=1, metavar="N", help="cases per effect and rig (default 1)")
    parser.add_argument("--clean", type=int, default=3, metavar="N", help="clean cases per rig: no effect (default 3)")
    parser.add_argument("--hard", type=int, default=0, metavar="N",
                        help=f"cases per rig of each hard kind ({', '.join(HARD_KINDS)}; default 0)")
    parser.add_argument("--pairs", type=int, default=0, metavar="N",
                        help="cases per rig with two different effects of --effects at once (default 0)")
    parser.add_argument("--effects", default="", metavar="LIST", help="comma-separated catalogue effects (default: all)")
    parser.add_argument("--duration", type=float, default=6.0, metavar="S", help="length of each recording, s (default 6)")
    parser.add_argument("--segments", type=int, default=0, metavar="N",
                        help="record with N segments per flexible part, as another implementation of the datasheet "
                             "would differ from ours (default 0: ours; the diagnosis is not told)")
    parser.add_argument("--step-divisor", type=int, default=1, metavar="K",
                        help="record with a physics step K x finer than ours (default 1)")
    parser.add_argument("--watflex-setup", choices=WATFLEX_SETUPS, default="single_link",
                        help="Watflex experiments: the elbow ones with the shoulder locked (default), or steps of "
                             "both joints under observer control, both links flexible (two_joint; ~3x the cost)")
    parser.add_argument("--range", action="append", default=[], metavar="EFFECT.PARAM=LOW:HIGH",
                        help="draw an effect parameter from LOW..HIGH (its unit in the catalogue) on every rig instead "
                             "of the benchmark's span, e.g. stribeck_friction.v_s=0.1:0.3 (repeatable; truth.json "
                             "\"ranges\" keeps them)")
    args = parser.parse_args(argv)
    rigs = [r for r in args.rigs.split(",") if r]
    effects = [e for e in args.effects.split(",") if e] or None
    if not rigs or set(rigs) - set(RIGS):
        parser.error(f"--rigs must name rigs among {', '.join(RIGS)}, got {args.rigs!r}")
    if effects and set(effects) - set(CATALOGUE):
        parser.error(f"unknown effect(s) {', '.join(sorted(set(effects) - set(CATALOGUE)))} "
                     f"(catalogue: {', '.join(CATALOGUE)})")
    try:
        ranges = dict(parse_range(text, rigs) for text in args.range)
    except ValueError as exc:
        parser.error(str(exc))
    if args.per_effect < 0 or args.clean < 0 or args.hard < 0 or args.pairs < 0:
        parser.error("--per-effect, --clean, --hard and --pairs must be >= 0")
    if args.segments != 0 and not 2 <= args.segments <= 100 or args.step_divisor < 1:
        parser.error(f"--segments must be 0 or within 2 .. 100 and --step-divisor >= 1, got {args.segments}, {args.step_divisor}")
    if not 0.2 <= args.duration <= 600:
        parser.error(f"--duration must be within 0.2 .. 600 s (the laser step is at 0.1 s), got {args.duration:g}")
    start = time.perf_counter()
    try:
        truth = make_cases(args.out, args.seed, rigs, effects, args.per_effect, args.clean, args.duration, hard=args.hard,
                           segments=args.segments, step_divisor=args.step_divisor, pairs=args.pairs,
                           setup=args.watflex_setup, ranges=ranges)
    except (ValueError, OSError) as exc:
        parser.error(str(exc))
    for s in truth["skipped"]:
        print(f"skipped {s['rig']}/{s['effect']}: {s['why']}")
    print(f"{len(truth['cases'])} cases in {args.out} ({time.perf_counter() - start:.0f} s); truth in "
          f"{args.out / 'truth.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
