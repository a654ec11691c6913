"""Diagnosis: where simulation and recordings differ, which physics is missing, fitted and shown.

Stages (each in the report): re-simulate every recording with the nominal model; refit the
rig's parameters within their tolerances (rig description); locate the mismatch (channel,
window, regime); fit the catalogue effects the rig allows, in parallel processes, on the
training part of the data; keep the one that improves the held-out part most, if it beats the
noise and a complexity penalty; try a second one on top; explain.
"""
from __future__ import annotations

import logging
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .effects import CATALOGUE
from .engine import SimulationError
from .metrics import correlation, nrmse
from .model import ConfigError
from .recording import Recording
from .resim import resimulate
from .rigdesc import RigDescription, load_rig

log = logging.getLogger(__name__)

MIN_GAIN = 0.02  # training NRMSE must fall by this fraction per fitted parameter, at least
HELD_TOLERANCE = 0.005  # and the held-out NRMSE must not rise by more than this fraction
NOISE_MARGIN = 1.3  # a fit within this factor of the noise floor leaves nothing to explain
BLOCK_S = 0.5  # s: held-out time blocks when there is a single recording
FIT_SECONDS = 12.0  # s: at most this much of each training recording is fitted; the rest is held out
STRIDE = 4  # samples: residuals are taken every STRIDE samples while fitting


@dataclass
class Model:
    """A candidate model: effects (catalogue entries with parameters) and refit parameter ratios."""

    effects: list[dict] = field(default_factory=list)
    parameters: dict[str, float] = field(default_factory=dict)


@dataclass
class Data:
    """The recordings of one rig, the channels compared, their scales and the train/held-out split."""

    recordings: list[Recording]
    names: list[str]
    rig: RigDescription
    channels: list[list[str]]  # per recording
    scale: list[dict[str, float]]  # per recording: channel -> RMS spread (its unit)
    noise_floor: list[dict[str, float]]  # per recording: channel -> NRMSE noise alone gives
    train: list[np.ndarray]  # per recording: boolean mask of training samples
    how: str = ""


