"""Screening: which catalogue effect's signature the residual carries.

Contract: `candidates` lists the (effect, place) pairs the rig description allows that the recordings can show
(`excited`). `signatures` simulates each once per parameter (and probe level) around the current model, half as fine
as the model (SCREEN_FINER; a sensor's gain or offset on a channel no controller reads unsimulated: sensors.py);
`screen` scores each by how much of the training residual its signature explains beyond refitting the rig's
parameters and the effects found so far (`with_findings`), and keeps that linear estimate as its start;
`rescreen.rescreen` checks the best by simulation at that estimate; `selection.shortlist` names the candidates to
fit in full (effect_fit.fit_candidate), and `concealed` one more: the best by the same signatures against the
datasheet model's residual, where the refit took an effect up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import lsq_linear

from ..effects import CATALOGUE
from ..recording import Recording
from .data import Data, Model
from .fitting import Slot, effect_slots_of, jacobian, value_of
from .motion import scale_of
from .runner import evaluator, in_units
from .sensors import fed_back, sensor_signature

STIFFER_PROBE = -10.0  # x (start - neutral): a `wide` log-scaled ratio (a link's stiffness) is also probed on
# the other side of neutral (0.9 -> 2.0): a stiffer link than the datasheet's is as likely as a softer one
SWITCH_LEVELS = (1.0, 0.1, 0.01)  # x start of a switch candidate's log-scaled size (width, stiffness, ...)
LIMIT_LEVELS = (1.0, 0.75, 0.5, 0.3)  # x start of a switch candidate's linear size (a command limit): a limit
# acts only where the command passes it, so one probe at the start (0.7 x the peak) says nothing of one at 0.4
SMALL_PROBE = 0.25  # x (start - neutral): a friction-like level is probed here too - stick-slip makes an effect's
# signature depend on its size (seed 48, a laser hub's Coulomb friction of 0.045 N m, a quarter of the probe at start:
# screened 1 % and was never fitted, read as viscous friction; probed at this level too it screens 18 % and is found)
LARGE_PROBE = 4.0  # x (start - neutral): friction-like levels and `wide` parameters are probed
# small and large, since a small dry friction can move a closed loop the other way from a large
# one (stick-slip is not linear) and a mode frequency goes with the square root of a stiffness
MIN_GAIN = 0.02  # a finding's training noise ratio must fall by this fraction per fitted parameter (validate.gains: the
# score's charge per parameter); a simpler law at the leader's place is fitted if it screens at this per parameter
CURVE_LAWS = ("coulomb_friction", "stribeck_friction", "viscous_friction")  # effects that change a joint's friction
# only through its sliding curve F(v) (friction.exponential): each other's nearest rivals at one joint (shortlist,
# laws.one_law)
SCREEN_FINER = 0.5  # signatures are simulated this many times as fine as the model (half the segments, twice the
# step where that divides the control period): a screening column is a difference of two simulations at one
# discretisation, which cancels most of its error; the rescreen and the fits then simulate as fine as the model
EXTRAPOLATE = 2.0  # a log-scaled parameter's linear estimate goes at most this far beyond its farthest probe
RIPPLE_CYCLES = (0.6, 1.0, 1.5, 2.0, 3.0)  # a ripple a sin(2 pi x / period + phase) is also screened at these many
# cycles over the motion's range, each in quadrature (phase 0 and pi/2: at a given period the ripple is linear in the
# a sin + b cos it is): at its start alone (a third of a cycle, phase 0) a Watflex elbow ripple of 1.73 N m with a period
# of 1.83 ranges (0.55 cycles) at phase -1.76 rad (a cosine) screened below the top eight and was never fitted (seed 57:
# 88 x the noise left). Half a cycle apart at most, a sine at the nearest screened period still matches it to ~0.6.
QUADRATURE = "quadrature"  # a ripple's signature at phase pi/2: its column's coefficient is b (its amplitude's slot)


@dataclass
class Candidate:
    """A catalogue effect at one place: its parameters (physical units) with slots, and its
    signature: the change of the training residual per unit of each parameter that has a
    neutral value, or (a 'switch') the change the whole effect at its start values makes.
    `wide` parameters are probed at two levels (start and LARGE_PROBE x start), effort-scaled ones at a third
    below (SMALL_PROBE), a `wide` log-scaled ratio on the other side of neutral (STIFFER_PROBE)."""

    effect: str
    where: str
    start: dict[str, float]
    slots: dict[str, Slot]
    neutral: dict[str, float]  # parameters with a value at which the effect vanishes
    levels: tuple[float, ...] = (1.0,)
    signature: dict[float, dict[str, np.ndarray]] = field(default_factory=dict)  # level -> parameter -> column
    estimate: dict[str, float] = field(default_factory=dict)  # linear estimate from the best signature
    gain: float = 0.0  # screening: fraction of the training cost the signature explains
    quanta: dict[str, float] = field(default_factory=dict)  # parameters acting in whole steps: the step
    checked: float | None = None  # rescreen: the gain simulated at (and half-way to) the estimate
    periodic: str = ""  # a ripple's periodic parameter (effects.Param.periodic), with the values screened in quadrature
    periods: tuple[float, ...] = ()  # (RIPPLE_CYCLES), besides its start
    shape: str = ""  # a shape parameter with `variants` (effects.Param): the neutral ones are probed at each value too,
    # at each level: stick-slip makes a friction's signature bend with its size and its shape together (seed 107)
    variants: tuple[float, ...] = ()  # its values (physical units) besides its start
    ladder: str = ""  # a `wide` log-scaled parameter with a neutral (a link's stiffness): rescreen's `ladder`

    def model(self, base: Model, values: dict[str, float]) -> Model:
        return Model(base.effects + [dict(effect=self.effect, where=self.where, **values)], dict(base.parameters))

    def probes(self) -> dict[tuple[float, str], dict[str, float]]:
        """Parameter sets to simulate: (level, parameter) -> values, one per neutral parameter
        and level, or (1, "switch") with every parameter at its start."""
        if not self.neutral:  # a log-scaled size is probed over two decades below its start, a linear one down to 0.3 x
            first = next(iter(self.start))
            slot = self.slots[first]
            levels = SWITCH_LEVELS if slot.log else LIMIT_LEVELS
            return {(level, "switch"): {**self.start, first: float(np.clip(self.start[first] * level, slot.low, slot.high))}
                    for level in levels}
        at_zero = {**self.start, **self.neutral}
        probes = {(level, name): {**at_zero, name: self.probe(name, level)}
                  for level in self.levels for name in self.neutral}
        for period in self.periods:  # keyed ("period", its value): screened as a variant of its own, like a level
            for name, phase in (("amplitude", 0.0), (QUADRATURE, math.pi / 2)):
                probes[(("period", period), name)] = {**at_zero, "amplitude": self.probe("amplitude"), "phase": phase,
                                                      self.periodic: period}
        for value in self.variants:  # keyed ("shape", its value, the level), likewise
            probes.update({(("shape", value, level), name): {**at_zero, self.shape: value,
                                                             name: self.probe(name, level)}
                           for level in self.levels for name in self.neutral})
        return probes

    def probe_step(self, level, name: str) -> float:
        """How far from neutral the probe (level, name) moves its parameter: the column's divisor."""
        if name == "switch":
            return 1.0
        if isinstance(level, tuple) and level[0] == "shape":  # a shape variant: each neutral parameter at a level
            return self.probe(name, level[2]) - self.neutral[name]
        if isinstance(level, tuple):  # a ripple's period variant: its amplitude at its start, either quadrature
            return self.probe("amplitude") - self.neutral["amplitude"]
        return self.probe(name, level) - self.neutral[name]

    def ripple(self, a: float, b: float) -> dict[str, float]:
        """A ripple's a sin + b cos (its amplitude's unit each) as its amplitude, within its slot, and phase (rad)."""
        amp = self.slots["amplitude"]
        return {"amplitude": float(np.clip(math.hypot(a, b), amp.low, amp.high)), "phase": math.atan2(b, a)}

    def probe(self, name: str, level: float = 1.0) -> float:
        """The value a neutral parameter is probed at: level x its start (or 2 % of its range)
        off neutral, within its bounds."""
        slot = self.slots[name]
        step = self.start[name] - self.neutral[name] or 0.02 * (slot.high - slot.low)
        return float(np.clip(self.neutral[name] + level * step, slot.low, slot.high))


