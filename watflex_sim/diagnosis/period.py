"""A ripple's period profiled: the cost along the one parameter the Jacobian cannot carry.

Contract: `period_profile(evaluate, model, index, slots, J, periods)` returns, for each period, the model with
effect `index`'s ripple (effects.Param.periodic) at that period and every other slot re-optimised, and its cost
0.5 |r|^2 (in `evaluate`'s units), the others re-optimised to first order. `profile_reach(...)` returns, per
effect parameter, the range of its values over the profile's points the data cannot tell from the best of them
(`limits`: the noise along each difference, the discretisation's shift), for the 95 % intervals. `profile_ladder`
gives the periods to try around an estimate, `neutral_others` a ripple's spring at 0.

Why: at a given period a ripple a sin(2 pi x / period + phase) is linear, to first order, in the a sin + b cos it
is, and the other slots in their Jacobian's columns, so a linear solve at each period is a profile likelihood. Where
the motion covers a small part of a cycle (the laser arm's hub moves 2.3 mrad; ripples of 20-30 mrad), the ripple is
a bend over the range that a nearby period, another phase and amplitude and a spring make as well: a curved valley
whose length no Jacobian at one end of it sees (seed 62, laser_arm-a39fc2ab: found at 17.7 mrad with a spring of
2.0 N m/rad, interval [0.78, 2.85]; the truth, 19.9 mrad and no spring, fits 15 cost units better).
"""
from __future__ import annotations

import math

import numpy as np

from ..effects import CATALOGUE
from .data import Model
from .fitting import Slot, at_internal, refit_step, residual_variance, value_of
from .motion import neutral_values

PROFILE_RATIO = 1.12  # one period of the profile to the next
PROFILE_STEPS = 4  # periods each side of the estimate at first ...
PROFILE_MORE = 4  # ... and this many more on a side whose outermost is still within its limit, up to the bound
PROFILE_ROUNDS = 3  # at most this many times a side


def periodic_name(effect: dict) -> str:
    """The effect's periodic parameter's name, '' if it has none."""
    return next((p.name for p in CATALOGUE[effect["effect"]][1] if p.periodic and p.name in effect), "")


def profile_ladder(slot: Slot, estimate: float, steps: range) -> list[float]:
    """Periods estimate x PROFILE_RATIO^k for k in `steps`, within the slot's bounds."""
    return sorted({min(max(estimate * PROFILE_RATIO**k, slot.low), slot.high) for k in steps})


def _ripple(a: float, b: float, sign: float, phase0: float, slot: Slot) -> dict[str, float]:
    """a sin + b cos as an amplitude of the estimate's sign (within its slot) and a phase (rad) within pi of the
    estimate's `phase0`."""
    amplitude, phase = math.hypot(a, b), math.atan2(b, a)
    if sign < 0:
        amplitude, phase = -amplitude, phase + math.pi
    return {"amplitude": float(np.clip(amplitude, slot.low, slot.high)),
            "phase": phase0 + (phase - phase0 + math.pi) % (2 * math.pi) - math.pi}


