"""Reaches: how far an estimate can move before the data tell, where a Jacobian's interval cannot say.

Contract: each takes `evaluate` (models -> residuals in one unit, None where a model diverges), the model and its
slots, and returns how far a parameter can move with the cost still within what the data resolve (`residual_variance`):
`slice_reach` along one slot, the others re-solved to first order (a linearised profile: stick-slip's rough cost, a
bent valley), `split_reach` along the line to the datasheet's rig parameters (an effect and a rig parameter that act
alike), and `gentler_side` the Jacobian's effect columns from the side that does not step over a cliff of the cost.
uncertainty.final_intervals joins them.
"""
from __future__ import annotations

import math

import numpy as np

from .data import Model
from .fitting import Slot, at_internal, fd_step, refit_cost, refit_step, residual_variance, value_of
from .period import periodic_name

SLICE_STEPS = (1, 2, 4, 8)  # x an interval's half-width: where slice_reach probes the cost on each side
SPLIT_STEP = 0.05  # x an effect parameter's value (internal units; a log one: 5 %): split_reach's local columns
SPLIT_LINE = (0.5, 1.0, 1.5, 2.0)  # x the move to the datasheet's split: where split_reach simulates the model


def split_reach(evaluate, model: Model, slots: list[Slot], n: int, r: np.ndarray, J: np.ndarray,
                error: np.ndarray | None) -> dict[int, tuple[float, float]]:
    """Effect slot index (of the first `n` of `slots`; the rest the rig's) -> (low, high): the effect's parameters
    where the rig's parameters are at the datasheet's values (ratio 1) and the effects re-solved beside them, as far
    along that line as the data cannot tell it from the estimate once our discretisation is allowed for. An
    effect and a rig parameter that act alike (a joint's added Coulomb friction and the rig's friction scale) share
    a valley the fit's split of is set by small differences of shape, which our discretisation changes; the
    Jacobian, its effect columns wide enough to step over stick-slip, claims the split to a few parts in 10^4.
    Seed 62, watflex-45eef46f (an elbow Coulomb friction 0.519 / 0.532 N m, the rig at the datasheet): found
    0.455 / 0.464 beside the friction scale at 1.012, interval [0.447, 0.478]; the move to the datasheet's scale
    predicted by those columns costs 1,124 (|J d|) in the residual, simulated 154; re-solved with local columns
    (SPLIT_STEP, central; the rig's are J's, n onwards) the line's end is 0.519 / 0.531, 1,580 cost units above the
    estimate, and the model 2 x finer favours it by 5,937 of them. A point of the line (SPLIT_LINE x the move, simulated) is kept where its cost
    less the estimate's, plus what the discretisation `error` (uncertainty.discretisation_error, in r's units) adds
    to that difference (error . (r_t - r), exact for an error that is the same at both), is within 1.96^2 / 2 s^2;
    the reach is the furthest point kept, interpolated on toward the next to where that crosses the threshold: there
    1.45 x the move, 0.547 / 0.558 N m. The furthest, not the first run of points: stick-slip makes the cost along
    the line rough (seed 61, watflex-4730f348, 0.497 / 1.354 N m for 0.564 / 1.426: the excess +1,604 at half the
    move, -1,039 and -1,375 at 1 and 1.5 x, +1,259 at 2 x; reach 1.76 x, 0.610 / 1.480 N m)."""
    u = np.array([s.to_internal(value_of(model, s)) for s in slots])
    lo = np.array([s.to_internal(s.low) for s in slots])
    hi = np.array([s.to_internal(s.high) for s in slots])
    move = np.array([s.to_internal(1.0) for s in slots[n:]]) - u[n:]
    free = [k for k, s in enumerate(slots[:n]) if s.name != periodic_name(model.effects[s.where[1]])]  # a period: profiled
    if not free or not np.any(np.abs(move) > 1e-9):
        return {}
    h = {k: SPLIT_STEP * (1.0 if slots[k].log else max(abs(u[k]), 1e-3 * slots[k].span())) for k in free}
    up, down = ([np.where(np.arange(u.size) == k, np.clip(u[k] + sign * h[k], lo[k], hi[k]), u) for k in free] for sign in (1, -1))
    runs = evaluate([at_internal(x, slots, model) for x in up + down])
    if any(q is None for q in runs) or any(a[k] == b[k] for k, a, b in zip(free, up, down)):
        return {}
    local = np.column_stack([(runs[j] - runs[len(free) + j]) / (up[j][k] - down[j][k]) for j, k in enumerate(free)])
    line = np.zeros(len(slots))
    line[free] = refit_step(local, r + J[:, n:] @ move, u[free], lo[free], hi[free])[1]
    line[n:] = move
    points = [np.clip(u + t * line, lo, hi) for t in SPLIT_LINE]
    threshold = 1.96**2 / 2 * residual_variance(r, len(slots))
    excess = [math.inf if rt is None else 0.5 * float(rt @ rt - r @ r) + (0.0 if error is None else float(error @ (rt - r)))
              for rt in evaluate([at_internal(x, slots, model) for x in points])]
    line_t, excess = (0.0, *SPLIT_LINE), [0.0, *excess]
    last = max(j for j, x in enumerate(excess) if x <= threshold)  # the furthest point kept: the estimate at least
    reach = line_t[last]
    if last + 1 < len(excess) and math.isfinite(excess[last + 1]):  # on to where the excess crosses the threshold
        reach += (line_t[last + 1] - reach) * (threshold - excess[last]) / (excess[last + 1] - excess[last])
    end = np.clip(u + reach * line, lo, hi)
    return {k: (slots[k].to_value(min(u[k], end[k])), slots[k].to_value(max(u[k], end[k]))) for k in free} if reach > 0 else {}