def make_candidate(data: Data, effect: str, where: str) -> Candidate:
    _, params, _ = CATALOGUE[effect]
    start, slots, neutral = {}, {}, {}
    for p in params:
        size = scale_of(data, p, where)
        start[p.name] = p.start * size
        slots[p.name] = Slot(("effect", -1, p.name), p.low * size, p.high * size, p.log)
        if p.neutral is not None:
            neutral[p.name] = p.neutral * size
    levels = (1.0, LARGE_PROBE) if any(p.scale == "effort" or p.wide for p in params) else (1.0,)
    if any(p.scale == "effort" for p in params):
        levels = (SMALL_PROBE,) + levels
    ladder = next((p.name for p in params if p.wide and p.log and p.neutral is not None), "")
    if ladder:
        levels += (STIFFER_PROBE,)
    quanta = {p.name: p.quantum for p in params if p.quantum > 0}
    ripple = next((p for p in params if p.periodic), None)
    periodic, periods = (ripple.name if ripple else ""), ()
    if ripple:  # its slot is in motion ranges
        motion = scale_of(data, ripple, where)
        periods = tuple(motion / n for n in RIPPLE_CYCLES if slots[periodic].low <= motion / n <= slots[periodic].high)
    shaped = next((p for p in params if p.variants), None)
    shape, variants = "", ()
    if shaped:  # a shape the signature depends on beyond a linear picture: its variants within its slot
        shape = shaped.name
        variants = tuple(float(np.clip(start[shape] * f, slots[shape].low, slots[shape].high)) for f in shaped.variants)
    return Candidate(effect, where, start, slots, neutral, levels, quanta=quanta, periodic=periodic, periods=periods,
                     ladder=ladder, shape=shape, variants=variants)


