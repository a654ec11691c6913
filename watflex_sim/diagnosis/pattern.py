"""The pattern search that carries a fit on where stick-slip makes its cost rough.

Contract: `compass` is the search itself (each slot a step up and down, the steps halved where none gains);
`pattern_search` runs it over given slots on the training cost in noise units until training and validation are
within the noise (the verdict's own test) or the noise resolves no step; `compass_worth` says when a model is near
enough the noise to be worth it. The refit of the rig's parameters (refit.refit_nominal) uses it after
Levenberg-Marquardt; `pattern_polish` carries the final model on by it (settle, before the verdict).
"""
from __future__ import annotations

import math

import numpy as np

from ..recording import Recording
from .data import Data, Model, residual_vector
from .fitting import (Slot, at_internal, effect_slots_of, huber_cost, huber_threshold, internal_start, rig_slots,
                      value_of)
from .refine import in_noise
from .runner import Runner
from .scores import fit_scores
from .validate import NOISE_MARGIN, within, within_noise

COMPASS_SWEEPS = 14  # at most this many pattern-search sweeps after the refit's Levenberg-Marquardt (2 simulations
# per parameter each); it stops once training and validation are within the noise, or once no step changes the
# cost by CHI2_RESOLUTION or by what a move must gain (compass; 6 sweeps halved the steps to
# 0.4 % of a tolerance at best: a clean Watflex case's strain bridge is 1.3 x its noise at link 2's EI 0.04 % off)
COMPASS_REACH = 3.0  # x NOISE_MARGIN: only a refit within this of the noise gets the pattern search; one further
# off is missing physics, which a harder refit only pushes into the rig's parameters (a 0.33 kg Watflex payload: the
# refit at 11.7 x the noise with elbow inertia at its bound and link 2's EI 4 % low, where its fits then started)
COMPASS_GAIN = 1e-3  # a pattern-search move must lower the cost by this share of it
CHI2_RESOLUTION = 0.5  # Huber cost in noise units (chi-square / 2): a change below this the noise does not resolve


def compass_worth(train: dict) -> bool:
    """Whether the refit's training scores ask for the pattern search: short of the noise on some channel,
    but within COMPASS_REACH x the margin (further off, the rig's parameters would only absorb missing physics)."""
    return not within(train) and train["noise_ratio"] <= COMPASS_REACH * NOISE_MARGIN


def pattern_search(data: Data, runner: Runner, evaluate, model: Model, free: list[Slot],
                   sims: list[Recording]) -> tuple[Model, list[Recording] | None]:
    """compass over `free` from `model` (simulated as `sims`) on the training cost `evaluate` gives (noise
    units, as residual_vector's), stopping once training and validation are within the noise (the verdict's own test:
    a lower cost then changes no verdict); the model it ends at and its simulations (None: they diverged)."""
    checked = {}

    def within_both(trial: Model) -> bool:
        checked.update(model=trial, sims=runner.simulate(trial))
        return checked["sims"] is not None and within_noise(fit_scores(data, checked["sims"], "train"),
                                                            fit_scores(data, checked["sims"], "held_out"))
    moved = compass(evaluate, model, free, [value_of(model, s) for s in free], residual_vector(data, sims, unit="noise"),
                    COMPASS_SWEEPS, resolution=CHI2_RESOLUTION, enough=within_both)
    # the last move judged is where the search ended unless a later move followed: its simulations serve
    return moved, checked["sims"] if checked.get("model") == moved else runner.simulate(moved)


def pattern_polish(data: Data, runner: Runner, model: Model, sims: list[Recording], say,
                   what: str = "the final model") -> tuple[Model, list[Recording]]:
    """The final model (`what` the progress calls it; its findings' and the rig's parameters) carried on by the
    pattern search on the training blocks where it is short of the noise but near it (compass_worth), kept if
    validation is no worse: with the floors calibrated, as the refit before them, a closed loop that sticks and hunts
    makes the cost rough and Levenberg-Marquardt stops short. Seed 83's two-joint watflex-490a4521, an 11 ms command
    delay found to the millisecond with the elbow inertia at x1.010 (truth x1.028): training 1.47 x the noise,
    validation 1.87 x with the elbow encoder at 3.41 x, `unexplained`; carried on, it stops within the noise at 0.94 x
    and 1.04 x, the elbow inertia x1.029 (searched to its end: 0.78 x and 0.84 x)."""
    train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    if within_noise(train, held) or not compass_worth(train):
        return model, sims
    free = effect_slots_of(data, model) + rig_slots(data)
    say("polish", f"{what} is short of the noise (training {train['noise_ratio']:.2f} x, validation "
        f"{held['noise_ratio']:.2f} x): a pattern search over its {len(free)} parameters (stick-slip makes the cost rough)")
    moved, new = pattern_search(data, runner, in_noise(data, runner), model, free, sims)
    if new is None or fit_scores(data, new, "held_out")["noise_ratio"] > held["noise_ratio"]:
        return model, sims
    return moved, new


def compass(evaluate, base: Model, free: list[Slot], x0, r0: np.ndarray, sweeps: int = 6,
            first_step: float = 0.25, resolution: float | None = None, enough=None) -> Model:
    """Compass (pattern) search on the training cost from x0, for a cost that stick-slip makes rough:
    each sweep simulates every slot one step up and one down (2 x len(free) models, in parallel) and
    moves to the best if it lowers Huber's cost by COMPASS_GAIN of it; a sweep that finds nothing halves
    the steps, which start at `first_step` x each slot's span. Levenberg-Marquardt's local model can
    stall there (a few 0.1 % of inertia decide where a stick-slipping joint stops). At most `sweeps`
    sweeps; with a `resolution` (a cost change the data cannot resolve: 0.5 for a residual in noise
    units, one unit of chi-square) it stops earlier, once no step changes the cost by that much or by
    what a move must gain: smaller steps would change it less still (far from the noise, where missing
    physics holds the cost up, the 0.1 % decides: a laser arm with its actuator gain x1.1 searched 11
    sweeps, 231 simulations, for a 0.3 % lower cost found in the first two); a slot at its bound, which
    steps one way only, does not hold it. With `enough(model)` it stops at the first move to a model for
    which that holds (and returns that very object)."""
    u, lo, hi = internal_start(free, x0)
    k = huber_threshold(r0)
    cost, step = huber_cost(r0, k), first_step * (hi - lo)
    for _ in range(sweeps):
        trials, both_ways = [], []
        for i in range(len(free)):
            moves = []
            for sign in (1.0, -1.0):
                v = u.copy()
                v[i] = np.clip(v[i] + sign * step[i], lo[i], hi[i])
                if v[i] != u[i]:
                    moves.append(v)
            trials += moves
            both_ways += [len(moves) == 2] * len(moves)
        costs = [math.inf if r is None else huber_cost(r, k)
                 for r in evaluate([at_internal(v, free, base) for v in trials])]
        best = int(np.argmin(costs)) if costs else -1
        # a slot at a bound steps one way only: its cost changes in proportion to the step, to first order,
        # so a step that gained too little, or lost, does no better shorter; it does not hold the search
        moving = max((abs(c - cost) for c, two in zip(costs, both_ways) if two), default=0.0)
        if best >= 0 and costs[best] < cost * (1 - COMPASS_GAIN):
            u, cost = trials[best], costs[best]
            if enough is not None and enough(moved := at_internal(u, free, base)):
                return moved
        elif resolution is not None and moving < max(resolution, COMPASS_GAIN * cost):
            break
        else:
            step = step / 2
    return at_internal(u, free, base)
