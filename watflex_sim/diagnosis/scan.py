"""Scans of a candidate's nonlinear parameter: where a fit starts when the residual is far from convex in it.

Contract: `period_scans` scans a ripple's period (effects.Param.periodic), several ways on the same simulations (one
beside what else the shortlist says may be missing: `beside`), `scan_shape` a shape parameter
(`candidate_shape`: a time constant, a Stribeck velocity); both run `scan_rungs`: at each rung the parameters the
effect is linear in, to first order, are re-solved with the rig's columns by bounded least squares, the best rungs
carried on by Gauss-Newton steps (a shape's on the slopes at each), and (values, their cost) returned for the fit to
start from (effect_fit.fit_candidate: a period's best, a shape's every contender). Costs are the caller's (`cost` of a
residual, in the fit's noise units). `shape_profile` looks around a fitted shape, the sizes scaled with it.
"""
from __future__ import annotations

import math

import numpy as np

from ..effects import CATALOGUE
from .data import Model
from .fitting import Slot, refit_step
from .level import shape_name, valley_points
from .screening import Candidate

PERIOD_CYCLES_STEP = 0.5  # cycles over the motion's range: the spacing of a period scan where the range holds a cycle
# or more (the true period is at most a quarter cycle of phase drift across the range from a rung, where a sine
# still matches it to 0.9: sin(pi / 4) / (pi / 4)) ...
PERIOD_LADDER = 1.4  # ... and the ratio of one longer period to the next, where it holds less ...
PERIOD_LONGEST = 8.0  # x the motion's range: ... up to this (a longer ripple is a smooth bend over the range, which the
# spring and the screening's own start, 3 x the range, already stand for)
PERIOD_CHECKED = 3  # the periods whose linear estimate fits best are simulated there ...
PERIOD_STEPS = 2  # ... and moved on by this many Gauss-Newton steps (the scan's columns, one simulation each)
LOCAL_STEP = 0.2  # a shape scan's Gauss-Newton steps take the size parameters' slopes at the contender, from a step
# this share of their distance from neutral: the probe's secant from neutral is a poor slope where stick-slip makes the
# residual bend (seed 59, a dwell's gain re-solved to ~0.5, its probe level, at every rung)
SHAPE_LADDER = 2.0  # a shape parameter's scan (a time constant, a Stribeck velocity): the ratio of one rung to the next
PROFILE_SHAPES = (2 ** -0.5, 2 ** -0.25, 2 ** 0.25, 2 ** 0.5)  # a fitted shape's profile: the shape x these (half and
# quarter rungs of SHAPE_LADDER) ...
PROFILE_SIZES = (0.35, 0.5, 0.7, 1.0, 1.4, 2.0)  # ... each with all the sizes' distances from neutral x these
RING_PHASES = 8  # a period rung of a cycle or less over the motion's range is also simulated at this many phases ...
RING_SIZES = (0.5, 1.0)  # ... at these shares of the start's amplitude (period_scans: its linear estimate fails there)


def period_ladder(slot: Slot, motion: float) -> list[float]:
    """Periods to scan within `slot` (rad, m) for a motion range `motion`: evenly spaced in cycles over the
    range (PERIOD_CYCLES_STEP) down to one cycle, then PERIOD_LADDER apart up to PERIOD_LONGEST ranges."""
    periods, cycles = [], motion / slot.low
    while cycles >= 1.0:
        periods.append(motion / cycles)
        cycles -= PERIOD_CYCLES_STEP
    period = periods[-1] * PERIOD_LADDER if periods else slot.low
    while period <= min(slot.high, PERIOD_LONGEST * motion):
        periods.append(period)
        period *= PERIOD_LADDER
    return periods


def candidate_shape(cand: Candidate) -> str:
    """The candidate's shape parameter (level.shape_name), '' if it has none or does not fit it. The residual bends
    along it: at each value the sizes act differently."""
    name = shape_name(cand.effect)
    return name if name and name in cand.slots and name not in cand.quanta else ""


def same_rung(cand: Candidate, a: dict[str, float], b: dict[str, float]) -> bool:
    """Whether the shape parameter of values `a` and `b` is within half a rung (SHAPE_LADDER) of each other: a fit
    from one starts where the other's does, at the scan's resolution (a laser hub's Stribeck v_s, 0.03 rad/s at the
    start, 0.023 at the best rung: a second fit of ~25 simulations for nothing)."""
    name = candidate_shape(cand)
    return abs(math.log(a[name] / b[name])) <= 0.5 * math.log(SHAPE_LADDER)