def excited(data: Data, effect: str, where: str) -> bool:
    """False when the recordings cannot show `effect` at `where`: a joint locked or still in every
    recording, a command channel that is constant, a sensor channel not compared."""
    kind = CATALOGUE[effect][2]
    compared = {c for chans in data.channels for c in chans}
    if kind == "joint":
        angles = [c for c, spec in data.rig.channels.items() if spec["kind"] == "measured"
                  and (c == f"{where}_angle" or spec.get("joint") == where)]
        commands = [c for c in data.rig.of_kind("command") if data.rig.channels[c].get("joint") == where]
        moving = [c for c in angles + commands if any(c in chans for chans in data.channels)]
        return bool(moving) or not (angles or commands)
    if kind == "command" and effect != "delay":
        return where in compared
    if kind == "channel" or (effect == "delay" and where != "command"):
        return where in compared
    return True


def candidates(data: Data, have: list[dict]) -> list[tuple[str, str]]:
    """(effect, where) pairs the rig allows, the recordings can show, and the model does not have yet."""
    taken = {(e["effect"], e["where"]) for e in have}
    return [(effect, where) for effect, places in data.rig.effects.items() for where in places
            if (effect, where) not in taken and excited(data, effect, where)]


def signatures(data: Data, runner, base: Model, sims: list[Recording], r0: np.ndarray, cands: list[Candidate],
               per: np.ndarray) -> None:
    """Fill each candidate's signature columns in the units `per` turns spread units into (`data.unit_change`: noise
    units, as `r0`): one simulation per probe, in parallel, SCREEN_FINER x as fine as the model (`base` too, so each
    column is a difference at one discretisation; at the runner's fidelity where that is as coarse already); a probe
    that diverges there is simulated at the runner's fidelity, against `r0`."""
    looped = fed_back(data)
    jobs, owners = [], []
    for cand in cands:
        if cand.effect in ("sensor_gain", "sensor_offset") and cand.where not in looped:
            cand.signature = {1.0: {n: v / per for n, v in sensor_signature(data, sims, cand.effect, cand.where).items()}}
            continue
        for key, values in cand.probes().items():
            jobs.append(cand.model(base, values))
            owners.append((cand, key))
    if not jobs:
        return
    full = in_units(evaluator(runner), per)
    factor = min(1.0, SCREEN_FINER / runner.fidelity)  # relative to the runner's: no coarser than SCREEN_FINER
    coarse = in_units(evaluator(runner, finer=factor), per)([base] + jobs) if runner.refinable(factor) else []
    if coarse and coarse[0] is not None:
        runs, against = coarse[1:], [coarse[0]] * len(jobs)
    else:
        runs, against = [None] * len(jobs), [r0] * len(jobs)
    again = [k for k, r in enumerate(runs) if r is None]
    for k, r in zip(again, full([jobs[k] for k in again]) if again else []):
        runs[k], against[k] = r, r0
    for (cand, (level, name)), r, r_base in zip(owners, runs, against):
        if r is None:
            continue  # this probe diverges: no signature at this level
        cand.signature.setdefault(level, {})[name] = (r - r_base) / cand.probe_step(level, name)


