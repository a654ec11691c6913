"""A shape or quantised parameter profiled: the cost along a parameter whose valley no Jacobian at one end sees.

Contract: `level_profile(evaluate, model, index, name, slots, J, values)` returns, for each value of effect `index`'s
parameter `name`, the model with it there and every other slot re-solved, and its cost 0.5 |r|^2 (in `evaluate`'s
units), to first order; `level_reach(...)` walks it out from the estimate (period.walk) and returns the ranges of the
effect parameters over the points the data cannot tell from the best (period.limits), for the 95 % intervals;
`level_start(...)` the point of a short profile that costs less than the estimate beyond the noise, for the final
refit to start again from, and `fine_start(...)` the same of a fine grid of a shape with its sizes scaled. `levels`
lists an effect's parameters to profile, `shape_name` its shape parameter.

Why: along a shape parameter (a dwell-time stiction's time constant, a Stribeck velocity) the parameters that set
the effect's size act differently at each value, so the residual bends: a long curved valley whose far end a Jacobian
at the estimate puts far above it (seed 59, watflex-1e32daae, a dwell of gain 0.51 and time constant 0.98 s: fitted
at 0.29 / 0.58 s, interval [0.37, 0.90] s, while a fit from 1.13 s ends at 0.52 / 1.18 s only 0.06 % costlier). A
quantised parameter (a delay, in control periods) was good to half its step, whichever step the fit stopped at: the
steps beside it are profiled as well (seed 64, watflex-7c2659f4: an 11 ms delay found at 10 ms, [9.5, 10.5]).
"""
from __future__ import annotations

import numpy as np

from ..effects import CATALOGUE
from .data import Data, Model
from .fitting import Slot, at_internal, fd_step, refit_step, residual_variance, value_of
from .motion import scale_of
from .period import reach_of, stepped, walk, within

LEVEL_RATIO = 2**0.5  # one value of a shape parameter's profile to the next (the scan's rungs are 2x apart)
START_STEPS = 2  # level_start profiles this many values either side of the estimate
FINE_SHAPES = tuple(2 ** (k / 16) for k in (-2, -1, 0, 1, 2))  # fine_start: a shape x these (sixteenths of the scan's
# factor-2 rungs) ...
FINE_SIZES = (0.85, 0.9, 0.95, 1.0, 1.05, 1.1)  # ... each with its effect's sizes' distances from neutral x these


def shape_name(effect: str) -> str:
    """The effect's shape parameter, '' if it has none: log-scaled, with no neutral value, neither quantised nor
    periodic, beside parameters that set the effect's size and vanish at a neutral value (a dwell-time stiction's
    time constant beside its gain, a Stribeck friction's v_s beside its break-aways)."""
    params = CATALOGUE[effect][1]
    if not any(p.neutral is not None for p in params):
        return ""
    return next((p.name for p in params if p.log and p.neutral is None and not p.periodic and not p.quantum), "")


def levels(data: Data, effect: dict) -> list[tuple[str, tuple[float, float], float]]:
    """The effect's parameters to profile, (name, bounds in the data's units, quantum or 0): its shape parameter
    (`shape_name`), its quantised ones and those the catalogue marks `profiled`."""
    out = []
    for p in CATALOGUE[effect["effect"]][1]:
        if p.name in effect and (p.quantum or p.profiled or p.name == shape_name(effect["effect"])):
            size = scale_of(data, p, effect["where"])
            out.append((p.name, (p.low * size, p.high * size), p.quantum))
    return out


def level_ladder(estimate: float, steps: range, bounds: tuple[float, float], quantum: float) -> list[float]:
    """Values estimate + k x quantum (a quantised parameter) or estimate x LEVEL_RATIO^k for k in `steps`, within
    `bounds`."""
    return sorted({float(np.clip(estimate + k * quantum if quantum else estimate * LEVEL_RATIO**k, *bounds)) for k in steps})


def level_profile(evaluate, model: Model, index: int, name: str, slots: list[Slot], J: np.ndarray,
                  values: list[float]) -> list[tuple[float, Model, float, np.ndarray]]:
    """(value, model, profiled cost, its residual) for each of `values` of effect `index`'s parameter `name` where the
    simulations run: every slot but that one re-solved, the effect's own others on their slopes at that value (one
    simulation each, fitting.fd_step from the estimate: the size's slope changes along the shape), the rest on J's
    columns (internal units, in `evaluate`'s units); then one Gauss-Newton step more from a simulation at that solution,
    the cost its linear prediction 0.5 |r + J d|^2 (as period.period_profile). Simulations: 1 + the effect's other
    parameters per value, and one at each solution."""
    keep = [k for k, s in enumerate(slots) if s.where != ("effect", index, name)]
    kept = [slots[k] for k in keep]
    own = [j for j, s in enumerate(kept) if s.where[:2] == ("effect", index)]
    u = np.array([s.to_internal(value_of(model, s)) for s in kept])
    lo, hi = np.array([s.to_internal(s.low) for s in kept]), np.array([s.to_internal(s.high) for s in kept])
    steps = {j: fd_step(kept[j], u[j]) for j in own}

    def at(v: float, x: np.ndarray) -> Model:
        m = at_internal(x, kept, model)
        m.effects[index][name] = v
        return m

    def nudged(j: int) -> np.ndarray:
        x = u.copy()
        x[j] += steps[j]
        return x

    runs = evaluate([at(v, u) for v in values] + [at(v, nudged(j)) for v in values for j in own])
    solved = []
    for n, v in enumerate(values):
        r_v, r_own = runs[n], runs[len(values) + n * len(own):len(values) + (n + 1) * len(own)]
        if r_v is None or any(r is None for r in r_own):
            continue
        columns = J[:, keep].copy()
        for j, r_j in zip(own, r_own):
            columns[:, j] = (r_j - r_v) / steps[j]
        solved.append((v, columns, u + refit_step(columns, r_v, u, lo, hi)[1]))
    return stepped(evaluate, solved, at, lo, hi)


