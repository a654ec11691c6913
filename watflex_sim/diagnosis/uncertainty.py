"""Uncertainty: 95 % intervals of the final model's parameters, in physical units.

Contract: `final_intervals(data, runner, model, sims)` returns effect index -> parameter -> (low, high), every
interval within the parameter's bounds. It joins what each source of error would move an estimate by: the data's
noise (the Jacobian, each effect parameter's column from the gentler side of a cliff (`reach.gentler_side`), widened
for serial correlation and for the rig's noise fed back in closed loop: `fitting.intervals`), the split of the data
(the estimate from the training half alone), our own discretisation (`discretisation_error`, and
`fitting.intervals`' bound on the bias it can cause) and a cost that stick-slip makes rough or a valley bends
(`reach.slice_reach`, a linearised profile: the estimate is known only up to where the cost's smooth trend, the
other parameters following, rises above its roughness), and along a ripple's period, where the cost's valley bends
past any Jacobian's reach, a profile (period.profile_reach), and along a shape parameter (a time constant, a
Stribeck velocity) or a quantised one (a delay) theirs (level.level_reach), and the split between the effects and
the rig's parameters they act like, followed to the datasheet's values as far as the discretisation lets the data
prefer it (`reach.split_reach`), and an effect size's neutral value where the data are as near the model's noisy
realisations with it there (`realisation_reach`). Knob-tied pairs (an effect's ratio and the rig parameter turning
the same knob) share one Jacobian column, and the ratio's interval also spans the datasheet's split of their product
(`nominal_split`).
"""
from __future__ import annotations

import math

import numpy as np

from ..effects import CATALOGUE
from ..recording import Recording
from .data import Data, Model, residual_vector, unit_change
from .fitting import Slot, effect_slots_of, intervals, jacobian, rig_slots, value_of
from .level import level_reach, levels
from .motion import neutral_values
from .period import neutral_others, periodic_name, profile_reach
from .reach import gentler_side, slice_reach, split_reach
from .runner import Runner, evaluator, in_units
from .tolerance import knob_partner

SPLIT_WIDTH = 4.0  # x |all-data - training-only estimate|: the least half-width of a 95 % interval (final_intervals)
FINER = 2  # the discretisation error is judged against this many times the segments and a step this much finer
NOISE_SEED = 7  # fixed: the closed-loop noise floor is the same on every run
DISCRETISATION_REACH = 2.0  # x what a FINER x finer model changes in the residual: the error against a converged
# model (a first-order error halves with each doubling, 1 + 1/2 + 1/4 ... = 2)
REPLICATES = 8  # noise replicates of the final model behind the intervals (seeds NOISE_SEED + 1 ...)
REPLICATE_SEEDS = tuple(NOISE_SEED + 1 + k for k in range(REPLICATES))


def tolerance_sd(slot: Slot) -> float:
    """Prior sd (internal units) of a rig parameter's slot: a uniform spread over its +-tolerance has
    sd tolerance / sqrt 3; inf (no prior) for an effect's parameter."""
    return slot.span() / 2 / math.sqrt(3) if slot.where[0] == "param" else math.inf


def tolerance_centre(slot: Slot) -> float:
    """Prior mean (internal units) of a rig parameter's slot: the datasheet's value, the centre of its
    +-tolerance; nan (no prior) for an effect's parameter."""
    return slot.to_internal((slot.low + slot.high) / 2) if slot.where[0] == "param" else math.nan


def tie_knob_columns(data: Data, model: Model, slots: list[Slot], J: np.ndarray) -> np.ndarray:
    """J with the column of each rig parameter that turns the same knob as an effect's ratio (knob_partner)
    derived from the effect's column: the residual depends on ratio x e only, so d r / d e =
    d r / d(ratio) x ratio / e (d r / d log ratio / e for a log-scaled ratio) - one column, not two
    finite differences of unequal steps that would make the pair look separable."""
    J = J.copy()
    for i, slot in enumerate(slots):
        partner = knob_partner(data, model.effects[slot.where[1]]) if slot.where[0] == "effect" else None
        j = next((j for j, s in enumerate(slots) if partner and s.where == ("param", partner)), None)
        if j is not None and slot.name == "ratio":
            ratio, e = value_of(model, slot), value_of(model, slots[j])
            J[:, j] = J[:, i] * (1.0 if slot.log else ratio) / e
    return J


