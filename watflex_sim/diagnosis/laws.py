"""One friction law where two were found at one joint: the law whose sliding curve stands for the pair's.

Contract: `one_law` takes the scored current result (effect_fit.scored); where two of its findings at one joint are
CURVE_LAWS, it refits each other such law the rig allows there in their place, started from `curve_start` (its curve
matched to the pair's over the joint's simulated speeds, `joint_speeds`), and keeps it where it scores better
(validate.gains). Returns a result scored like a candidate, and what it tried for the report's alternatives.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from ..effects import Patch, apply_effects, apply_parameters
from ..friction import exponential
from ..joint_friction import patched, scenario_frictions
from ..recording import Recording
from ..resim import scenario_from_recording
from .data import Data, Model
from .earlier import refit_in_place, scores_without
from .fitting import parameter_count
from .motion import motions
from .runner import Runner
from .screening import CURVE_LAWS, make_candidate
from .validate import gains


CURVE_SPEEDS = 2000  # joint speeds (of the simulated motion) a law's curve is matched on, at most
SPEED_WINDOW_S = 0.02  # s: a joint's speed is the slope of a quadratic over this long (Savitzky-Golay)
CURVE_STARTS = 7  # a log-scaled parameter (a Stribeck speed) is started at this many values over its bounds


def one_law(data: Data, runner: Runner, current: dict, margin: float) -> tuple[dict, list[tuple[dict, dict, int]]]:
    """Two friction laws found at one joint (CURVE_LAWS) replaced by one other law there, where it scores better.

    Rounds add one law at a time, and two can stand for a third: a small Stribeck friction (break-away 0.051 N m
    decaying by 0.0103 rad/s, seed 79's laser_arm-49948fef) was found as a Coulomb friction of 0.052 N m and then a
    viscous term of -2.36 N m s/rad, which together slope down as the Stribeck law does at the slow speeds the hub
    spent its time at; the Stribeck law alone was fitted only beside the Coulomb friction. Each other law the rig
    allows at the joint is started where its sliding curve best matches the pair's over the joint's simulated speeds
    (least squares, `curve_start`), then it and the rig's parameters are refit in the pair's place
    (earlier.refit_in_place, as swap_earlier) and both are scored by validate.gains against the model without the
    pair; the single law is kept when it scores better by `margin` (the score charges each parameter: one law has
    fewer). Returns the current result and (tried, chosen, the number of effects before the tried one's) for the
    report's alternatives."""
    tried = []
    for joint in sorted({e["where"] for e in current["model"].effects if e["effect"] in CURVE_LAWS}):
        effects = current["model"].effects  # as an earlier joint's replacement left them
        pair = [i for i, e in enumerate(effects) if e["effect"] in CURVE_LAWS and e["where"] == joint]
        laws = [law for law in CURVE_LAWS if joint in data.rig.effects.get(law, ())
                and law not in {effects[i]["effect"] for i in pair}]
        if len(pair) != 2 or not laws:
            continue
        rest = [e for i, e in enumerate(effects) if i not in pair]
        parameters = dict(current["model"].parameters)
        baseline = scores_without(data, runner, Model(rest, parameters))
        if baseline is None:
            continue
        chosen = gains({**current, "effect": effects[pair[-1]]["effect"], "where": joint,
                        "n_params": sum(parameter_count(data, effects[i]) for i in pair)}, *baseline)
        speeds = joint_speeds(data, current["sims"], joint)
        for law in laws:
            start = curve_start(data, current["model"], rest, law, joint, speeds)
            result = refit_in_place(data, runner, Model(rest + [start], parameters), baseline)
            if result is None:
                continue
            if result["score"] > chosen["score"] + margin:  # the pair replaced, its two laws last (alternative_entry)
                pair_model = Model(rest + [effects[i] for i in pair], dict(chosen["model"].parameters))
                tried.append(({**chosen, "model": pair_model}, result, len(rest)))
                current = result
                break
            tried.append((result, chosen, len(rest)))
    return current, tried


def joint_speeds(data: Data, sims: list[Recording], joint: str) -> np.ndarray:
    """Speeds (rad/s or m/s) of `joint` over the simulated recordings `sims`, every sample where it moves, at most
    CURVE_SPEEDS of them evenly taken: from the rig's measured channel of that joint (SPEED_WINDOW_S slopes), else
    each recording's motion."""
    angle = next((c for c, spec in data.rig.channels.items() if spec["kind"] == "measured"
                  and (c == f"{joint}_angle" or spec.get("joint") == joint)), None)
    pieces = []
    for sim, motion in zip(sims, motions(data)):
        q = sim.channels.get(angle) if angle else None
        q = q if q is not None and np.isfinite(q).all() else (motion[1] if motion else None)
        dt = float(np.median(np.diff(sim.time)))  # s
        window = int(SPEED_WINDOW_S / dt) | 1  # samples, odd: a quantised encoder's steps smoothed over it
        if q is not None and q.size > window:
            pieces.append(savgol_filter(q, window, 2, deriv=1, delta=dt))
    v = np.concatenate(pieces) if pieces else np.zeros(0)
    v = v[np.abs(v) > 1e-9]
    return v[np.linspace(0, v.size - 1, min(v.size, CURVE_SPEEDS)).astype(int)] if v.size else v


def friction_curve(data: Data, model: Model, joint: str, speeds: np.ndarray, base: dict) -> np.ndarray:
    """The sliding friction (N m or N; friction.exponential) of `joint` at `speeds` under `model`: the rig's joint
    friction (`base`, rig_frictions) with the model's refit parameters and effects applied."""
    patch = Patch()
    apply_parameters(patch, model.parameters, data.rig.parameter_knobs())
    apply_effects(patch, model.effects)
    law = patched(base, patch.friction, patch.friction_add).get(joint)
    if law is None:
        return np.zeros_like(speeds)
    return np.array([exponential(float(v), law.positive, law.negative) for v in speeds])


def rig_frictions(data: Data) -> dict:
    """The rig's joint friction laws (joint_friction.JointFriction) as the first recording's scenario sets them."""
    return scenario_frictions(data.rig, scenario_from_recording(data.recordings[0], data.rig))


def curve_start(data: Data, model: Model, rest: list[dict], law: str, joint: str, speeds: np.ndarray) -> dict:
    """`law` at `joint` with the parameters (within its slots) whose sliding curve beside `rest` best matches `model`'s
    at `speeds` (least squares; a log-scaled parameter started at CURVE_STARTS values over its bounds)."""
    cand = make_candidate(data, law, joint)
    names, slots = list(cand.slots), list(cand.slots.values())
    base = rig_frictions(data)
    target = friction_curve(data, model, joint, speeds, base)
    lo = np.array([s.to_internal(s.low) for s in slots])
    hi = np.array([s.to_internal(s.high) for s in slots])

    def effect(u):
        return {"effect": law, "where": joint, **{n: s.to_value(float(x)) for n, s, x in zip(names, slots, u)}}

    def misfit(u):
        return friction_curve(data, Model(rest + [effect(u)], model.parameters), joint, speeds, base) - target

    first = np.clip([s.to_internal(cand.start[n]) for n, s in zip(names, slots)], lo, hi)
    starts = [first]
    for k, s in enumerate(slots):
        if s.log:
            starts += [np.where(np.arange(first.size) == k, u, first) for u in np.linspace(lo[k], hi[k], CURVE_STARTS)]
    best = None
    if speeds.size:
        for u0 in starts:
            fit = least_squares(misfit, np.clip(u0, lo + 1e-12, hi - 1e-12), bounds=(lo, hi))
            if best is None or fit.cost < best.cost:
                best = fit
    return effect(best.x if best is not None else first)
