"""Rescreen: the best-screening candidates checked by simulation at their linear estimates.

Contract: `rescreen(evaluate, cands, base, columns, slots, at, r0)` sets each candidate's `checked` (the share of the
training cost a simulation at its estimate, or half-way to it, leaves once the rig's parameters and the findings so
far are refit to first order) and moves its `estimate` where a simulation gains more: on along its line while that
gains or where the estimate loses (`looks_further`, `further`, then `search_along` between the moves), a link's
stiffness on a ladder of rungs (`ladder`), a log-scaled switch half a level either side (`between_levels`).
selection.shortlist then reads `checked`.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from .data import Model
from .fitting import Slot, refit_cost
from .screening import SWITCH_LEVELS, Candidate

FURTHER_STEPS = 2  # rescreen: times an estimate whose simulated gain still rises is moved on to twice its distance
ALONG_TOLERANCE = 0.01  # rescreen: an estimate moved on is then searched for between half and twice its distance
# (bounded Brent) to this share of the distance from neutral it started at, in internal units (a ratio's log)
LADDER_RATIO = 1.3  # rescreen: a `wide` log-scaled parameter with a neutral (a link's stiffness) is simulated at
LADDER_REACH = 8.0  # rungs this ratio apart, out to this factor either side of neutral: its residual is flat near
# neutral and its basin narrow far from it (seed 71, watflex-0f5ae0dc, link 2 x0.257: training 325 x the noise from
# x0.65 to x1, 30 x at x0.25, 291 x at x0.18; seed 70's x2.866: its basin's skirt spans x2.3-x3.3, a ratio of 1.43)
DIVERGED = 1e6  # the search's loss where a simulation diverges (a gain is a share of the cost: at most 1)
RESCREEN = 6  # the best-screening candidates whose linear gain is checked by simulation (rescreen)


def rescreen(evaluate, cands: list[Candidate], base: Model, columns: np.ndarray, slots: list[Slot],
             at: np.ndarray, r0: np.ndarray) -> None:
    """Check the linear screening of `cands` by simulation: each is simulated at its linear estimate and
    half-way to it, and `checked` set to the larger share of the training cost those leave once `slots` (the
    rig's parameters and the findings so far, as in `screen`) are re-optimised to first order (`refit_cost`).
    A signature is a slope at its probe and the rig's parameters absorb part of an effect in the refit: a
    Watflex link's stiffness screened at 14 % and, at its estimate, made the residual 2.2 x worse; the 0.33 kg
    payload that was there screened at 12 % with an estimate of 0.08 kg and was not fitted. A quantised
    parameter keeps its step search.
    Where the gain at the estimate beats the gain half-way, the estimate is moved on to twice its distance from
    neutral (`further`), at most FURTHER_STEPS times while that gains more; `checked` and `estimate` follow
    (seed 46, a laser beam 0.26 x as stiff as the datasheet: estimated at 0.43 x, simulated at 26 %, behind
    the hub's compliance at 77 %, and never fitted), and one moved on is searched for between the moves
    (`search_along`). A candidate with a `ladder` parameter is simulated on its rungs too (`ladder`), and the best
    rung taken where it gains more; a log-scaled switch candidate (a backlash's width, a compliance's stiffness) half
    a level's step either side of its estimate too (`between_levels`)."""
    todo = [c for c in cands if not c.quanta and c.gain > -math.inf]
    if not todo:
        return
    lo, hi = np.array([s.low for s in slots]), np.array([s.high for s in slots])
    cost0 = float(r0 @ r0) or 1.0
    cost_rig = refit_cost(columns, r0, at, lo, hi)
    models, owners = [], []
    for cand in todo:
        origin = {**cand.start, **cand.neutral}
        halfway = {n: (v + origin[n]) / 2 if n in cand.neutral else v for n, v in cand.estimate.items()}
        for values in (cand.estimate, halfway) if halfway != cand.estimate else (cand.estimate,):
            models.append(cand.model(base, values))
            owners.append(cand)
    def gain_of(r: np.ndarray | None) -> float:
        return -math.inf if r is None else (cost_rig - refit_cost(columns, r, at, lo, hi)) / cost0

    gains: dict[int, list[float]] = {}
    for cand, r in zip(owners, evaluate(models)):
        gain = gain_of(r)
        gains.setdefault(id(cand), []).append(gain)
        if r is not None:
            cand.checked = gain if cand.checked is None else max(cand.checked, gain)
    # on along the line while the gain still rises from half-way to the estimate: a linear signature taken
    # near neutral under-reaches an effect far from it (a beam 0.26 x as stiff, estimated at 0.43 x); and where the
    # estimate itself loses, beyond it too (`looks_further`)
    moving = [c for c in todo if looks_further(gains[id(c)])]
    starts = {id(c): (c, dict(c.estimate)) for c in moving}  # where each started, and the moves it made on
    made: dict[int, int] = {}
    for _ in range(FURTHER_STEPS):
        moves = {id(c): further(c) for c in moving}
        moving = [c for c in moving if moves[id(c)] != c.estimate]
        if not moving:
            break
        runs = evaluate([c.model(base, moves[id(c)]) for c in moving])
        better = []
        for cand, r in zip(moving, runs):
            gain = gain_of(r)
            if gain > cand.checked:
                cand.checked, cand.estimate = gain, moves[id(cand)]
                made[id(cand)] = made.get(id(cand), 0) + 1
                better.append(cand)
        moving = better
    for key, k in made.items():  # between the moves: the line's best lies anywhere from half to twice the last
        cand, first = starts[key]
        search_along(evaluate, cand, base, first, 2.0 ** k, gain_of)
    tries = [(cand, {**cand.estimate, cand.ladder: value}) for cand in todo for value in ladder(cand)]
    tries += [(cand, values) for cand in todo for values in between_levels(cand)]
    runs = evaluate([cand.model(base, values) for cand, values in tries]) if tries else []
    for (cand, values), r in zip(tries, runs):
        gain = gain_of(r)
        if r is not None and (cand.checked is None or gain > cand.checked):
            cand.checked, cand.estimate = gain, values


def looks_further(gains: list[float]) -> bool:
    """Whether a candidate simulated at its estimate and half-way to it (`gains`, in that order) is moved on along
    its line: the gain rises from half-way to the estimate, or the estimate itself loses (gain <= 0, not diverged).
    Stick-slip is far from linear in a friction's size and its residual is not monotone along the line: a laser hub
    Coulomb friction of 0.6 / 0.3 N m (tools/bench_diagnose.py) estimated at 0.27 / 0.033 gains 0.24 half-way, -0.28
    there and 0.33 at twice that; fitted from the estimate it ended at 0.115 / 0 N m with the rig's parameters at
    their bounds (14 x the noise, a spurious fine ripple chosen instead), from twice it at the truth (0.5997 /
    0.2998)."""
    if len(gains) != 2:
        return False
    at, half = gains
    return at > max(half, 0.0) or -math.inf < at <= 0.0


def between_levels(cand: Candidate) -> list[dict[str, float]]:
    """A log-scaled switch candidate's estimate (one of SWITCH_LEVELS, a decade apart) moved half a level's step
    (x and / the square root of their ratio) either way, within its slot: such an effect is far from linear in its
    size between two levels (seed 75, watflex-55e80326: a 0.023 rad elbow backlash, probed at 0.080 and 0.0080 rad,
    simulated at its estimate worse than no effect and never fitted; at 0.025 rad it leaves 1.6 x the noise from
    13.8 x). [] for any other candidate (one with a neutral value is probed by level, not switched: `probes`)."""
    first = next(iter(cand.start), None)
    if cand.neutral or first is None or not cand.slots[first].log:
        return []
    slot = cand.slots[first]
    step = math.sqrt(SWITCH_LEVELS[0] / SWITCH_LEVELS[1])
    out = [{**cand.estimate, first: float(np.clip(cand.estimate[first] * f, slot.low, slot.high))} for f in (step, 1 / step)]
    return [v for v in out if v != cand.estimate]


def ladder(cand: Candidate) -> list[float]:
    """Values of the candidate's `ladder` parameter to simulate: LADDER_RATIO apart from neutral, out to LADDER_REACH x
    either side, within its slot ([] without one)."""
    if not cand.ladder:
        return []
    neutral, slot = cand.neutral[cand.ladder], cand.slots[cand.ladder]
    steps = int(math.log(LADDER_REACH) / math.log(LADDER_RATIO) + 1e-9)
    return [v for k in range(-steps, steps + 1) if k and slot.low <= (v := neutral * LADDER_RATIO**k) <= slot.high]


def search_along(evaluate, cand: Candidate, base: Model, first: dict[str, float], far: float, gain_of) -> None:
    """An estimate `rescreen` moved on from `first` to `far` times its distance from neutral, searched for between
    half and twice that along the same line (bounded Brent on `gain_of` of a simulation, to ALONG_TOLERANCE of
    first's distance); kept where it gains more. Moving on doubles the distance, and a residual that is not convex
    along the line can have its basin between two moves: seed 70's watflex-0eef1dc1, link 2 x2.866 as stiff with the
    rig's EI and inertia refit to their bounds, estimated at x1.99 and moved on to x3.95, on a plateau (training 25.7 x
    the noise) beyond the basin at x2.62 (5.3 x), which is 3 % wide; fitted from x3.95, a spurious elbow compliance
    made up the rest."""
    tried: dict[float, float] = {}

    def loss(s: float) -> float:
        r = evaluate([cand.model(base, along(cand, first, s))])[0]
        tried[s] = gain_of(r)
        return -tried[s] if math.isfinite(tried[s]) else DIVERGED

    minimize_scalar(loss, bounds=(far / 2, 2 * far), method="bounded",
                    options={"xatol": ALONG_TOLERANCE})
    best = max(tried, key=tried.__getitem__)
    if tried[best] > cand.checked:
        cand.checked, cand.estimate = tried[best], along(cand, first, best)


def _internal(cand: Candidate, name: str, value: float) -> tuple[float, float, bool]:
    """(neutral, value) of a parameter in its internal units (a log-scaled ratio's logarithm), and whether logs."""
    neutral, slot = cand.neutral[name], cand.slots[name]
    log = slot.log and neutral > 0 and value > 0
    return (math.log(neutral), math.log(value), True) if log else (neutral, value, False)


def along(cand: Candidate, values: dict[str, float], s: float) -> dict[str, float]:
    """`values` moved to `s` times their distance from neutral (in the parameters' internal units: a log-scaled
    ratio's logarithm), within their bounds; quantised parameters stay."""
    out = dict(values)
    for name in cand.neutral:
        if name in out and name not in cand.quanta:
            o, e, log = _internal(cand, name, out[name])
            x = o + s * (e - o)
            out[name] = float(np.clip(math.exp(x) if log else x, cand.slots[name].low, cand.slots[name].high))
    return out


def further(cand: Candidate) -> dict[str, float]:
    """The candidate's estimate moved on to twice its distance from neutral, within the bounds (`along`)."""
    return along(cand, cand.estimate, 2.0)