def prepare(recordings: list[Recording], names: list[str]) -> Data:
    """Check the recordings share one rig and have comparable channels; split train/held-out."""
    rigs = {r.rig for r in recordings}
    if len(rigs) != 1:
        raise ConfigError(f"recordings of different rigs in one diagnosis: {', '.join(sorted(rigs))}")
    rig = load_rig(rigs.pop())
    outputs = set(rig.of_kind("measured"))
    channels, scale, floor, train = [], [], [], []
    for rec, name in zip(recordings, names):
        closed = rec.meta.get("mode", "closed_loop") != "open_loop"
        wanted = outputs | (set(rig.of_kind("command")) if closed else set())
        chans = [c for c in rec.channels if c in wanted and np.isfinite(rec.channels[c]).sum() > 10
                 and np.nanstd(rec.channels[c]) > 0]  # a constant channel (a locked joint) tells nothing
        if not chans:
            raise ConfigError(f"{name}: no measured channel of rig {rig.name} to compare")
        if rec.time[-1] - rec.time[0] < 0.05:
            raise ConfigError(f"{name}: recording shorter than 50 ms, too short to simulate")
        spread = {c: float(np.nanstd(rec.channels[c])) or 1.0 for c in chans}
        channels.append(chans)
        scale.append(spread)
        floor.append({c: float(rig.channels[c].get("noise", 0.0)) / spread[c] for c in chans})
    if len(recordings) >= 2:  # the last recording is held out, so every other condition is fitted
        last = len(recordings) - 1
        for i, rec in enumerate(recordings):
            train.append((rec.time - rec.time[0] < FIT_SECONDS) & (i != last))
        how = (f"fit on the first {FIT_SECONDS:g} s of " + ", ".join(names[:-1]) + f"; judged on {names[-1]}"
               + " and the rest of the others")
    else:
        t = recordings[0].time - recordings[0].time[0]
        train.append((t // BLOCK_S) % 2 == 0)
        how = f"fit on alternate {BLOCK_S:g} s blocks, judged on the blocks in between"
    return Data(recordings, names, rig, channels, scale, floor, train, how)


def simulate_all(data: Data, model: Model, part: str = "all") -> list[Recording] | None:
    """The recordings re-simulated with `model` (those with samples in `part`; the others are left
    as the measurement itself, contributing nothing); None if a simulation diverged."""
    try:
        return [resimulate(r, model.effects, model.parameters, until=_last_time(r, t, part)) if _in_part(t, part).any() else r
                for r, t in zip(data.recordings, data.train)]
    except SimulationError as exc:
        log.info("model %s diverged: %s", model, exc)
        return None


def _last_time(rec: Recording, train: np.ndarray, part: str) -> float | None:
    """Time (s from the start) after which no sample of `part` is needed: the simulation may stop."""
    if part != "train":
        return None
    return float(rec.time[np.flatnonzero(train)[-1]] - rec.time[0])


def _in_part(train: np.ndarray, part: str) -> np.ndarray:
    return {"train": train, "held_out": ~train, "all": np.ones_like(train)}[part]


def residual_vector(data: Data, sims: list[Recording], part: str = "train", stride: int = STRIDE) -> np.ndarray:
    """(simulated - measured) / spread over the chosen part ('train', 'held_out', 'all')."""
    pieces = []
    for rec, sim, chans, scale, train in zip(data.recordings, sims, data.channels, data.scale, data.train):
        mask = _in_part(train, part)
        if not mask.any():
            continue
        idx = np.flatnonzero(mask)[::stride]
        for c in chans:
            r = (sim.channels[c][idx] - rec.channels[c][idx]) / scale[c]
            pieces.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(pieces) if pieces else np.zeros(1)


def fit_scores(data: Data, sims: list[Recording] | None, part: str = "all") -> dict:
    """Mean NRMSE and correlation over channels and recordings (recordings.md), on a part."""
    if sims is None:
        return {"nrmse": math.inf, "correlation": 0.0}
    errors, corrs = [], []
    for rec, sim, chans, train in zip(data.recordings, sims, data.channels, data.train):
        mask = _in_part(train, part)
        if mask.sum() < 10:
            continue
        for c in chans:
            errors.append(nrmse(rec.channels[c][mask], sim.channels[c][mask]))
            corrs.append(correlation(rec.channels[c][mask], sim.channels[c][mask]))
    return {"nrmse": float(np.nanmean(errors)), "correlation": float(np.nanmean(corrs))}


def noise_nrmse(data: Data) -> float:
    """Mean NRMSE that measurement noise alone leaves (rig description noise levels)."""
    return float(np.mean([v for floor in data.noise_floor for v in floor.values()]))


# --- fitting ---------------------------------------------------------------------------------


def _unpack(x: np.ndarray, free: list[tuple], base: Model) -> Model:
    """Parameter vector -> Model. `free` entries: ("param", name) or ("effect", index, param)."""
    model = Model([dict(e) for e in base.effects], dict(base.parameters))
    for value, slot in zip(x, free):
        if slot[0] == "param":
            model.parameters[slot[1]] = float(value)
        else:  # one effect parameter, or a tuple of them tied to one value
            for name in (slot[2] if isinstance(slot[2], tuple) else (slot[2],)):
                model.effects[slot[1]][name] = float(value)
    return model


def fit(data: Data, base: Model, free: list[tuple], x0, lower, upper, max_evals: int = 40) -> tuple[Model, float]:
    """Least squares on the training residuals over the `free` slots; returns (model, cost)."""
    def residuals(x):
        sims = simulate_all(data, _unpack(x, free, base), "train")
        if sims is None:
            return np.full(_n_residuals(data), 1e3)
        return residual_vector(data, sims)

    x0 = np.clip(np.asarray(x0, float), lower, upper)
    span = np.asarray(upper, float) - np.asarray(lower, float)
    result = least_squares(residuals, x0, bounds=(lower, upper), x_scale=span, diff_step=1e-3,
                           max_nfev=max_evals, method="trf")
    return _unpack(result.x, free, base), float(result.cost)


def _n_residuals(data: Data) -> int:
    return sum(len(np.flatnonzero(t)[::STRIDE]) * len(c) for t, c in zip(data.train, data.channels))


def refit_parameters(data: Data, base: Model) -> Model:
    """Refit the rig's parameters within their tolerances (rigs.md §4) on the training data."""
    names = list(data.rig.parameters)
    if not names:
        return base
    tol = np.array([data.rig.parameters[n]["tolerance"] for n in names])
    model, _ = fit(data, base, [("param", n) for n in names], [base.parameters.get(n, 1.0) for n in names], 1 - tol, 1 + tol)
    return model


def candidates(rig: RigDescription, have: list[dict]) -> list[tuple[str, str]]:
    """(effect, where) pairs the rig allows and the model does not have yet."""
    taken = {(e["effect"], e["where"]) for e in have}
    return [(effect, where) for effect, places in rig.effects.items() for where in places
            if (effect, where) not in taken]


def scale_of(data: Data, param, where: str) -> float:
    """The size a scaled catalogue parameter is measured in (effects.Param.scale), from the data."""
    if not param.scale:
        return 1.0
    efforts, speeds, values = [], [], []
    for rec in data.recordings:
        for c in data.rig.of_kind("command"):
            if c in rec.channels:
                efforts.append(np.sqrt(np.nanmean(rec.channels[c] ** 2)) * data.rig.channels[c].get("gain", 1.0))
        motion = _motion_channel(rec, data.rig)
        if motion:
            speeds.append(np.sqrt(np.mean(np.gradient(rec.channels[motion], rec.time) ** 2)))
        if where in rec.channels:
            values.append(np.sqrt(np.nanmean(rec.channels[where] ** 2)) if param.scale == "command"
                          else float(np.nanstd(rec.channels[where])))
    effort = max(efforts, default=1.0) or 1.0
    if param.scale == "effort":
        return effort
    if param.scale == "effort/speed":
        return effort / (max(speeds, default=1.0) or 1.0)
    return max(values, default=1.0) or 1.0


def fit_candidate(args) -> dict:
    """Fit one (effect, where) on top of `base` (worker process); return its scores.

    `budget` bounds the least-squares evaluations (a short one screens candidates); with
    `joint`, the rig's parameters are refit together with the effect, within their tolerances."""
    data, base, effect, where, budget, joint = args
    _, params, _ = CATALOGUE[effect]
    sizes = [scale_of(data, p, where) for p in params]
    new = dict(effect=effect, where=where)
    for p, size in zip(params, sizes):
        new[p.name] = p.start * size
    trial = Model(base.effects + [new], dict(base.parameters))
    index = len(trial.effects) - 1
    free = [("effect", index, p.name) for p in params]
    x0, lower, upper = [new[p.name] for p in params], [p.low * z for p, z in zip(params, sizes)], [p.high * z for p, z in zip(params, sizes)]
    if joint:
        for name, spec in data.rig.parameters.items():
            free.append(("param", name))
            x0.append(base.parameters.get(name, 1.0))
            lower.append(1 - spec["tolerance"])
            upper.append(1 + spec["tolerance"])
    try:
        model, cost = fit(data, trial, free, x0, lower, upper, max_evals=budget)
    except Exception as exc:  # noqa: BLE001 - a candidate that fails is dropped and reported, never fatal
        return {"effect": effect, "where": where, "error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"}
    sims = simulate_all(data, model)
    if sims is None:
        return {"effect": effect, "where": where, "error": "the fitted model diverges"}
    return {"effect": effect, "where": where, "model": model, "n_params": len(params), "cost": cost,
            "train": fit_scores(data, sims, "train"), "held_out": fit_scores(data, sims, "held_out"),
            "all": fit_scores(data, sims, "all")}


def offset_alternative(data: Data, base: Model, result: dict, train_now: float, held: float) -> dict | None:
    """Asymmetric Coulomb levels a (positive) != b (negative) are also symmetric friction plus a
    constant actuator bias f = (b - a)/2 pushing the positive way: the two cannot be told apart
    in steady sliding, only at rest. Fit that alternative (as many parameters) jointly with the
    rig's parameters and return it scored like a candidate, or None if it does not apply."""
    if result["effect"] != "coulomb_friction":
        return None
    found = result["model"].effects[-1]
    a, b, where = found["torque_positive"], found["torque_negative"], found["where"]
    channel = next((c for c in data.rig.effects.get("actuator_offset", [])
                    if data.rig.channels.get(c, {}).get("joint") == where), None)
    if channel is None or abs(a - b) <= 0.05 * (a + b) / 2:
        return None
    gain = data.rig.channels[channel].get("gain", 1.0)
    trial = Model(base.effects + [dict(effect="coulomb_friction", where=where, torque_positive=(a + b) / 2, torque_negative=(a + b) / 2),
                                  dict(effect="actuator_offset", where=channel, offset=(b - a) / 2 / gain)],
                  dict(result["model"].parameters))
    i = len(trial.effects) - 2
    free = [("effect", i, ("torque_positive", "torque_negative")), ("effect", i + 1, "offset")]
    x0, lower, upper = [(a + b) / 2, (b - a) / 2 / gain], [0.0, -abs(a - b) / gain], [2 * max(a, b), abs(a - b) / gain]
    for name, spec in data.rig.parameters.items():
        free.append(("param", name))
        x0.append(trial.parameters.get(name, 1.0))
        lower.append(1 - spec["tolerance"])
        upper.append(1 + spec["tolerance"])
    model, _ = fit(data, trial, free, x0, lower, upper, max_evals=20)
    sims = simulate_all(data, model)
    if sims is None:
        return None
    train, held_out = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    out = {"effect": "coulomb_friction", "where": where, "model": model, "n_params": 2, "train": train,
           "held_out": held_out, "train_gain": (train_now - train["nrmse"]) / train_now,
           "held_gain": (held - held_out["nrmse"]) / held}
    out["score"] = out["train_gain"] + out["held_gain"] - MIN_GAIN * 2
    return out


def run_candidates(data: Data, base: Model, pairs: list[tuple[str, str]], workers: int, budget: int,
                   joint: bool = False) -> list[dict]:
    """Fit every candidate, in `workers` processes (MuJoCo callbacks are global: one model per process)."""
    jobs = [(data, base, e, w, budget, joint) for e, w in pairs]
    if workers <= 1 or len(jobs) <= 1:
        return [fit_candidate(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(fit_candidate, jobs))


# --- where the mismatch is -------------------------------------------------------------------

WINDOW_S = 0.05  # s, moving-RMS window of the residual


def _motion_channel(rec: Recording, rig: RigDescription) -> str | None:
    """The measured joint position (rad or m) that moves most in the recording: what 'motion' means."""
    positions = [c for c in rig.of_kind("measured") if c in rec.channels
                 and rig.channels[c]["unit"] in ("rad", "m") and not c.startswith("tip_")]
    return max(positions, key=lambda c: float(np.nanstd(rec.channels[c])), default=None)


def regimes(rec: Recording, rig: RigDescription, i0: int, i1: int) -> str:
    """Words for what the rig was doing in samples i0..i1: direction, rest, reversal, saturation."""
    words = []
    motion = _motion_channel(rec, rig)
    if motion:
        q = rec.channels[motion]
        dt = float(np.median(np.diff(rec.time)))
        v = np.gradient(q, dt)[i0:i1]
        span = float(np.nanmax(np.abs(np.gradient(q, dt)))) or 1.0
        moving = np.abs(v) > 0.05 * span
        if moving.mean() < 0.2:
            words.append(f"near zero velocity ({motion} at rest)")
        else:
            up, down = (v > 0.05 * span).mean(), (v < -0.05 * span).mean()
            if up > 0.1 and down > 0.1:
                words.append("velocity reversal")
            words.append("positive motion" if up >= down else "negative motion")
    for c in rig.of_kind("command"):
        limit = rig.channels[c].get("limit")
        if c in rec.channels and limit and np.nanmax(np.abs(rec.channels[c][i0:i1])) >= 0.98 * limit:
            words.append(f"{c} saturated")
    if i1 >= 0.8 * rec.time.size:
        words.append("steady state")
    return ", ".join(words) or "transient"


def locate(data: Data, sims: list[Recording], top: int = 8) -> list[dict]:
    """Windows where the residual stands out of the noise: recording, channel, times (s), regime, score.

    score = RMS residual in the window / channel spread (a local NRMSE)."""
    found = []
    for rec, sim, name, chans, scale, floor in zip(data.recordings, sims, data.names, data.channels,
                                                   data.scale, data.noise_floor):
        dt = float(np.median(np.diff(rec.time)))
        width = max(3, int(WINDOW_S / dt))
        kernel = np.ones(width) / width
        for c in chans:
            r = np.nan_to_num((sim.channels[c] - rec.channels[c]) / scale[c])
            rms = np.sqrt(np.convolve(r**2, kernel, mode="same"))
            threshold = max(3 * floor[c], 0.5 * float(np.sqrt(np.mean(r**2))), 1e-3)
            hot = rms > threshold
            edges = np.flatnonzero(np.diff(np.r_[0, hot.astype(int), 0]))
            for i0, i1 in zip(edges[::2], edges[1::2]):
                if i1 - i0 < width:
                    continue
                found.append({"recording": name, "channel": c, "t_start": float(rec.time[i0]),
                              "t_end": float(rec.time[i1 - 1]), "regime": regimes(rec, data.rig, i0, i1),
                              "score": float(np.sqrt(np.mean(r[i0:i1] ** 2)))})
    found.sort(key=lambda w: -w["score"])
    return found[:top]


# --- the whole diagnosis ---------------------------------------------------------------------

EXPLAIN = {
    "coulomb_friction": "dry friction at {where}: the joint sticks below {torque_positive:.3g} (positive) / {torque_negative:.3g} (negative) and slides against that level",
    "stribeck_friction": "break-away at {where} above the sliding level by {breakaway_positive:.3g} / {breakaway_negative:.3g}, decaying with speed (v_s {v_s:.3g})",
    "viscous_friction": "extra viscous friction at {where}: {coefficient:.4g} (positive) / {coefficient_negative:.4g} (negative motion) per unit speed",
    "presliding": "elastic pre-sliding at {where} (bristle stiffness {sigma0:.3g}, damping {sigma1:.3g})",
    "dwell_time_stiction": "break-away at {where} grows with time at rest (gain {gain:.3g}, time constant {time_constant:.3g} s)",
    "position_dependent_friction": "a torque at {where} that varies with angle (amplitude {amplitude:.3g}, period {period:.3g}, spring {spring:.3g})",
    "backlash": "a dead band of {width:.3g} between {where} and its link",
    "joint_compliance": "a torsional spring of {stiffness:.4g} between {where} and its link",
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


def _finding(result: dict, model: Model, before: float, after: float, mismatch: list[dict],
             train_before: float = math.nan) -> dict:
    effect = next(e for e in model.effects if e["effect"] == result["effect"] and e["where"] == result["where"])
    params = {k: v for k, v in effect.items() if k not in ("effect", "where")}
    units = {p.name: p.unit for p in CATALOGUE[result["effect"]][1]}
    direction = "both"
    if "torque_positive" in params or "breakaway_positive" in params or "coefficient_negative" in params:
        a, b = list(params.values())[:2]
        direction = "both" if abs(a - b) <= 0.1 * max(abs(a), abs(b), 1e-12) else ("positive" if abs(a) > abs(b) else "negative")
    hot = [w for w in mismatch][:3]
    evidence = "; ".join(f"{w['channel']} off by {w['score']:.2f} of its spread in {w['recording']} "
                         f"{w['t_start']:.2f}-{w['t_end']:.2f} s ({w['regime']})" for w in hot)
    return {
        "effect": result["effect"], "where": result["where"], "direction": direction,
        "parameters": params, "units": {k: units.get(k, "") for k in params},
        "explanation": EXPLAIN[result["effect"]].format(where=result["where"], **{**{p.name: p.start for p in CATALOGUE[result["effect"]][1]}, **params}),
        "evidence": (f"residual: {evidence}. " if evidence else "") +
                    f"With this effect fitted: training NRMSE {train_before:.4f} -> {result['train']['nrmse']:.4f}, "
                    f"held-out {before:.4f} -> {after:.4f}.",
        "delta_fit": before - after,
    }


def diagnose(recordings: list[Recording], names: list[str], workers: int = 2, max_effects: int = 2,
             screen: int = 3, progress=None) -> dict:
    """Run the whole diagnosis; return the report (recordings.md schema) plus 'sims' for plotting.

    Raises ConfigError for recordings that cannot be diagnosed together.
    """
    say = progress or (lambda message: None)
    data = prepare(recordings, names)
    say("re-simulating with the nominal model")
    nominal = Model()
    sims_nominal = simulate_all(data, nominal)
    if sims_nominal is None:
        raise ConfigError("the nominal model diverges on these recordings")
    say("refitting the nominal parameters within their tolerances")
    current = refit_parameters(data, nominal)
    sims = simulate_all(data, current)
    mismatch = locate(data, sims)
    noise = noise_nrmse(data)
    held = fit_scores(data, sims, "held_out")["nrmse"]
    findings, rejected = [], []
    for round_ in range(max_effects):
        if held <= NOISE_MARGIN * noise:
            break
        pairs = candidates(data.rig, current.effects)
        say(f"round {round_ + 1}: screening {len(pairs)} candidate effects")
        screened = [r for r in run_candidates(data, current, pairs, workers, budget=3) if "error" not in r]
        screened.sort(key=lambda r: r["cost"])
        say(f"round {round_ + 1}: fitting the best {screen}: " + ", ".join(f"{r['effect']}@{r['where']}" for r in screened[:screen]))
        fitted = [r for r in run_candidates(data, current, [(r["effect"], r["where"]) for r in screened[:screen]],
                                            workers, budget=12, joint=True) if "error" not in r]
        if not fitted:
            break
        train_now = fit_scores(data, sims, "train")["nrmse"]
        for r in fitted:  # relative improvements, and a score that charges every parameter
            r["train_gain"] = (train_now - r["train"]["nrmse"]) / train_now
            r["held_gain"] = (held - r["held_out"]["nrmse"]) / held
            r["score"] = r["train_gain"] + r["held_gain"] - MIN_GAIN * r["n_params"]
        best = max(fitted, key=lambda r: r["score"])
        if best["train_gain"] < MIN_GAIN * best["n_params"] or best["held_gain"] < -HELD_TOLERANCE:
            rejected.append({"effect": best["effect"], "where": best["where"], "train_gain": best["train_gain"],
                             "held_out_gain": best["held_gain"]})
            break
        alternative = offset_alternative(data, current, best, train_now, held)
        if alternative is not None and alternative["score"] >= best["score"] - 1e-3:
            say("asymmetric Coulomb friction is better explained as symmetric friction plus an actuator offset")
            findings.append(_finding(alternative, alternative["model"], held, alternative["held_out"]["nrmse"], mismatch, train_now))
            offset = {**alternative, "effect": "actuator_offset", "where": alternative["model"].effects[-1]["where"]}
            findings.append(_finding(offset, alternative["model"], held, alternative["held_out"]["nrmse"], mismatch, train_now))
            best = alternative
        else:
            findings.append(_finding(best, best["model"], held, best["held_out"]["nrmse"], mismatch, train_now))
        current = best["model"]
        sims = simulate_all(data, current)
        held = best["held_out"]["nrmse"]
        mismatch = locate(data, sims) or mismatch
    if findings:  # final joint refit of the rig's parameters with the effects in place
        say("refitting the parameters with the effects in place")
        refit = refit_parameters(data, current)
        refit_sims = simulate_all(data, refit)
        if refit_sims is not None and fit_scores(data, refit_sims, "held_out")["nrmse"] <= held:
            current, sims = refit, refit_sims
    before_mismatch = locate(data, sims_nominal)
    return {
        "format": "flexarm-diagnosis/1",
        "rig": data.rig.name,
        "recordings": names,
        "mismatch": before_mismatch,
        "findings": findings,
        "fit_before": fit_scores(data, sims_nominal, "all"),
        "fit_after": fit_scores(data, sims, "all"),
        "held_out": {"before": fit_scores(data, sims_nominal, "held_out"), "after": fit_scores(data, sims, "held_out"),
                     "how": data.how},
        "refit_parameters": {n: current.parameters[n] for n in current.parameters},
        "noise_nrmse": noise,
        "rejected": rejected,
        "patch": {"effects": current.effects, "parameters": current.parameters},
        "sims": {"nominal": sims_nominal, "final": sims},
    }
