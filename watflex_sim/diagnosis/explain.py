"""Findings in words and physical terms: which effect, where (a place the rig names), which
direction (from the final parameters), how large (units of the effect at that place, 95 % intervals),
and the evidence.

Contract: `finding(...)` builds one report entry from the final model; `physical_place` names where an
effect acts in the rig's own terms (a delay 'on the commands' becomes the command channels recorded);
`units_at` turns the catalogue's generic units into the rig's ("command unit" -> V or N m, torque -> force
on a linear axis), and adds a current in A where the rig says how much current a command unit drives;
`canonical_form` puts the final model's effects in their canonical form with their intervals.
"""
from __future__ import annotations

from ..effects import CATALOGUE, canonical, canonical_moves
from .data import Data, Model
from .motion import neutral_values

EXPLAIN = {
    "coulomb_friction": "dry friction at {where}: it sticks below {torque_positive:.3g} (positive) / {torque_negative:.3g} (negative) and slides against that level",
    "stribeck_friction": "break-away at {where} above the sliding level by {breakaway_positive:.3g} / {breakaway_negative:.3g}, decaying with speed (v_s {v_s:.3g})",
    "viscous_friction": "extra viscous friction at {where}: {coefficient:.4g} (positive) / {coefficient_negative:.4g} (negative motion) per unit speed",
    "presliding": "elastic pre-sliding at {where} (bristle stiffness {sigma0:.3g}, damping {sigma1:.3g})",
    "dwell_time_stiction": "break-away at {where} grows with time at rest (gain {gain:.3g}, time constant {time_constant:.3g} s)",
    "position_dependent_friction": "a torque at {where} that varies with angle (amplitude {amplitude:.3g}, period {period:.3g}, spring {spring:.3g})",
    "backlash": "a dead band of {width:.3g} rad between {where} and its link, the link starting at {position:+.2f} of its half-width (a band that opens one way only reads as slip in that direction)",
    "joint_compliance": "a torsional spring of {stiffness:.4g} N m/rad between {where} and its link",
    "payload": "a tip mass {mass:+.3g} kg different from the declared payload",
    "link_stiffness_change": "bending stiffness of {where} at {ratio:.3g} x the datasheet",
    "structural_damping": "beam damping of {where} at {ratio:.3g} x nominal",
    "actuator_gain": "{where} acts with {ratio:.4g} x the commanded value",
    "actuator_offset": "a constant bias of {offset:+.4g} on {where}",
    "current_saturation": "{where} saturates at +-{limit:.3g}",
    "sensor_gain": "{where} reads {ratio:.4g} x the true value",
    "sensor_offset": "{where} reads {offset:+.4g} off",
    "delay": "a transport delay of {seconds:.3g} s on {where}",
    "bearing_friction": "an air bearing touching down: {force:.3g} N sliding friction at {where}",
    "table_tilt": "the table tilted by {angle:.3g} rad",
}

SIDED = {  # effects with a level per direction: (positive, negative) parameter names
    "coulomb_friction": ("torque_positive", "torque_negative"),
    "stribeck_friction": ("breakaway_positive", "breakaway_negative"),
    "viscous_friction": ("coefficient", "coefficient_negative"),
}


def physical_place(data: Data, effect: str, where: str) -> str:
    """Where `effect` acts, named as the rig names it: a delay on 'command' is on the command
    channels the recordings carry; anything else is already a rig place."""
    if effect == "delay" and where == "command":
        return commands_recorded(data.rig, data.recordings) or where
    return where


def commands_recorded(rig, recordings) -> str:
    """The rig's command channels that `recordings` carry, joined by '+' ('' if none)."""
    return "+".join(c for c in rig.of_kind("command") if any(c in r.channels for r in recordings))


def _linear(data: Data, joint: str) -> bool:
    """True when `joint` is a slide (its position is recorded in m)."""
    return any(spec.get("joint") == joint and spec["unit"] == "m" for spec in data.rig.channels.values())


def units_at(data: Data, effect: str, where: str) -> dict[str, str]:
    """The effect's parameter units at `where` in the rig's own units."""
    out = {}
    for p in CATALOGUE[effect][1]:
        unit = p.unit
        if unit in ("command unit", "channel unit"):
            unit = data.rig.channels.get(where, {}).get("unit", unit)
        elif CATALOGUE[effect][2] == "joint" and _linear(data, where):
            unit = unit.replace("N m", "N").replace("rad", "m").replace("N/m/m", "N/m")
        out[p.name] = unit
    return out


def direction(effect: str, params: dict) -> str:
    """'positive', 'negative' or 'both', from the final parameters: a level per direction that is
    (nearly) zero one way is one-sided; a band that opens one way only is one-sided."""
    if effect in SIDED:
        a, b = (abs(params.get(n, 0.0)) for n in SIDED[effect])
        if max(a, b) == 0 or abs(a - b) <= 0.1 * max(a, b):
            return "both"
        return "positive" if a > b else "negative"
    if effect == "backlash" and abs(params.get("position", 0.0)) > 0.5:
        return "positive" if params["position"] > 0 else "negative"
    return "both"