def final_intervals(data: Data, runner: Runner, model: Model, sims: list[Recording], trained: Model | None = None) -> dict[int, dict[str, tuple[float, float]]]:
    """95 % intervals of every effect parameter of the final model: effect index -> parameter -> (low, high).
    A quantised parameter (a delay) is good to half its step. The Jacobian's interval is over every
    effect parameter and rig parameter together, those at a bound too (a friction side near 0 that
    trades off with a viscous term widens it), the rig's with their tolerance as a prior (the sd of a uniform
    spread over +-tolerance, tolerance / sqrt 3, about the datasheet's value). An effect that turns a rig
    parameter's knob (a link's stiffness change and its EI) has one Jacobian column for both, so their product
    alone is fixed by the data: finite differences of unequal steps (10 % for a log-scaled ratio, 0.5 % for a
    +-5 % tolerance) made the two look separable (seed 6: a link stiffness 4.8 % off with an interval of
    +-0.05 %, the EI at its bound).
    Each effect parameter's column is the gentler of a step either way (`gentler_side`: one over a cliff of the
    cost claims a false precision). The Jacobian and the residual are in final_refit's units (a channel's noise,
    or its misfit in `sims`, the final model's simulations, where larger), and REPLICATES simulations of the
    final model with the rig's noise on (other seeds) show how far that noise moves the estimate and
    which way (`fitting.intervals`): in closed loop, noise fed back moves the rig, which no white-noise
    interval describes. It is widened to SPLIT_WIDTH x the distance to the same parameter fitted on the
    training half alone (`trained`): on a rough (stick-slip) cost the fit's own scatter dominates; for
    unbiased estimates that distance is |N(0, sd)| of the all-data estimate, and SPLIT_WIDTH = 4 covers
    84 % from that one sample (2/pi atan 4). And it reaches as far as our own discretisation can bias the
    estimate (`discretisation_error`). A ripple's period, a shape and a quantised parameter are profiled (the others
    re-solved at each value): their intervals reach as far along the valley as the data cannot tell from its best
    point (seed 59, watflex-1e32daae: a time constant of 0.58 s with [0.37, 0.90] from the Jacobian, [0.21, 2.1]
    profiled, the truth 0.98; a delay's steps beside the one found). Last, a size reaches its neutral value where the
    data are as near one of the noisy realisations of the model with it there as to the model's own
    (`realisation_reach`: in closed loop, what the rig's noise does to a rig at rest can mimic a friction)."""
    out: dict[int, dict] = {}
    for i, effect in enumerate(model.effects):
        for p in CATALOGUE[effect["effect"]][1]:
            if p.quantum and p.name in effect:
                out.setdefault(i, {})[p.name] = (effect[p.name] - p.quantum / 2, effect[p.name] + p.quantum / 2)
    if not model.effects:
        return out
    effect_slots = effect_slots_of(data, model)
    slots = effect_slots + rig_slots(data)
    per = unit_change(data, "all", sims=sims)  # the units final_refit fits in
    evaluate = in_units(evaluator(runner, "all"), per)
    r = evaluate([model])[0]
    if r is None:
        return out
    u = np.array([s.to_internal(value_of(model, s)) for s in slots])
    J = gentler_side(evaluate, model, slots, u, r, jacobian(evaluate, model, slots, u, r), len(effect_slots))
    J = tie_knob_columns(data, model, slots, J)
    prior = [tolerance_sd(s) for s in slots]
    noisy = runner.simulate_seeds(model, list(REPLICATE_SEEDS))
    replicates = [residual_vector(data, noisy_sims, "all") / per - r for noisy_sims in noisy if noisy_sims is not None]
    error = discretisation_error(data, runner, model, r, per)
    centre = [tolerance_centre(s) for s in slots]
    biased = intervals(slots, model, J, r, prior, replicates, centre, error)
    for k, (low, high) in intervals(slots, model, J, r, prior, replicates, centre).items():
        slot = slots[k]
        if slot.where[0] == "effect":
            value = slot.to_internal(value_of(model, slot))
            if trained is not None and len(trained.effects) == len(model.effects):
                reach = SPLIT_WIDTH * abs(value - slot.to_internal(value_of(trained, slot)))
                low = min(low, max(slot.to_value(value - reach), slot.low))
                high = max(high, min(slot.to_value(value + reach), slot.high))
            # the slice probes at multiples of the data's own interval: the discretisation's reach joins after it
            # (probed 8 x that far, a cost's curvature reads as roughness: seed 53's laser backlash, 3 % off, got
            # [1.4e-7, 1.4e-4] rad)
            low, high = slice_reach(evaluate, model, slots, k, r, low, high, J)
            low, high = min(low, biased[k][0]), max(high, biased[k][1])
            low, high = nominal_split(data, model, slot, low, high)
            out.setdefault(slot.where[1], {})[slot.name] = (float(low), float(high))
    for i, effect in enumerate(model.effects):  # a ripple's period and what trades with it: their profile
        if periodic_name(effect):
            widen(out, slots, profile_reach(evaluate, model, i, slots, J, r, replicates, error, neutral_others(data, effect)))
        for name, bounds, quantum in levels(data, effect):  # a shape or a quantised parameter and what trades with it
            reach, kept = level_reach(evaluate, model, i, name, bounds, quantum, slots, J, r, replicates, error)
            widen(out, slots, reach)
            if quantum and kept:
                low, high = out[i][name]
                out[i][name] = (min(low, min(kept) - quantum / 2), max(high, max(kept) + quantum / 2))
    widen(out, slots, split_reach(evaluate, model, slots, len(effect_slots), r, J, error))
    realisation_reach(data, runner, model, per, [float((r + e) @ (r + e)) for e in replicates], out)
    return out