def shape_profile(evaluate, cand: Candidate, model: Model) -> dict[str, float] | None:
    """The candidate's values in `model` (its last effect, fitted) and at PROFILE_SHAPES x its shape, each with its
    sizes' distances from neutral scaled by PROFILE_SIZES (one batch): the values of the least |r|^2, or None where
    the fit itself leaves the least (or the candidate has no shape). A valley narrower than a scan's rung runs
    diagonally through shape and size: the data pin the effect at the speed (or rest) they sample, and a faster decay
    is made up by a larger size. Levenberg-Marquardt does not walk it: its finite difference in the shape (0.1 in
    log) steps across it (seed 107's watflex-f535260d, a one-way shoulder Stribeck friction of 1.088 N m at v_s
    0.0103 rad/s: fitted at 1.61 N m with v_s still the 0.009 it started from, |r|^2 2.3e5 in noise units; the truth
    3.7e4, and 1.53 N m at 0.0103 6.2e5), nor does the scan's Gauss-Newton on slopes stick-slip bends. Scaling all
    sizes together follows the valley of any direction's excess at once."""
    name = candidate_shape(cand)
    if not name:
        return None
    fitted = {n: v for n, v in model.effects[-1].items() if n in cand.slots}
    bounds = {n: (slot.low, slot.high) for n, slot in cand.slots.items()}
    trials = valley_points(fitted, name, bounds, cand.neutral, [(s, k) for s in PROFILE_SHAPES for k in PROFILE_SIZES])
    models = [Model(model.effects[:-1] + [{**model.effects[-1], **t}], dict(model.parameters)) for t in trials]
    runs = evaluate([model] + models)
    costs = [math.inf if r is None else float(r @ r) for r in runs]
    best = int(np.argmin(costs))
    return trials[best - 1] if best > 0 else None


def shape_ladder(slot: Slot) -> list[float]:
    """Values to scan a shape parameter at: SHAPE_LADDER apart across its slot (rung midpoints, off its bounds)."""
    rungs, value = [], slot.low * math.sqrt(SHAPE_LADDER)
    while value < slot.high:
        rungs.append(value)
        value *= SHAPE_LADDER
    return rungs


def _nudge(x: np.ndarray, j: int, start: np.ndarray, low: float, high: float) -> np.ndarray:
    """A step of coefficient j from `x` for its slope there: LOCAL_STEP of its distance from `start` (its neutral value),
    at least LOCAL_STEP of its slot's width / 50, towards the slot's inside."""
    h = np.zeros_like(x)
    h[j] = LOCAL_STEP * max(abs(x[j] - start[j]), 0.02 * (high - low))
    h[j] = -h[j] if x[j] + h[j] > high else h[j]
    return h


