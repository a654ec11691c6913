"""Fitting: bounded Levenberg-Marquardt on the training residual, and 95 % intervals.

Contract: a fitted number is a `Slot` (where it goes in a `Model`, bounds, linear or log). `levenberg`
takes a function models -> residual vectors (None where a model diverges) and returns the model
with the lowest training cost it found; each iteration costs one simulation of the training data
(the Jacobian is kept current by Broyden updates). `intervals` turns a Jacobian at the solution into
95 % intervals in physical units, widened for the residual's serial correlation.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear

from ..effects import CATALOGUE
from ..engine import SimulationError
from .data import Data, Model
from .motion import scale_of
from .runner import evaluator, hold

log = logging.getLogger(__name__)


@dataclass
class Slot:
    """One fitted number: where it goes in a Model, its bounds and whether it is fitted in log."""

    where: tuple  # ("param", name) or ("effect", index, name | tuple of names tied together)
    low: float
    high: float
    log: bool = False

    def to_internal(self, x: float) -> float:
        return math.log(x) if self.log else x

    def to_value(self, u: float) -> float:
        return math.exp(u) if self.log else u

    def span(self) -> float:
        return math.log(self.high / self.low) if self.log else self.high - self.low

    @property
    def name(self) -> str:
        if self.where[0] == "param":
            return self.where[1]
        return self.where[2][0] if isinstance(self.where[2], tuple) else self.where[2]


def unpack(x, free: list[Slot], base: Model) -> Model:
    """Values (physical units) of the free slots -> Model."""
    model = Model([dict(e) for e in base.effects], dict(base.parameters))
    for value, slot in zip(x, free):
        if slot.where[0] == "param":
            model.parameters[slot.where[1]] = float(value)
        else:
            names = slot.where[2] if isinstance(slot.where[2], tuple) else (slot.where[2],)
            for name in names:
                model.effects[slot.where[1]][name] = float(value)
    return model


def at_internal(u, free: list[Slot], base: Model) -> Model:
    """Internal values (log where the slot is) of the free slots -> Model."""
    return unpack([s.to_value(x) for s, x in zip(free, u)], free, base)


def internal_start(free: list[Slot], x0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, low, high) in internal units: the start x0 (physical units) clipped into the slots' bounds."""
    lo = np.array([s.to_internal(s.low) for s in free])
    hi = np.array([s.to_internal(s.high) for s in free])
    return np.clip([s.to_internal(x) for s, x in zip(free, x0)], lo, hi), lo, hi