def physical_extras(data: Data, effect: str, where: str, params: dict, ranges: dict) -> tuple[dict, dict, dict]:
    """Parameters a rig can state in other physical terms: a command limit as the current it drives
    (the rig's `current_per_unit`, A per command unit)."""
    per = data.rig.channels.get(where, {}).get("current_per_unit")
    if effect == "current_saturation" and per:
        lo, hi = ranges.get("limit", (params["limit"], params["limit"]))
        return {"limit_current": params["limit"] * per}, {"limit_current": "A"}, {"limit_current": [lo * per, hi * per]}
    return {}, {}, {}


def explain(effect: str, where: str, params: dict, units: dict, open_to_neutral: dict[str, float] | None = None) -> str:
    """The finding in words, its parameters with units, and each parameter whose 95 % interval reaches the value at
    which the effect vanishes there (`open_to_neutral`: name -> that value): the data do not rule that out."""
    text = EXPLAIN[effect].format(where=where, **{**{p.name: p.start for p in CATALOGUE[effect][1]}, **params})
    named = [f"{k} {v:.4g} {units.get(k, '')}".rstrip() for k, v in params.items()]
    open_ = [f"{k} = {v:.4g} {units.get(k, '')}".rstrip() for k, v in (open_to_neutral or {}).items()]
    return f"{text} ({', '.join(named)})" + (
        f"; the 95 % interval{'s' if len(open_) > 1 else ''} reach{'' if len(open_) > 1 else 'es'} "
        f"{' and '.join(open_)}: the data do not rule that out" if open_ else "")


def open_to_neutral(data: Data, effect: str, where: str, intervals: dict[str, list[float]]) -> dict[str, float]:
    """Parameters of `effect` at `where` whose 95 % interval includes the value at which the effect vanishes (the
    catalogue's `neutral` in the data's units: no friction one way, a ratio of 1), with that value."""
    return {name: float(value) for name, value in neutral_values(data, {"effect": effect, "where": where}).items()
            if intervals.get(name) and intervals[name][0] <= value <= intervals[name][1]}


def finding(data: Data, effect: dict, ranges: dict, scores: dict, mismatch: list[dict]) -> dict:
    """One report finding from an effect of the final model (`effect`: catalogue entry with its
    parameters), its 95 % intervals and the scores before/after it ({train,held}_{before,after},
    in NRMSE and noise ratio)."""
    name, where = effect["effect"], effect["where"]
    params = {k: float(v) for k, v in effect.items() if k not in ("effect", "where")}
    units = units_at(data, name, where)
    intervals = {k: [float(min(lo, params[k])), float(max(hi, params[k]))] for k, (lo, hi) in ranges.items() if k in params}
    extra, extra_units, extra_intervals = physical_extras(data, name, where, params, ranges)
    place = physical_place(data, name, where)
    reaching = open_to_neutral(data, name, where, intervals)
    evidence = "; ".join(f"{w['channel']} off by {w['score']:.2f} of its spread ({w['noise_ratio']:.1f} x its noise) "
                         f"in {w['recording']} {w['t_start']:.2f}-{w['t_end']:.2f} s ({w['regime']})" for w in mismatch[:3])
    s = scores
    return {
        "effect": name, "where": place, "direction": direction(name, params),
        "parameters": {**params, **extra}, "units": {**{k: units.get(k, "") for k in params}, **extra_units},
        "intervals": {**intervals, **extra_intervals},
        "explanation": explain(name, place, {**params, **extra}, {**units, **extra_units}, reaching),
        "interval_reaches_neutral": sorted(reaching),
        "evidence": (f"residual: {evidence}. " if evidence else "")
        + f"With the findings: training NRMSE {s['train_before']:.4f} -> {s['train_after']:.4f}, validation "
          f"{s['held_before']:.4f} -> {s['held_after']:.4f} ({s['ratio_before']:.2f} -> {s['ratio_after']:.2f} x the noise); "
          f"without this one in the final model validation would be {s['held_without']:.4f} ({s['ablated']:.2f} x the noise).",
        "delta_fit": s["held_without"] - s["held_after"],  # validation NRMSE this finding removes from the final model
    }


def indistinct(data: Data, effect: dict, intervals: dict[str, tuple[float, float]]) -> bool:
    """Whether the 95 % interval of every parameter of `effect` that has a value at which the effect vanishes
    (the catalogue's `neutral`: no friction, a ratio of 1) includes that value: the data cannot tell the finding
    from no effect at all. False for an effect without such a parameter (a backlash, a compliance, a limit) or
    without intervals."""
    named = [p.name for p in CATALOGUE[effect["effect"]][1] if p.neutral is not None and intervals.get(p.name)]
    return bool(named) and set(named) <= set(open_to_neutral(data, effect["effect"], effect["where"], intervals))


def canonical_form(model: Model, ranges: dict[int, dict]) -> tuple[Model, dict[int, dict]]:
    """The model's effects in their canonical form (effects.canonical: the same physics), each interval moved
    by the same sign and shift as its parameter (effects.canonical_moves)."""
    moved = {}
    for i, effect in enumerate(model.effects):
        moves = canonical_moves(effect)
        moved[i] = {}
        for name, (lo, hi) in ranges.get(i, {}).items():
            sign, shift = moves.get(name, (1.0, 0.0))
            a, b = sign * lo + shift, sign * hi + shift
            moved[i][name] = (min(a, b), max(a, b))
    return Model([canonical(e) for e in model.effects], dict(model.parameters)), moved