def level_reach(evaluate, model: Model, index: int, name: str, bounds: tuple[float, float], quantum: float,
                slots: list[Slot], J: np.ndarray, r: np.ndarray, replicates: list[np.ndarray],
                error: np.ndarray | None) -> tuple[dict[int, tuple[float, float]], list[float]]:
    """Effect `index`'s parameter `name` profiled from its estimate out (`level_profile` on `level_ladder`, within
    `bounds`, `quantum` 0 for a continuous one): per effect slot (index into `slots`) the range of its values over the
    points the data cannot tell from the best of them (period.reach_of), and the profiled values that are such points
    (a quantised parameter's steps)."""
    estimate = model.effects[index][name]
    points = walk(lambda values: level_profile(evaluate, model, index, name, slots, J, values),
                  lambda steps: level_ladder(estimate, steps, bounds, quantum), bounds, r, len(slots), replicates, error)
    kept = [x[0] for x, ok in zip(points, within(points, r, len(slots), replicates, error)) if ok]
    return reach_of([points], slots, r, replicates, error), kept


def level_start(data: Data, evaluate, model: Model, slots: list[Slot], J: np.ndarray, r: np.ndarray) -> Model | None:
    """A start further along a valley: of short profiles (`level_profile`, START_STEPS values either side) along each
    effect's shape and quantised parameters (`levels`), the point whose cost is least, where it is below the
    estimate's own profiled cost by more than the noise resolves (1.96^2 / 2 x s^2); None where none is. `r`: the
    model's residual in `evaluate`'s units, J its Jacobian over `slots` (internal units)."""
    best, least = None, 0.5 * float(r @ r)
    resolved = 1.96**2 / 2 * residual_variance(r, len(slots))  # a cost difference the noise resolves
    for i, effect in enumerate(model.effects):
        for name, bounds, quantum in levels(data, effect):
            points = level_profile(evaluate, model, i, name, slots, J,
                                   level_ladder(effect[name], range(-START_STEPS, START_STEPS + 1), bounds, quantum))
            own = [x[2] for x in points if x[0] == effect[name]]
            if not own:
                continue
            for _, m, cost, _ in points:
                if cost < min(least, own[0] - resolved):
                    best, least = m, cost
    return best


def fine_start(data: Data, evaluate, model: Model, p: int, r: np.ndarray) -> Model | None:
    """A start on a valley narrower than level_start's steps: each shape effect's shape (`shape_name`) x FINE_SHAPES,
    with its sizes' distances from neutral x FINE_SIZES (29 simulations a shape effect, one batch), the point of least
    |r|^2 where it is below the model's by more than the noise resolves (1.96^2 x s^2, `p` parameters fitted); None
    where none is. `r`: the model's residual in `evaluate`'s units. A one-way Stribeck friction sampled near one speed
    leaves a valley diagonal in v_s and break-away a few per cent wide; the final refit's finite differences step across
    it and level_start's profile (v_s x 2^(+-1/2), the break-aways re-solved to first order) lands on its walls (seed
    111, watflex-26368bfd, 1.055 N m positive only at v_s 0.02451 rad/s: refit at 1.150 / 0.0152 N m and 0.02356,
    |r|^2 37,126; at v_s x 2^(1/16) with the sizes x 0.9, 12,724 less, and refit from there 1.038 / 0.0013 N m at
    0.02464, 17,863 less)."""
    trials = []
    pairs = [(shape, k) for shape in FINE_SHAPES for k in FINE_SIZES if shape != 1.0 or k != 1.0]
    for i, effect in enumerate(model.effects):
        name = shape_name(effect["effect"])
        if not name or name not in effect:
            continue
        params = {q.name: q for q in CATALOGUE[effect["effect"]][1] if q.name in effect}
        size = {n: scale_of(data, q, effect["where"]) for n, q in params.items()}
        bounds = {n: (q.low * size[n], q.high * size[n]) for n, q in params.items()}
        neutral = {n: q.neutral * size[n] for n, q in params.items() if q.neutral is not None}
        for values in valley_points(effect, name, bounds, neutral, pairs):
            trials.append(Model([values if j == i else e for j, e in enumerate(model.effects)], dict(model.parameters)))
    if not trials:
        return None
    costs = [np.inf if q is None else float(q @ q) for q in evaluate(trials)]
    best = int(np.argmin(costs))
    return trials[best] if costs[best] < float(r @ r) - 1.96**2 * residual_variance(r, p) else None


def valley_points(values: dict, name: str, bounds: dict[str, tuple[float, float]], neutral: dict[str, float],
                  pairs: list[tuple[float, float]]) -> list[dict]:
    """Points along a shape-size valley (scan.shape_profile, fine_start): per (shape factor, size factor) in `pairs`,
    `values` with its shape `name` x the first and each size's distance from `neutral` x the second, each value
    clipped to its `bounds` (low, high)."""
    def clip(n: str, v: float) -> float:
        return float(np.clip(v, *bounds[n]))

    return [{**values, name: clip(name, values[name] * shape), **{n: clip(n, v + k * (values[n] - v))
                                                                  for n, v in neutral.items()}}
            for shape, k in pairs]