def refit_cost(J: np.ndarray, r: np.ndarray, u: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Sum of squares of the residual r once the slots of Jacobian J (internal units, at u, bounds lo..hi)
    are re-optimised to first order: min over the bounded step d of |r + J d|^2."""
    return refit_step(J, r, u, lo, hi)[0]


def refit_step(J: np.ndarray, r: np.ndarray, u: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[float, np.ndarray]:
    """(refit_cost, the step d that reaches it)."""
    if J.shape[1] == 0:
        return float(r @ r), np.zeros(0)
    span = np.where(hi > lo, hi - lo, 1.0)
    A = J * span
    z = lsq_linear(A, -r, bounds=((lo - u) / span, np.maximum(hi - u, lo - u + 1e-12) / span)).x
    return float(np.sum((r + A @ z) ** 2)), z * span


def value_of(model: Model, slot: Slot) -> float:
    if slot.where[0] == "param":
        return model.parameters.get(slot.where[1], 1.0)
    return model.effects[slot.where[1]][slot.name]


def rig_slots(data: Data) -> list[Slot]:
    """The rig's refit parameters as slots: ratios within 1 +- tolerance (rigs.md section 4), but those
    the recordings do not depend on (`data.idle`: a locked joint's, a link not mounted)."""
    return [Slot(("param", n), 1 - p["tolerance"], 1 + p["tolerance"]) for n, p in data.rig.parameters.items()
            if n not in data.idle]


def effect_slots_of(data: Data, model: Model) -> list[Slot]:
    """Slots of every parameter of the model's effects (catalogue bounds scaled to the data, the bounds widened to
    take the value; a cyclic one's a turn centred on its value)."""
    slots = []
    for i, effect in enumerate(model.effects):
        for p in CATALOGUE[effect["effect"]][1]:
            if p.name in effect and not p.quantum:  # a quantised one keeps the step it was found at
                size = scale_of(data, p, effect["where"])
                low, high = min(p.low * size, effect[p.name]), max(p.high * size, effect[p.name])
                if p.cyclic:  # one turn centred on its value: no wall at +-pi (seed 116, watflex-e9576ce5)
                    low, high = effect[p.name] - (p.high - p.low) / 2, effect[p.name] + (p.high - p.low) / 2
                slots.append(Slot(("effect", i, p.name), low, high, p.log))
    return slots


def parameter_count(data: Data, effect: dict) -> int:
    """The fitted parameters of one effect."""
    return len(effect_slots_of(data, Model([effect])))


def fd_step(slot: Slot, u: float) -> float:
    """Finite-difference step in internal units: large enough to see through stick-slip."""
    h = 0.1 if slot.log else 0.05 * slot.span()
    hi = slot.to_internal(slot.high)
    return h if u + h <= hi else -h


def jacobian(evaluate, base: Model, free: list[Slot], u: np.ndarray, r: np.ndarray,
             known: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """Columns d(residual)/d(internal value) at u; `known` columns (by slot index) are reused.
    `evaluate(models)` returns the residual vectors (None where a model diverged)."""
    known = dict(known or {})
    todo = [i for i in range(len(free)) if i not in known]
    steps, models = {}, []
    for i in todo:
        steps[i] = fd_step(free[i], u[i])
        v = np.array(u, float)
        v[i] += steps[i]
        models.append(at_internal(v, free, base))
    for i, rv in zip(todo, evaluate(models)):
        known[i] = np.zeros_like(r) if rv is None else (rv - r) / steps[i]
    return np.column_stack([known[i] for i in range(len(free))]) if free else np.zeros((r.size, 0))


T_REPLICATES = 2.36  # Student's t, 95 %, 7 degrees of freedom: the interval from 8 noise replicates' scatter
HUBER = 1.345  # x the residual's robust spread: beyond it a residual counts linearly (Huber's M-estimate)


def huber_threshold(r: np.ndarray) -> float:
    """Huber's threshold for residual `r`: HUBER x its robust standard deviation (1.4826 MAD) over its
    non-zero elements; inf for a residual without spread. A few large residuals no model explains (a
    real rig's unmodelled pulses) then pull the fit no more than their share. Exact zeros are left out
    of the spread: missing samples (a 25 Hz camera: 91 % of a 1 kHz recording) and a quantised channel
    that re-simulates to the same count (Watflex encoders and strain converters: half of all elements)
    would otherwise put the median at 0 and the threshold at ~1e-12, every residual of a model off by
    more than one count beyond it, and Levenberg-Marquardt's weights with it (its steps stalled at the
    start: a payload 2.4 % off at 15 x the truth's chi-square)."""
    r = r[r != 0]
    mad = float(np.median(np.abs(r - np.median(r)))) if r.size else 0.0
    return HUBER * 1.4826 * mad if mad > 0 else math.inf


def huber_cost(r: np.ndarray, k: float) -> float:
    """Sum of Huber's loss: r^2/2 within k, k|r| - k^2/2 beyond."""
    a = np.abs(r)
    if not math.isfinite(k):
        return float(0.5 * np.sum(a * a))
    return float(np.sum(np.where(a <= k, 0.5 * a * a, k * a - 0.5 * k * k)))


def levenberg(evaluate, base: Model, free: list[Slot], x0, J: np.ndarray | None = None,
              iters: int = 6, r0: np.ndarray | None = None) -> tuple[Model, float, np.ndarray]:
    """Bounded, robust Levenberg-Marquardt on the training residual: Huber's loss with its threshold
    from the starting residual (iteratively reweighted), the Jacobian given (signatures) or taken by
    finite differences once, then kept current by Broyden updates, so each iteration costs one
    simulation of the training data; it stops when a step gains less than 0.1 %. Returns (model, Huber
    cost, J)."""
    u, lo, hi = internal_start(free, x0)
    model = at_internal(u, free, base)
    r = r0 if r0 is not None else evaluate([model])[0]
    if r is None:
        raise SimulationError("the starting model diverges")
    if J is None:
        J = jacobian(evaluate, base, free, u, r)
    span = hi - lo
    k = huber_threshold(r)
    cost, lam = huber_cost(r, k), 1e-3
    for _ in range(iters):
        w = np.sqrt(np.where(np.abs(r) <= k, 1.0, k / np.maximum(np.abs(r), 1e-300)))
        A = (J * span) * w[:, None]
        scale = float(np.mean(np.sum(A * A, axis=0))) or 1.0
        M = np.vstack([A, math.sqrt(lam * scale) * np.eye(len(free))])
        z = lsq_linear(M, np.concatenate([-r * w, np.zeros(len(free))]), bounds=((lo - u) / span, (hi - u) / span)).x
        step = z * span
        if np.max(np.abs(z)) < 1e-5:
            break
        trial = at_internal(u + step, free, base)
        r_new = evaluate([trial])[0]
        if r_new is None:
            lam *= 10
            continue
        J = J + np.outer(r_new - r - J @ step, step) / float(step @ step)  # Broyden: the secant we saw
        new = huber_cost(r_new, k)
        log.debug("LM: cost %.6g -> %.6g (lambda %.2g, step %s)", cost, new, lam, np.round(z, 4))
        if new < cost:
            u, r, model, gained, cost = u + step, r_new, trial, (cost - new) / cost, new
            lam = max(lam / 5, 1e-6)
            if gained < 1e-3:
                break
        else:
            lam *= 5
    return model, cost, J


def refit_parameters(data: Data, base: Model, runner=None, J: np.ndarray | None = None, iters: int = 4) -> Model:
    """Refit the rig's parameters within their tolerances (rigs.md section 4) on the training data, in noise
    units as the diagnosis does (`J`, if given, in those units)."""
    free = rig_slots(data)
    if not free:
        return base
    if runner is None:
        hold(data)
    model, _, _ = levenberg(evaluator(runner, unit="noise"), base, free, [value_of(base, s) for s in free], J, iters)
    return model


def serial_inflation(r: np.ndarray) -> float:
    """How much serial correlation shrinks the information in residual `r`: (1 + phi) / (1 - phi)
    with phi its lag-1 autocorrelation (an AR(1) residual; 1 for white noise)."""
    if r.size < 3 or not np.any(r):
        return 1.0
    phi = float(np.clip(np.corrcoef(r[:-1], r[1:])[0, 1], 0.0, 0.99))
    return (1 + phi) / (1 - phi)


def residual_variance(r: np.ndarray, p: int) -> float:
    """Variance per degree of freedom of residual `r` after fitting `p` parameters, times the serial-correlation
    inflation: the s^2 that turns a cost change into a chi-square."""
    return float(r @ r) / (r.size - p) * serial_inflation(r)


def intervals(free: list[Slot], model: Model, J: np.ndarray, r: np.ndarray, prior_sd: list[float] | None = None,
              replicates: list[np.ndarray] | None = None, prior_mean: list[float] | None = None,
              model_error: np.ndarray | None = None) -> dict[int, tuple[float, float]]:
    """95 % intervals (physical units, within the slots' bounds) of the slots, by slot index:
    covariance (J'J / s^2 + P)^-1 with s^2 the residual variance per degree of freedom times the
    serial-correlation inflation, and P the precision of a Gaussian prior of sd `prior_sd` (internal
    units; inf: none) - a rig parameter's tolerance, so that one the data leave loose widens what it
    trades off with by no more than its tolerance allows; a parameter the residual does not depend on
    gets its whole bounds.

    `replicates`: residual changes e_k that the rig's noise makes (the model simulated with its noise on,
    minus off, in r's units). Each moves the linearised estimate by d_k = cov J' e_k / s^2; the interval
    is widened to T_REPLICATES x their standard deviation and stretched by their mean, the estimator's
    bias from the noise (in closed loop sensor noise moves the rig, and a noise-free re-simulation of it
    misses that; a rig at rest is dithered out of stick). The truth sits near estimate - mean.

    The interval also reaches the Gauss-Newton step from the estimate, -(J'WJ + s^2 P)^-1 J'W r (W: Huber's
    weights, as the fit has them): zero where the fit converged; where it stopped in a valley of a cost
    that stick-slip makes rough, the Jacobian (finite differences wide enough to see through the
    roughness) points to where the smooth part of the cost has its minimum, and the truth is as likely
    there (seed 5: a Stribeck break-away 0.7 % off, a link stiffness 1.4 % off, with intervals of +-0.05 %
    and +-0.8 %). With `prior_mean` (internal units, the datasheet's values) the step is the one to the posterior's
    mode, the prior pulling each rig parameter back to its datasheet value as far as the data let it: a fit that
    parked a rig parameter at its tolerance bound in a valley it shares with an effect's parameter (a hub's inertia at
    +3 % and a tip payload 1.6 % short, the truth at +0 % and 0.903 kg; seed 48) then reaches along that valley.

    `model_error`: how far the model's residual is from a more exact model's at the same parameters (in r's units;
    uncertainty.discretisation_error). Such an error biases a least-squares estimate by b = -cov J' e / s^2, in a
    direction the linearisation gets wrong (seed 41: a quarter of a payload's bias, the wrong sign for a Coulomb
    friction), but never by more than |b_i| <= |g_i| |P e|, g_i the i-th row of cov J' / s^2 (Cauchy-Schwarz; P e:
    the part of e the parameters' columns can absorb, the rest no fit can follow). Without a prior |g_i| = sd_i / s;
    with one, |g_i|^2 = (cov - cov P cov)_ii / s^2: the part of a parameter's spread that the prior alone sets (an
    effect's ratio turning the same knob as a rig parameter, tie_knob_columns) is no way for the data's error to move
    it (seed 56: a Watflex link 2 stiffness x1.26 got [0.02, 153], its whole bounds, from sd_i |P e| / s). The
    interval reaches that bound beyond the noise's: on the Watflex, where |P e| / s is 180-320 (e: twice what a
    2 x finer model changes), that is up to 180-320 sd, against estimates off by 10-270 sd on recordings of a 3 x
    finer model (seeds 51-53, docs/diagnosis.md)."""
    n, p = r.size, len(free)
    if p == 0 or n <= p:
        return {}
    s2 = residual_variance(r, p)
    prior = np.array([0.0 if not math.isfinite(sd) else sd**-2 for sd in (prior_sd or [math.inf] * p)])
    cov = np.linalg.pinv(J.T @ J / s2 + np.diag(prior)) if s2 > 0 else np.zeros((p, p))
    k = huber_threshold(r)
    weights = np.where(np.abs(r) <= k, 1.0, k / np.maximum(np.abs(r), 1e-300))
    u = np.array([slot.to_internal(value_of(model, slot)) for slot in free])
    pull = prior * (u - np.nan_to_num(np.array(prior_mean, float))) if prior_mean is not None else np.zeros(p)
    newton = (-np.linalg.pinv(J.T @ (weights[:, None] * J) + s2 * np.diag(prior)) @ (J.T @ (weights * r) + s2 * pull)
              if s2 > 0 else np.zeros(p))
    reach_error = np.zeros(p)
    if model_error is not None and s2 > 0:
        absorbed = J @ np.linalg.lstsq(J, model_error, rcond=None)[0]
        reach_error = np.linalg.norm(cov @ J.T, axis=1) / s2 * float(np.linalg.norm(absorbed))  # |g_i| |P e|
    shift, scatter = np.zeros(p), np.zeros(p)
    if replicates and len(replicates) >= 2 and s2 > 0:
        moves = np.array([cov @ (J.T @ e) / s2 for e in replicates])
        shift, scatter = moves.mean(axis=0), moves.std(axis=0, ddof=1)
    out = {}
    for i, slot in enumerate(free):
        sd = math.sqrt(max(float(cov[i, i]), 0.0))
        if not np.any(J[:, i]) or not math.isfinite(sd):
            out[i] = (slot.low, slot.high)
            continue
        half = max(1.96 * sd, T_REPLICATES * float(scatter[i])) + float(reach_error[i])
        reach = (u[i], u[i] - shift[i], u[i] + newton[i])
        lo, hi = slot.to_value(min(reach) - half), slot.to_value(max(reach) + half)
        out[i] = (float(max(lo, slot.low)), float(min(hi, slot.high)))
    return out