def screen(cands: list[Candidate], columns: np.ndarray, slots: list[Slot], at: np.ndarray, r0: np.ndarray) -> None:
    """Score each candidate by how much of the training residual its signature explains beyond
    what refitting `slots` explains (bounded linear least squares on their `columns`, from their values `at`:
    the rig's parameters and the findings so far, `with_findings`), and keep the linear estimate of its
    parameters as the start of its fit."""
    cost0 = float(r0 @ r0) or 1.0
    lo = np.array([s.low for s in slots]) - at
    hi = np.array([s.high for s in slots]) - at

    def solve(columns, low, high):
        norms = np.linalg.norm(columns, axis=0)
        norms[norms == 0] = 1.0
        result = lsq_linear(columns / norms, -r0, bounds=(low * norms, high * norms))
        return float(np.sum((r0 + columns @ (result.x / norms)) ** 2)), result.x / norms

    cost_rig = solve(columns, lo, hi)[0] if slots else cost0
    for cand in cands:
        cand.gain, cand.estimate = -math.inf, dict(cand.start)
        for level, signature in cand.signature.items():
            names = list(signature)
            cols = np.column_stack([columns] + [signature[n][:, None] for n in names])
            own = ["amplitude" if n == QUADRATURE else n for n in names]  # a quadrature's coefficient is an amplitude
            low = [cand.slots[n].low - cand.neutral[n] if n != "switch" else 0.0 for n in own]
            high = [cand.slots[n].high - cand.neutral[n] if n != "switch" else 3.0 for n in own]
            cost, x = solve(cols, np.r_[lo, low], np.r_[hi, high])
            if (cost_rig - cost) / cost0 <= cand.gain:
                continue
            cand.gain = (cost_rig - cost) / cost0
            cand.estimate = dict(cand.probes()[(level, "switch")]) if "switch" in signature else dict(cand.start)
            coefficients = dict(zip(names, x[len(slots):]))
            if QUADRATURE in coefficients:  # a ripple at one period: a sin + b cos is an amplitude and a phase
                a, b = coefficients.pop("amplitude"), coefficients.pop(QUADRATURE)
                cand.estimate.update({cand.periodic: level[1], **cand.ripple(a, b)})
            if isinstance(level, tuple) and level[0] == "shape":
                cand.estimate[cand.shape] = level[1]
            for n, a in coefficients.items():
                if n != "switch":
                    slot = cand.slots[n]
                    if slot.log:  # a ratio acts nonlinearly: its signature is linear near its probe only
                        reach = EXTRAPOLATE * abs(cand.probe_step(level, n))
                        a = float(np.clip(a, -reach, reach))
                    value = float(np.clip(cand.neutral[n] + a, slot.low, slot.high))
                    cand.estimate[n] = value if value > 0 or not slot.log else cand.start[n]


def with_findings(evaluate, data: Data, model: Model, r0: np.ndarray, rig_columns: np.ndarray, free: list[Slot],
                  at: np.ndarray) -> tuple[np.ndarray, list[Slot], np.ndarray]:
    """The rig's columns, slots and values (`screen`'s arguments) with those of the effects found so far: each
    found parameter's Jacobian column at `model` (one simulation each; `evaluate`'s units per unit of its value, a
    log-scaled one's divided by its value) on a linear slot within its bounds, so the screening refits the findings
    to first order beside the rig's parameters, as the candidate fits refit them. Held at their values, a finding
    that took up part of a second effect makes that effect screen worse than none (seed 55: a current limit behind
    an actuator gain found at 0.651 for 0.742 screened at -2.6 % in round 2 and was never fitted)."""
    found = effect_slots_of(data, model)
    if not found:
        return rig_columns, free, at
    values = np.array([value_of(model, s) for s in found])
    J = jacobian(evaluate, model, found, np.array([s.to_internal(v) for s, v in zip(found, values)]), r0)
    per_value = np.array([v if s.log else 1.0 for s, v in zip(found, values)])  # d/du = x d/dx where u = log x
    linear = [Slot(s.where, s.low, s.high) for s in found]
    return np.column_stack([rig_columns, J / per_value]), free + linear, np.concatenate([at, values])


def concealed(cands: list[Candidate], columns: np.ndarray, slots: list[Slot], at: np.ndarray, r: np.ndarray,
              listed: list[Candidate]) -> Candidate | None:
    """The candidate the same signatures put first against `r`, the residual of the rig's parameters at `at`
    (the datasheet's: the nominal model), when `shortlist` did not list it and it screens there at MIN_GAIN per
    parameter; else None. The refit moves the rig's parameters to mimic what it can of a missing effect, and
    around the refit model the effect's signature then adds to what the moved parameter already did: seed 57,
    an elbow's joint compliance of 2797 N m/rad that a link stiffness 0.958 x the datasheet's took up screened
    fifth at 8 % around the refit, was never fitted, and two strain bridges' gains x 0.956 were found instead;
    against the nominal residual it screens first (17 %) and, fitted, reaches 0.68 x the noise on validation at
    2702 N m/rad with the stiffness back at 1.00 x. `screen` is linear in the rig's columns, which were taken at
    the nominal model, so this look costs no simulation."""
    if not cands:
        return None
    copies = [replace(c) for c in cands]  # `screen` sets their gain and estimate, and leaves the originals' alone
    screen(copies, columns, slots, at, r)
    k = max(range(len(copies)), key=lambda i: (copies[i].gain, copies[i].effect, copies[i].where))
    if copies[k].gain < MIN_GAIN * len(copies[k].slots) or any(cands[k] is c for c in listed):
        return None
    return cands[k]