def beside(cand: Candidate, others: list[Candidate]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The signature columns of the `others` of another effect (each neutral parameter's at the first level: the change
    of the residual per unit; their start at neutral; their bounds) for a scan of `cand` to re-solve beside its own,
    or None without any: what else the shortlist says may be in the residual. Without them a ripple's period is
    scanned against a residual that another missing effect dominates, and a wrong period that mimics a little of that
    effect wins (seed 68, watflex-db048a3c: an elbow ripple of 1.35 N m at 0.82 rad beside a Coulomb friction of
    0.86 / 0.99 N m, scanned and fitted at 0.116 rad; the case ended `unexplained`). A second way, not the only one: a
    friction's column is a linear picture of stick-slip (effect_fit.fit_candidate)."""
    columns, start, low, high = [], [], [], []
    for other in others:
        if other is cand or other.effect == cand.effect or not other.signature:
            continue
        level = other.signature.get(other.levels[0], {})
        for name, neutral in other.neutral.items():
            if name in level and np.all(np.isfinite(level[name])):
                columns.append(level[name])
                start.append(neutral)
                low.append(min(other.slots[name].low, neutral))
                high.append(max(other.slots[name].high, neutral))
    if not columns:
        return None
    return np.column_stack(columns), np.array(start), np.array(low), np.array(high)


def period_scans(evaluate, cand: Candidate, base: Model, values: dict[str, float], ways: list[tuple]) -> list[tuple[dict[str, float], float]]:
    """A periodic parameter's value (a ripple a sin(2 pi x / period + phase), effects.Param.periodic) from a scan,
    with its amplitude and phase: the residual is far from convex in the period (seed 52, a 0.77 rad Watflex elbow
    ripple fitted at 1.35 rad from its start at 3 x the motion's range, 5 x the noise left), but at a given
    period it is linear, to first order, in the a sin + b cos the ripple is. Each period of `period_ladder` is
    simulated twice (the amplitude at its start, phase 0 and pi/2); with the effect's other neutral parameters (a
    spring: its own column) the rest is `scan_rungs'`, done each of several ways on the same simulations: `ways` is a
    list of (cost, (columns, values, low, high), values given) - the cost of a residual with the columns re-solved, the
    columns re-solved beside the ripple's at each rung (the rig's, or the rig's and what else may be missing: `beside`)
    and the values that way's result is judged against (`values`, or that way's earlier choice). A rung of a cycle or
    less over the motion's range is also simulated on a ring (RING_PHASES phases at RING_SIZES of the start's
    amplitude), its least costly point a contender: there the ripple is a bias and a slope, which a joint that sticks
    answers far from linearly, and the probes' estimate is no guide (seed 93, watflex-3f8a52e2: 0.78 N m at 1.127 rad
    over 0.54 rad, the rung at 1.056 rad estimated at 1.47 N m beside a spring of -0.78 N m/rad, cost 8.4e6; the
    ring's best there 1.4e6, carried on 3.8e5; 16 simulations a rung). Returns the best (values, cost) of each way, in
    order; [] for an effect without a periodic parameter or whose neutral model diverges."""
    param = next((p for p in CATALOGUE[cand.effect][1] if p.periodic), None)
    if param is None:
        return []
    period, size, amp = param.name, cand.start["amplitude"], cand.slots["amplitude"]
    motion = cand.slots[period].low / param.low  # the slot is in motion ranges
    periods = period_ladder(cand.slots[period], motion)

    def rung(p: float) -> list[tuple[dict[str, float], float]]:
        return [({period: p, "amplitude": size, "phase": phase}, size) for phase in (0.0, math.pi / 2)]

    def as_own(p: float, x: np.ndarray) -> dict[str, float]:
        return {period: p, **cand.ripple(*x)}

    fixed = [n for n in cand.neutral if n != "amplitude"]  # a spring beside the ripple: its own column
    ring = [(p, np.r_[[cand.neutral[n] for n in fixed], s * size * math.cos(phase), s * size * math.sin(phase)])
            for p in periods if p >= motion for s in RING_SIZES
            for phase in np.linspace(-math.pi, math.pi, RING_PHASES, endpoint=False)]
    found = scan_rungs(evaluate, cand, base, values, ways, periods, rung, [amp, amp], np.zeros(2), as_own, fixed,
                       every=True, ring=ring)
    return [way[0] for way in found] if all(found) else []


def scan_shape(evaluate, cand: Candidate, base: Model, values: dict[str, float], cost,
               rig_columns: np.ndarray, u_rig: np.ndarray, lo_rig: np.ndarray, hi_rig: np.ndarray) -> list[tuple[dict[str, float], float]]:
    """A shape parameter's value (`candidate_shape`) from a scan over `shape_ladder`: at a given shape the effect is, to
    first order, linear in its neutral parameters, but the residual is far from convex in the shape (seeds 54, 55,
    62, 63: a Watflex dwell-time stiction's time constant of 0.6-0.7 s fitted at 1.5-2 s from its 2 s start, gain 2x
    too large; at the true time constant a gain near the truth fits better). Each rung is simulated once per neutral
    parameter (at its probe); the rest is `scan_rungs`' (with the slopes at each contender: `local`), and its
    PERIOD_CHECKED contenders are returned, (values, cost) least first, whatever the values given cost: the fit is
    started from each (`fit_candidate`). [] without a shape parameter."""
    name = candidate_shape(cand)
    if not name:
        return []
    own = list(cand.neutral)
    slots = [cand.slots[n] for n in own]

    def rung(v: float) -> list[tuple[dict[str, float], float]]:
        return [({name: v, n: cand.probe(n)}, cand.probe(n) - cand.neutral[n]) for n in own]

    def as_own(v: float, x: np.ndarray) -> dict[str, float]:
        return {name: v, **{n: float(np.clip(x_n, s.low, s.high)) for n, x_n, s in zip(own, x, slots)}}

    return scan_rungs(evaluate, cand, base, values, [(cost, (rig_columns, u_rig, lo_rig, hi_rig), values)],
                      shape_ladder(cand.slots[name]), rung, slots, np.array([cand.neutral[n] for n in own]), as_own, [],
                      given=False, local=True)[0]


def scan_rungs(evaluate, cand: Candidate, base: Model, values: dict[str, float], ways: list[tuple], rungs: list[float],
               rung_probes, rung_slots: list[Slot], rung_start: np.ndarray, as_own, fixed: list[str],
               given: bool = True, local: bool = False, every: bool = False,
               ring: list[tuple[float, np.ndarray]] = ()) -> list[list[tuple[dict[str, float], float]]]:
    """The scan of one nonlinear parameter over `rungs`: one simulation with the effect at its neutral values, one
    per `fixed` parameter at its probe (a column shared by all rungs), and at each rung those of `rung_probes(v)`
    ((values, the probe's step) each: the rung's own columns); the columns, with the rig's (`rig`: columns, values,
    bounds, internal units; one of `ways`, each (cost, rig, the values given it), sharing the rung simulations),
    estimate the rung's coefficients by bounded least squares from `rung_start` within `rung_slots`; the
    PERIOD_CHECKED rungs whose estimate leaves the least residual are carried PERIOD_STEPS Gauss-Newton steps on
    (the same columns, the residual simulated at the estimate: stick-slip makes the first estimate rough; there,
    seed 52's ripple phase was 0.49 rad off and the estimate lost to a wrong period's), and the contenders and
    (`given`) the values given are returned as (values, their `cost` of the residual), least first; none where the
    effect at neutral diverges. `as_own(v, coefficients)` gives the effect's values at rung v. With `local`, the
    steps take the rung's coefficients' slopes at the contender (`_nudge`), not the probes' secants from neutral.
    With `every`, every rung takes the first step (a simulation at its first estimate), and each step is followed by
    the PERIOD_CHECKED best first estimates and the PERIOD_CHECKED whose simulation in it cost least: the first estimate,
    from probes at the start's size, is rough where the effect is large and stick-slip bends its residual (seed 75,
    watflex-6cc78dba, an elbow ripple of 0.56 N m at 1.23 rad: the rung at 1.05 rad was not among the three best
    first estimates and the fit ended at 0.34 rad, 8 x the noise; carried on, it scans at 6.5e5 against 0.36 rad's
    1.5e6). Either ranking alone loses cases the other finds (a dead-zone stand-in, test_diagnosis_stages); together
    the scan is never worse than from the first three alone, whose steps are the same. `ring`: (rung, coefficients)
    points simulated too, the least costly at each rung a contender of its own (and among the values returned), where
    the linear estimate is no guide (period_scans). One such list per way, in order (all [] where the effect at neutral
    diverges)."""
    zero = {**values, **cand.neutral}
    probes = [(v, rung_probes(v)) for v in rungs]
    at_ring = [{**zero, **dict(zip(fixed, map(float, x[:len(fixed)]))), **as_own(v, x[len(fixed):])} for v, x in ring]
    runs = evaluate([cand.model(base, zero)] + [cand.model(base, {**zero, n: cand.probe(n)}) for n in fixed]
                    + [cand.model(base, {**zero, **p}) for _, ps in probes for p, _ in ps]
                    + [cand.model(base, v) for v in at_ring])
    if any(r is None for r in runs[:1 + len(fixed)]):
        return [[] for _ in ways]
    runs, ringed = runs[:len(runs) - len(ring)], [(v, x, r) for (v, x), r in zip(ring, runs[len(runs) - len(ring):])]
    r0, shared = runs[0], [(r - runs[0]) / (cand.probe(n) - cand.neutral[n]) for n, r in zip(fixed, runs[1:])]
    return [_carry(evaluate, cand, base, given_values, cost, rig, probes, runs, r0, shared, rung_slots, rung_start,
                   as_own, fixed, given, local, every, ringed) for cost, rig, given_values in ways]


def _carry(evaluate, cand: Candidate, base: Model, values: dict[str, float], cost, rig: tuple, probes: list, runs: list,
           r0: np.ndarray, shared: list, rung_slots: list[Slot], rung_start: np.ndarray, as_own, fixed: list[str],
           given: bool, local: bool, every: bool, ringed: list = ()) -> list[tuple[dict[str, float], float]]:
    """scan_rungs' one way: the rungs ranked by their linear estimate beside `rig`'s columns (with `every`, also by
    the simulated cost at it), and the least costly `ringed` (rung, coefficients, residual) point at each rung, carried
    on."""
    rig_columns, u_rig, lo_rig, hi_rig = rig
    slots = [cand.slots[n] for n in fixed] + rung_slots
    lo, hi = np.concatenate([lo_rig, [s.low for s in slots]]), np.concatenate([hi_rig, [s.high for s in slots]])

    def estimate(columns: np.ndarray, r: np.ndarray, at: np.ndarray) -> tuple[float, np.ndarray]:
        """(residual left, the values of the fixed and the rung's coefficients) from the linear solve about `at`."""
        left, step = refit_step(columns, r, np.concatenate([u_rig, at]), lo, hi)
        return left, at + step[len(u_rig):]

    def as_values(v: float, x: np.ndarray) -> dict[str, float]:
        return {**values, **dict(zip(fixed, map(float, x[:len(fixed)]))), **as_own(v, x[len(fixed):])}

    start, ranked, k = np.concatenate([[cand.neutral[n] for n in fixed], rung_start]), [], 1 + len(fixed)
    for v, ps in probes:
        own, k = runs[k:k + len(ps)], k + len(ps)
        if all(r is not None for r in own):
            columns = np.column_stack([rig_columns, *shared, *[(r - r0) / step for r, (_, step) in zip(own, ps)]])
            ranked.append((*estimate(columns, r0, start), v, columns))
    ranked.sort(key=lambda x: x[0])
    contenders = [(v, x, columns) for _, x, v, columns in (ranked if every else ranked[:PERIOD_CHECKED])]
    ring_best = {}  # rung -> (cost, coefficients) of its least costly ring point
    for v, x, r in ringed:
        c = math.inf if r is None else cost(r)
        if c < ring_best.get(v, (math.inf,))[0]:
            ring_best[v] = (c, x)
    rung_columns = {v: columns for _, _, v, columns in ranked}
    from_ring = [(v, x) for v, (_, x) in ring_best.items() if v in rung_columns]
    contenders += [(v, x, rung_columns[v]) for v, x in from_ring]
    sizes = range(len(fixed), len(start)) if local else range(0)  # the coefficients whose slopes are taken at x
    for _ in range(PERIOD_STEPS):  # Gauss-Newton steps with the probes' columns: a linear estimate in a closed loop
        nudges = [[_nudge(x, j, start, lo[len(u_rig) + j], hi[len(u_rig) + j]) for j in sizes] for _, x, _ in contenders]
        runs = evaluate([cand.model(base, as_values(v, x)) for v, x, _ in contenders]  # with stick-slip is rough
                        + [cand.model(base, as_values(v, x + h)) for (v, x, _), hs in zip(contenders, nudges) for h in hs])
        at, nudged = runs[:len(contenders)], iter(runs[len(contenders):])
        moved = []
        for (v, x, columns), r, hs in zip(contenders, at, nudges):
            local_columns = columns.copy()
            for j, h in zip(sizes, hs):  # the secant from neutral to the probe replaced by the slope at x
                r_h = next(nudged)
                if r is not None and r_h is not None:
                    local_columns[:, len(u_rig) + j] = (r_h - r) / h[j]
            moved.append((math.inf if r is None else cost(r), v, x if r is None else estimate(local_columns, r, x)[1], columns))
        least = sorted(range(len(moved)), key=lambda i: moved[i][0])[:PERIOD_CHECKED]  # by the simulated cost at x
        contenders = [m[1:] for i, m in enumerate(moved) if i < PERIOD_CHECKED or i in least]  # and the best first estimates
    tried = [values] * given + [as_values(v, x) for v, x, _ in contenders]
    costs = [math.inf if r is None else cost(r) for r in evaluate([cand.model(base, v) for v in tried])]
    ring_tried = [(as_values(v, x), ring_best[v][0]) for v, x in from_ring]  # simulated already: their costs known
    return sorted([*zip(tried, costs), *ring_tried], key=lambda vc: vc[1])