def period_profile(evaluate, model: Model, index: int, slots: list[Slot], J: np.ndarray, periods: list[float],
                   held: dict[str, float] | None = None, checked: int | None = None) -> list[tuple[float, Model, float, np.ndarray]]:
    """(period, model, profiled cost, its residual) for each period of `periods` where the simulations run: the
    ripple of `model.effects[index]` re-solved as a sin + b cos together with every other slot (J's columns, internal
    units, in `evaluate`'s units), then one Gauss-Newton step more from a simulation there; the cost is that step's
    linear prediction, 0.5 |r + J d|^2 (as reach.slice_reach profiles), and r + J d its residual.
    Simulations: one without the ripple, two per period (phase 0 and pi/2 at the estimate's amplitude) and one at
    each solution. `held`: parameters of the ripple's effect held at these values (a spring at its neutral 0);
    `checked`: only the periods whose linear solve leaves the least residual, this many, are simulated there (a scan
    that wants the best, not the whole profile)."""
    held = held or {}
    if held:
        model = Model([dict(e, **(held if i == index else {})) for i, e in enumerate(model.effects)], dict(model.parameters))
    effect = model.effects[index]
    period = periodic_name(effect)
    own = {"amplitude", "phase", period, *held}
    keep = [k for k, s in enumerate(slots) if not (s.where[0] == "effect" and s.where[1] == index and s.name in own)]
    amp = next(s for s in slots if s.where[:2] == ("effect", index) and s.name == "amplitude")
    size = abs(effect["amplitude"]) or 0.02 * (amp.high - amp.low)
    sign, phase0 = (-1.0 if effect["amplitude"] < 0 else 1.0), effect["phase"]
    u = np.array([slots[k].to_internal(value_of(model, slots[k])) for k in keep])
    lo = np.array([slots[k].to_internal(slots[k].low) for k in keep] + [-amp_bound(amp)] * 2)
    hi = np.array([slots[k].to_internal(slots[k].high) for k in keep] + [amp_bound(amp)] * 2)
    kept_slots = [slots[k] for k in keep]

    def at(p: float, x: np.ndarray) -> Model:
        m = at_internal(x[:-2], kept_slots, model)
        m.effects[index].update({period: p, **_ripple(x[-2], x[-1], sign, phase0, amp)})
        return m

    def ripple_only(p: float, phase: float, amplitude: float) -> Model:
        return Model([dict(e, **({period: p, "amplitude": amplitude, "phase": phase} if i == index else {}))
                      for i, e in enumerate(model.effects)], dict(model.parameters))

    runs = evaluate([ripple_only(effect[period], 0.0, 0.0)]
                    + [ripple_only(p, phase, size) for p in periods for phase in (0.0, math.pi / 2)])
    r0 = runs[0]
    if r0 is None:
        return []
    start = np.concatenate([u, [0.0, 0.0]])
    solved = []
    for k, p in enumerate(periods):
        r_sin, r_cos = runs[1 + 2 * k], runs[2 + 2 * k]
        if r_sin is None or r_cos is None:
            continue
        columns = np.column_stack([J[:, keep], (r_sin - r0) / size, (r_cos - r0) / size])
        left, step = refit_step(columns, r0, start, lo, hi)
        solved.append((left, p, columns, start + step))
    solved = [x[1:] for x in sorted(solved, key=lambda x: x[0])[:checked]] if checked else [x[1:] for x in solved]
    return stepped(evaluate, solved, at, lo, hi)


def stepped(evaluate, solved: list, at, lo: np.ndarray, hi: np.ndarray) -> list[tuple[float, Model, float, np.ndarray]]:
    """A profile's points from its solves: for each (value, columns, x) of `solved` whose model `at(value, x)` runs,
    one Gauss-Newton step more on those columns from a simulation there, within the bounds lo, hi: (value, the model
    stepped, the step's linear prediction of the cost 0.5 |r + J d|^2, r + J d)."""
    out = []
    for (v, columns, x), r in zip(solved, evaluate([at(v, x) for v, _, x in solved])):
        if r is not None:
            left, step = refit_step(columns, r, x, lo, hi)
            out.append((v, at(v, x + step), 0.5 * left, r + columns @ step))
    return out


def amp_bound(slot: Slot) -> float:
    """The largest |a| or |b| of a ripple's a sin + b cos: its amplitude slot's largest magnitude."""
    return max(abs(slot.low), abs(slot.high))


def limits(points: list, r: np.ndarray, p: int, replicates: list[np.ndarray], error: np.ndarray | None) -> list[float]:
    """The cost each profile point (period_profile's) must stay under for the data not to tell it from the best of
    them: the least cost + 1.96^2 / 2 x s^2, s^2 the noise's variance along the difference of their residuals g (the
    residual's variance per degree of freedom, or where more, that of g.e / |g| over `replicates`, the rig's noise
    fed back in closed loop: 2.4-3.3 x on the laser arm's hub ripple, seed 62), + what our own discretisation
    (`error`, uncertainty.discretisation_error) can shift the cost difference by, |g.error|."""
    if not points:
        return []
    best = min(points, key=lambda x: x[2])
    s2 = residual_variance(r, p)
    out = []
    for _, _, _, q in points:
        g = q - best[3]
        gg = float(g @ g)
        noise = max([s2] + ([float(np.mean([(g @ e) ** 2 for e in replicates])) / gg] if replicates and gg > 0 else []))
        out.append(best[2] + 1.96**2 / 2 * noise + (abs(float(g @ error)) if error is not None else 0.0))
    return out


def within(points: list, r: np.ndarray, p: int, replicates: list[np.ndarray], error: np.ndarray | None) -> list[bool]:
    """Which profile points the data cannot tell from the best of them (`limits`)."""
    return [x[2] <= limit for x, limit in zip(points, limits(points, r, p, replicates, error))]


def neutral_others(data, effect: dict) -> dict[str, float]:
    """The values at which a ripple's parameters other than its amplitude vanish (a spring's 0), in the data's
    units (motion.scale_of)."""
    return {n: v for n, v in neutral_values(data, effect).items() if n != "amplitude"}