def gentler_side(evaluate, model: Model, slots: list[Slot], u: np.ndarray, r: np.ndarray, J: np.ndarray, n: int) -> np.ndarray:
    """J with each of the first `n` columns (the effects' parameters) taken by a step the other way where that
    changes the residual less: a one-sided difference that steps over a cliff of the cost (a break-away the command
    no longer overcomes: the joint stays stuck) claims the parameter is known to the width of that cliff's foot.
    Seed 54, a Watflex dwell-time stiction found at gain 1.53, time constant 1.61 s (truth 0.60, 0.39 s): +0.15 of
    gain changed the residual by |dr| = 2.3e5 noise units against 390 for -0.15, and the gain's interval was +-0.002.
    The gentler side bounds how far the estimate can move with the cost within the noise on at least that side.
    A step the other way that a bound cuts to less than half the forward step's is no side at all: seed 77's
    two-joint watflex-8da6e87a, a one-way shoulder Coulomb friction whose other side was fitted at 8e-17 N m, stepped
    back 8e-17 to the bound, saw no change, and its column, so zeroed, gave that side its whole bounds [0, 65.8] N m
    (0.05 N m there costs 2.3 x the noise)."""
    if n == 0:
        return J
    J, back = J.copy(), []
    for i in range(n):
        v = np.array(u, float)
        v[i] = np.clip(u[i] - fd_step(slots[i], u[i]), slots[i].to_internal(slots[i].low), slots[i].to_internal(slots[i].high))
        back.append(v)
    runs = evaluate([at_internal(v, slots, model) for v in back])
    for i, (v, rv) in enumerate(zip(back, runs)):
        if rv is not None and abs(v[i] - u[i]) >= 0.5 * abs(fd_step(slots[i], u[i])):
            column = (rv - r) / (v[i] - u[i])
            if np.linalg.norm(column) < np.linalg.norm(J[:, i]):
                J[:, i] = column
    return J


def slice_reach(evaluate, model: Model, slots: list[Slot], i: int, r: np.ndarray, low: float, high: float,
                J: np.ndarray | None = None) -> tuple[float, float]:
    """Interval (low, high) of slot i widened to every probe along that slot, SLICE_STEPS x the interval's
    half-width on each side, whose profiled cost is within a threshold of the lowest seen: 1.96^2 / 2 x s^2
    (`residual_variance`: what the data's noise resolves), or, where more, 1.96 x the cost's roughness, the
    RMS departure of the inner probes from a parabola. The profiled cost is 0.5 |r|^2 with every other slot
    re-optimised to first order within its bounds (`refit_cost` on J's other columns, J in r's units; without
    J the others are held): a profile likelihood, linearised. On a smooth cost with the estimate at its
    minimum it adds nothing to the Jacobian's interval; where stick-slip makes the cost rough, a minimum is
    known only to where the smooth trend rises above the jumps, and a probe that beats the estimate shows
    the fit stopped short (seed 47, structural damping of link 2 at x14.516, interval [14.513, 14.522]: the
    cost at 14.49 is 51 lower, with jumps of +-400 between probes 0.01 apart; the truth is 14.48). Along a
    valley the others follow the probe, where a slice with them held climbs its wall at once: a bend the
    linear interval cuts short is reached, and the wall's climb is not taken for roughness (seed 55, a Watflex
    presliding's sigma1: [5.0, 19.3] N m s/rad held, [7.0, 13.8] profiled; truth 11.9).
    `r`: the residual of `model` in `evaluate`'s units."""
    slot = slots[i]
    u = np.array([s.to_internal(value_of(model, s)) for s in slots])
    lo = np.array([s.to_internal(s.low) for s in slots])
    hi = np.array([s.to_internal(s.high) for s in slots])
    others = [j for j in range(len(slots)) if j != i]

    def profiled(q: np.ndarray) -> float:
        if J is None or not others:
            return 0.5 * float(q @ q)
        return 0.5 * refit_cost(J[:, others], q, u[others], lo[others], hi[others])

    bottom, top = lo[i], hi[i]
    a, b = slot.to_internal(low), slot.to_internal(high)
    half = max(u[i] - a, b - u[i], 1e-4 * (top - bottom))
    points = sorted({float(np.clip(u[i] + sign * k * half, bottom, top)) for sign in (-1, 1) for k in SLICE_STEPS} - {float(u[i])})
    probes = []
    for x in points:
        v = u.copy()
        v[i] = x
        probes.append(at_internal(v, slots, model))
    costs = np.array([math.inf if q is None else profiled(q) for q in evaluate(probes)])
    cost0 = profiled(r)
    inner = [k for k, x in enumerate(points) if abs(x - u[i]) <= SLICE_STEPS[-2] * half * (1 + 1e-9) and math.isfinite(costs[k])]
    x = np.array([0.0] + [(points[k] - u[i]) / half for k in inner])
    c = np.array([cost0] + [costs[k] for k in inner])
    roughness = 0.0
    if x.size > 3:
        departure = c - np.polyval(np.polyfit(x, c, 2), x)
        roughness = math.sqrt(float(departure @ departure) / (x.size - 3))
    threshold = min(cost0, float(costs.min(initial=math.inf))) + max(1.96**2 / 2 * residual_variance(r, len(slots)), 1.96 * roughness)
    kept = [p for p, q in zip(points, costs) if q <= threshold]
    return slot.to_value(min([a] + kept)), slot.to_value(max([b] + kept))