def realisation_reach(data: Data, runner: Runner, model: Model, per: np.ndarray, costs: list[float],
                      out: dict[int, dict[str, tuple[float, float]]]) -> None:
    """Widen `out` to each effect size's neutral value (where its effect vanishes: a friction side's 0) wherever the
    data are as near one of the model's realisations with the rig's noise on and that size at neutral (REPLICATES
    seeds, the final model's own) as they are on average to the final model's own (`costs`: |r|^2 of those, in
    `per`'s units). In closed loop the rig's noise fed back moves a rig at rest, a friction one way only turns that
    into a creep, and where a realisation creeps or not decides where an arm stops: a noise-free re-simulation of
    the truth then fits worse than a biased estimate, and no linearised replicate sees it (seed 113's
    laser_arm-b895983b, a one-way hub Coulomb friction of 0 / 0.0984 N m on 2 mrad steps: fitted 0.027 [0.023, 0.031]
    / 0.098; the truth noise-free |r|^2 9,694, the estimate 5,446, replicate moves +-0.0005 N m; with the noise on,
    8,245-8,906 in 3 of 6 seeds of the truth and 9,010-9,862 in all 6 of the estimate's)."""
    if len(costs) < 2:
        return
    reference = float(np.mean(costs))
    sizes = [(i, name, neutral) for i, effect in enumerate(model.effects)
             for name, neutral in neutral_values(data, effect).items()
             if name in out.get(i, {}) and not out[i][name][0] <= neutral <= out[i][name][1]]
    if not sizes:
        return
    moved = [Model([{**e, name: neutral} if j == i else e for j, e in enumerate(model.effects)], dict(model.parameters))
             for i, name, neutral in sizes]
    every = runner.simulate_runs([(m, seed) for m in moved for seed in REPLICATE_SEEDS])  # one lockstep call
    for k, (i, name, neutral) in enumerate(sizes):
        runs = [residual_vector(data, sims, "all") / per
                for sims in every[k * len(REPLICATE_SEEDS):(k + 1) * len(REPLICATE_SEEDS)] if sims]
        if runs and min(float(x @ x) for x in runs) <= reference:
            low, high = out[i][name]
            out[i][name] = (min(low, neutral), max(high, neutral))


def widen(out: dict[int, dict], slots: list[Slot], reach: dict[int, tuple[float, float]]) -> None:
    """Each interval in `out` (effect index -> parameter -> (low, high)) widened to `reach` (slot index -> (low,
    high)); a parameter without one yet gets the reach."""
    for k, (low, high) in reach.items():
        at = out.setdefault(slots[k].where[1], {})
        was = at.get(slots[k].name, (low, high))
        at[slots[k].name] = (float(min(was[0], low)), float(max(was[1], high)))


def nominal_split(data: Data, model: Model, slot: Slot, low: float, high: float) -> tuple[float, float]:
    """Interval (low, high) of a knob-tied effect's ratio joined with the same interval moved to the rig
    parameter's nominal value: the data fix the product ratio x e only (tie_knob_columns), so where the fit split
    it is arbitrary within e's tolerance, and the interval about the fit's split is one of many; about e = 1
    (the datasheet's value, the centre of its tolerance) is the other end of the range (seed 47: a link stiffness
    x3.17 on a rig with link 2's EI at 0.957 was found at x2.979 with the EI refit at 1.030, interval [2.819,
    3.147]; moved to EI 1, [2.904, 3.242]). Any other slot: unchanged."""
    partner = knob_partner(data, model.effects[slot.where[1]]) if slot.name == "ratio" else None
    if partner is None:
        return low, high
    e = model.parameters.get(partner, 1.0)
    return max(min(low, low * e), slot.low), min(max(high, high * e), slot.high)


def discretisation_error(data: Data, runner: Runner, model: Model, r: np.ndarray, per: np.ndarray) -> np.ndarray | None:
    """What our own discretisation leaves in the residual `r` of `model` (final_intervals' units: per): DISCRETISATION_REACH
    x the change the model simulated FINER x finer (segments, step) makes at the same parameters; None when the rig
    has no discretisation to refine or the finer model diverges. Data from a finer simulator or a continuum (a real
    rig) differ from ours by about that, which no amount of data averages away; `fitting.intervals` bounds the bias it
    can cause. It replaced a refit on the finer model (4 Levenberg-Marquardt steps), whose move stopped short in
    valleys (seed 51: an elbow Coulomb friction 7 % low, traded against the rig's friction scale, interval +-0.7 %)."""
    if not any(data.discretisation):
        return None
    sims = runner.simulate(model, finer=FINER)
    return None if sims is None else DISCRETISATION_REACH * (residual_vector(data, sims, "all") / per - r)