def _walk(evaluate, model: Model, index: int, slots: list[Slot], J: np.ndarray, r: np.ndarray,
          replicates: list[np.ndarray], error: np.ndarray | None, held: dict[str, float]) -> list:
    """period_profile's points along effect `index`'s period (`walk`)."""
    slot = next(s for s in slots if s.where[:2] == ("effect", index) and s.name == periodic_name(model.effects[index]))
    estimate = model.effects[index][slot.name]
    return walk(lambda periods: period_profile(evaluate, model, index, slots, J, periods, held),
                lambda steps: profile_ladder(slot, estimate, steps), (slot.low, slot.high), r, len(slots), replicates, error)


def walk(profile, ladder, bounds: tuple[float, float], r: np.ndarray, p: int, replicates: list[np.ndarray],
         error: np.ndarray | None) -> list:
    """A profile's points (`profile(values)`: (value, model, cost, residual) each) at `ladder(steps)`: PROFILE_STEPS
    values either side of the estimate, then PROFILE_MORE more on a side whose outermost is `within` and not at one of
    `bounds`, PROFILE_ROUNDS times at most."""
    points = profile(ladder(range(-PROFILE_STEPS, PROFILE_STEPS + 1)))
    reach = {"low": -PROFILE_STEPS, "high": PROFILE_STEPS}
    for _ in range(PROFILE_ROUNDS if points else 0):
        ok = dict(zip([x[0] for x in points], within(points, r, p, replicates, error)))
        more = []
        for side, sign in (("low", -1), ("high", 1)):
            outer = min(ok) if side == "low" else max(ok)
            if ok[outer] and outer not in bounds:
                more += ladder(range(reach[side] + sign, reach[side] + sign * (PROFILE_MORE + 1), sign))
                reach[side] += sign * PROFILE_MORE
        if not more:
            break
        points += profile(sorted(set(more) - set(ok)))
    return points


def profile_reach(evaluate, model: Model, index: int, slots: list[Slot], J: np.ndarray, r: np.ndarray,
                  replicates: list[np.ndarray], error: np.ndarray | None,
                  held: dict[str, float] | None = None) -> dict[int, tuple[float, float]]:
    """Per slot of an effect (index into `slots`), the range of its values over the points of effect `index`'s
    period profile that the data cannot tell from the best (`limits`), walked out from the estimate (`_walk`) with
    the ripple's other parameters free and, given `held`, again with them held there (a spring at 0: a spring and
    a ripple over a small part of its cycle trade, seed 61 laser_arm-40d67509: a spring of 6.4 N m/rad found, the
    truth's 0 at the same cost); between a point within and its neighbour beyond, to where the cost, linearly
    interpolated, crosses the limit (the grid's last point within stops short of the region's edge: seed 62,
    laser_arm-a39fc2ab, a period interval reaching 19.89 mrad, the truth 19.93). Profiled: the period, and with it
    the amplitude, phase, a spring and every other effect's parameters."""
    walks = [_walk(evaluate, model, index, slots, J, r, replicates, error, variant) for variant in ([{}, held] if held else [{}])]
    return reach_of(walks, slots, r, replicates, error)


def reach_of(walks: list[list], slots: list[Slot], r: np.ndarray, replicates: list[np.ndarray],
             error: np.ndarray | None) -> dict[int, tuple[float, float]]:
    """Per effect slot (index into `slots`), the range of its values over the points of `walks` (profiles' points,
    (value, model, cost, residual) each) that the data cannot tell from the best of them all (`limits`), and on to
    where the cost, linear between a point within and its neighbour beyond, crosses the limit."""
    bound = iter(limits([x for w in walks for x in w], r, len(slots), replicates, error))
    effect_slots = [k for k, s in enumerate(slots) if s.where[0] == "effect"]
    reached: dict[int, list[float]] = {k: [] for k in effect_slots}
    for w in walks:
        rows = sorted(((x[0], x[1], x[2], next(bound)) for x in w), key=lambda x: x[0])
        for k in effect_slots:
            u = [slots[k].to_internal(value_of(m, slots[k])) for _, m, _, _ in rows]
            for n, (_, _, cost, limit) in enumerate(rows):
                if cost > limit:
                    continue
                reached[k].append(u[n])
                for m in (n - 1, n + 1):  # toward a neighbour beyond the limit: where the cost crosses it (the
                    # limits differ point by point: one below this point's cost crosses here, not past it)
                    if 0 <= m < len(rows) and rows[m][2] > rows[m][3]:
                        f = min(max((rows[m][3] - cost) / (rows[m][2] - cost), 0.0), 1.0)
                        reached[k].append(u[n] + f * (u[m] - u[n]))
    return {k: (max(slots[k].to_value(min(v)), slots[k].low), min(slots[k].to_value(max(v)), slots[k].high))
            for k, v in reached.items() if v}
