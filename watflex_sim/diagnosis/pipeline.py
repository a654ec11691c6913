"""The whole diagnosis, stage by stage, and its verdict.

Contract: `diagnose(recordings, names)` returns the report of recordings.md section 2 (plus 'sims' for
plotting). Stages: re-simulate with the nominal model; refit the rig's parameters within tolerance
(kept only if validation does not get worse); locate; rounds of screening, candidate fits and a polish
of the best, each kept only if its *final* model improves training by MIN_GAIN per parameter and
validation by MIN_HELD_GAIN; backward elimination (a finding whose removal from the final model does
not worsen validation is dropped); 95 % intervals; alternatives within noise of the chosen one and,
when there are any, the experiment that would tell them apart. Verdict: `nothing_missing` only when
the refit nominal model is within NOISE_MARGIN x the noise on training AND validation data,
`explained` when the findings bring both there, `unexplained` otherwise.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..effects import canonical, canonical_moves
from ..model import ConfigError
from ..recording import Recording
from ..resim import finer_discretisation, scenario_from_recording
from .data import Data, Model, add_closed_loop_noise, add_discretisation_error, fit_scores, noise_nrmse, prepare, residual_vector, unit_change
from .explain import finding, indistinct
from .fitting import compass, jacobian, levenberg, rig_slots, value_of
from .locate import locate
from .refine import POLISH_ITERATIONS, alternative_entry, offset_alternative, polish, single_from_pair
from .runner import Runner, evaluator, in_units
from .screening import (FIT_ITERATIONS, MIN_GAIN, RESCREEN, SCREEN_TOP, candidates, effect_slots_of, fit_candidate,
                        make_candidate, rescreen, screen, scored, shortlist, signatures)
from .tolerance import at_bounds, beyond_tolerance, fold_within_tolerance, knob_partner
from .uncertainty import FINER, NOISE_SEED, final_intervals

MIN_HELD_GAIN = 0.01  # and the validation noise ratio by this fraction (data the fit did not see)
NOISE_MARGIN = 1.3  # within this factor of the noise, a model leaves nothing to explain
MIN_EXCESS_GAIN = 0.25  # a later effect must remove at least this share of the validation residual above the noise
EXPLAINED_SHARE = 0.8  # findings that remove this share of the residual above the noise explain the data
ALTERNATIVE_MARGIN = 0.03  # a candidate whose validation noise ratio is within 3 % of the chosen one's is an alternative
PAIR_MARGIN = 1e-3  # symmetric friction + an actuator offset replaces one asymmetric friction only when it
# scores better by this much (one effect before two on a tie; the pair is then listed as an alternative)
REFIT_ITERATIONS = 8
COMPASS_SWEEPS = 14  # at most this many pattern-search sweeps after the refit's Levenberg-Marquardt (2 simulations
# per parameter each); it stops once no step changes the cost by CHI2_RESOLUTION (6 sweeps halved the steps to
# 0.4 % of a tolerance at best: a clean Watflex case's strain bridge is 1.3 x its noise at link 2's EI 0.04 % off)
COMPASS_REACH = 3.0  # x NOISE_MARGIN: only a refit within this of the noise gets the pattern search; one further
# off is missing physics, which a harder refit only pushes into the rig's parameters (a 0.33 kg Watflex payload: the
# refit at 11.7 x the noise with elbow inertia at its bound and link 2's EI 4 % low, where its fits then started)
CHI2_RESOLUTION = 0.5  # Huber cost in noise units (chi-square / 2): a change below this the noise does not resolve


class Stages:
    """Names the stage in progress, tells the user, and adds up wall time (s) and simulation
    jobs per kind of stage (the report's "timing")."""

    def __init__(self, say, runner: Runner):
        self.say, self.runner = say, runner
        self.table: dict[str, dict[str, float]] = {}
        self.kind, self.t0, self.jobs0 = None, time.perf_counter(), 0

    def __call__(self, kind: str, message: str) -> None:
        now = time.perf_counter()
        if self.kind is not None:
            row = self.table.setdefault(self.kind, {"seconds": 0.0, "jobs": 0})
            row["seconds"] += now - self.t0
            row["jobs"] += self.runner.jobs - self.jobs0
        self.kind, self.t0, self.jobs0 = kind, now, self.runner.jobs
        if kind != "done":
            self.say(message)


def diagnose(recordings: list[Recording], names: list[str], workers: int = 2, max_effects: int = 2,
             screen_top: int = SCREEN_TOP, progress=None, jobs_done=None, propose: bool = True) -> dict:
    """Run the whole diagnosis; return the report (recordings.md schema) plus 'sims' for plotting.

    `progress(message)` hears each stage, `jobs_done(done, total)` each finished simulation job of a
    stage. With `propose`, a discriminating experiment is proposed when alternatives remain (the
    scenario itself is written by report.write_report). Raises ConfigError for recordings that cannot
    be diagnosed together."""
    data = prepare(recordings, names)
    with Runner(data, workers, jobs_done) as runner:
        stages = Stages(progress or (lambda message: None), runner)
        report = _diagnose(data, runner, max_effects, screen_top, stages, propose)
        stages("done", "done")
        report["timing"] = stages.table
        return report


def _gains(result: dict, train_now: dict, held_now: dict) -> dict:
    """Relative falls of the training and validation noise ratios (from the fit_scores train_now and
    held_now), the share of the excess on validation it removes (excess_gain) and the score that charges
    every parameter."""
    train_gain = (train_now["noise_ratio"] - result["train"]["noise_ratio"]) / train_now["noise_ratio"]
    held_gain = (held_now["noise_ratio"] - result["held_out"]["noise_ratio"]) / held_now["noise_ratio"]
    return {**result, "train_gain": train_gain, "held_gain": held_gain, "excess_gain": excess_gain(held_now, result["held_out"]),
            "score": train_gain + held_gain - MIN_GAIN * result["n_params"]}


def excess_gain(held_now: dict, held_new: dict) -> float:
    """Share of what validation has above the noise that a model removes, on what made one more round
    necessary: the mean noise ratio's excess over 1 where the mean is beyond NOISE_MARGIN, else the excess
    of the channel beyond it (`worst_channel`), else 0 (validation is within the noise everywhere: a
    round for training alone shows nothing on unseen data). Seed 5: with a 11 ms delay found, validation
    at 1.00x the noise on the mean and strain_2A above the margin, a 0.03 % gain of the elbow encoder
    lowered the mean to 0.96x - 'removing' 4e7 times the mean's excess (then 1e-9) - and strain_2A not at all."""
    if held_now["noise_ratio"] > NOISE_MARGIN:
        return (held_now["noise_ratio"] - held_new["noise_ratio"]) / (held_now["noise_ratio"] - 1.0)
    if held_now["worst_ratio"] > NOISE_MARGIN:
        channel, before = held_now["worst_channel"], held_now["worst_ratio"]
        return (before - held_new["channel_ratios"].get(channel, math.inf)) / (before - 1.0)
    return 0.0


def _earns_place(result: dict, later: bool) -> bool:
    """Whether a fitted candidate earns its place (_shortfall says nothing against it)."""
    return not _shortfall(result, later)


def _shortfall(result: dict, later: bool) -> str:
    """Why a fitted candidate does not earn its place, in words, or "" if it does: training must be better
    by MIN_GAIN per parameter and validation by MIN_HELD_GAIN; a `later` finding (one is in already) must
    also remove MIN_EXCESS_GAIN of what validation still has above the noise (excess_gain), so a second
    effect does not merely absorb the first one's imperfect fit (stick-slip fits are approximate)."""
    if result["train_gain"] < MIN_GAIN * result["n_params"] or result["held_gain"] < MIN_HELD_GAIN:
        return "less than its parameters' cost"
    if later and result["excess_gain"] < MIN_EXCESS_GAIN:
        return (f"removes only {100 * result['excess_gain']:.0f} % of what validation has above the noise where another "
                f"round was asked for (a later finding must remove {100 * MIN_EXCESS_GAIN:.0f} %)")
    return ""


def explained_share(before: float, after: float) -> float:
    """Share of the residual above the noise (noise ratio - 1) that a model removes."""
    return (before - after) / max(before - 1.0, 1e-9) if before > 1.0 else 1.0


def _within(scores: dict) -> bool:
    """One part's fit_scores within NOISE_MARGIN x the noise, on average and on every channel."""
    return scores["noise_ratio"] <= NOISE_MARGIN and scores["worst_ratio"] <= NOISE_MARGIN


def compass_worth(train: dict) -> bool:
    """Whether the refit's training scores ask for the pattern search: short of the noise on some channel,
    but within COMPASS_REACH x the margin (further off, the rig's parameters would only absorb missing physics)."""
    return not _within(train) and train["noise_ratio"] <= COMPASS_REACH * NOISE_MARGIN


def within_noise(scores_train: dict, scores_held: dict) -> bool:
    """Training and validation within NOISE_MARGIN x the noise, on average and on every channel."""
    return _within(scores_train) and _within(scores_held)


def _diagnose(data: Data, runner: Runner, max_effects: int, screen_top: int, say: Stages, propose: bool) -> dict:
    # the refit minimises the residual in noise units, what the verdict judges (data.unit_change: in spread
    # units the noisiest channels' noise swamps a precise channel's misfit)
    evaluate = evaluator(runner, unit="noise")
    say("nominal", "re-simulating with the nominal model")
    nominal = Model()
    sims_nominal = runner.simulate(nominal)
    if sims_nominal is None:
        raise ConfigError("the nominal model diverges on these recordings")
    free = rig_slots(data)
    r_nominal = residual_vector(data, sims_nominal, unit="noise")
    say("refit", f"refitting the {len(free)} nominal parameters within their tolerances")
    at = np.array([value_of(nominal, s) for s in free])
    rig_columns = jacobian(evaluate, nominal, free, at, r_nominal)
    data.idle = frozenset(s.name for s, column in zip(free, rig_columns.T) if not np.any(column))
    live = [i for i, s in enumerate(free) if s.name not in data.idle]
    free, at, rig_columns = [free[i] for i in live], at[live], rig_columns[:, live]
    current = levenberg(evaluate, nominal, free, at, rig_columns, REFIT_ITERATIONS, r_nominal)[0] if free else nominal
    sims = runner.simulate(current)
    if free and sims is not None and compass_worth(fit_scores(data, sims, "train")):
        say("refit", "the refit is short of the noise: a pattern search over the same parameters (stick-slip makes "
            "the cost rough)")
        current = compass(evaluate, current, free, [value_of(current, s) for s in free],
                          residual_vector(data, sims, unit="noise"), COMPASS_SWEEPS, resolution=CHI2_RESOLUTION)
        sims = runner.simulate(current)
    rig_columns = rig_columns * unit_change(data)[:, None]  # the screening works in spread units (the effect fits turn them back)
    if sims is None or fit_scores(data, sims, "held_out")["noise_ratio"] > fit_scores(data, sims_nominal, "held_out")["noise_ratio"]:
        current, sims = nominal, sims_nominal  # a refit must earn its place on validation data too
    say("noise", "simulating the refit model with the rig's noise on: what noise alone leaves in closed loop")
    noisy = runner.simulate(current, noise_seed=NOISE_SEED)
    if noisy is not None:
        add_closed_loop_noise(data, sims, noisy)
    if any(finer_discretisation(data.rig, scenario_from_recording(r, data.rig), FINER) for r in data.recordings):
        say("noise", f"simulating the refit model {FINER} x finer (segments, step): what our own discretisation leaves")
        finer = runner.simulate(current, finer=FINER)
        if finer is not None:
            add_discretisation_error(data, sims, finer)
    per = unit_change(data)  # the effect fits' noise units, with the closed-loop floor the workers' data lack
    steps = [{"model": "nominal", **_scores(data, sims_nominal, nominal)}, {"model": "parameters refit", **_scores(data, sims, current)}]
    refit_sims, refit_model = sims, current
    mismatch = locate(data, sims)
    rejected, screened_report, fitted_report, alternatives = [], [], [], []
    round_ = 0
    bounds_tried = False  # a round for rig parameters at their tolerance bounds (beyond_tolerance) runs once
    while len(current.effects) < max_effects:
        train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
        pinned = beyond_tolerance(data, current)
        beyond = []
        if within_noise(train, held):
            beyond = [] if bounds_tried else pinned
            bounds_tried = True
            if not beyond:
                say("verdict", f"training {train['noise_ratio']:.2f} x and validation {held['noise_ratio']:.2f} x the noise, "
                    f"every channel within {NOISE_MARGIN:g} x: nothing left to explain")
                break
            say("verdict", "within the noise, but with " + ", ".join(sorted({c.where for c in beyond}))
                + " at a tolerance bound: is the datasheet wrong beyond it?")
        round_ += 1
        r0 = residual_vector(data, sims)
        # signatures are taken around the current model: an effect can look different once
        # another is in (a slip shows only where stiction lets the joint move)
        live = beyond or [make_candidate(data, e, w) for e, w in candidates(data, current.effects)]
        say("signatures", f"round {round_}: taking the signatures of {len(live)} candidate effects "
            f"({sum(len(c.probes()) for c in live)} probe simulations)")
        signatures(data, runner, current, sims, r0, live)
        at = np.array([value_of(current, s) for s in free])
        screen(live, rig_columns, free, at, r0)
        live.sort(key=lambda c: (-c.gain, c.effect, c.where))
        rescreen(evaluator(runner), live[:RESCREEN], current, rig_columns, free, at, r0)
        screened_report.append([{"effect": c.effect, "where": c.where, "explained": round(c.gain, 4)}
                                | ({} if c.checked is None else {"simulated": round(c.checked, 4)}) for c in live[:8]])
        top = shortlist(live, screen_top)
        if not top:
            break
        say("candidate fits", f"round {round_}: fitting the {len(top)} whose signatures match the residual best: "
            + ", ".join(f"{c.effect}@{c.where} ({100 * c.gain:.0f} %)" for c in top))
        results = runner.map(fit_candidate, [(current, c, rig_columns, FIT_ITERATIONS, data.idle, per) for c in top])
        rejected += [{"effect": r["effect"], "where": r["where"], "error": r["error"]} for r in results if "error" in r]
        fitted = [_gains(scored(data, r, r["sims"]), train, held)  # scored here, where
                  for r in results if "error" not in r]  # the data has the closed-loop noise the workers' copies lack
        if not fitted:
            break
        fitted.sort(key=lambda r: (-r["score"], r["effect"], r["where"]))
        fitted_report.append([{"effect": r["effect"], "where": r["where"], "parameters": r["n_params"],
                               "train_gain": round(r["train_gain"], 4), "held_out_gain": round(r["held_gain"], 4),
                               "validation_noise_ratio": round(r["held_out"]["noise_ratio"], 4),
                               "score": round(r["score"], 4)} for r in fitted])
        # a later finding must remove the excess that asked for its round, but for the effect that frees a rig
        # parameter pinned at its tolerance bound (beyond_tolerance): that is evidence of its own
        best = fitted[0]
        later = bool(current.effects) and (best["effect"], best["where"]) not in {(c.effect, c.where) for c in pinned}
        if _earns_place(best, later):
            say("polish", f"round {round_}: polishing {best['effect']} at {best['where']} and trying alternatives")
            best = _gains(polish(data, runner, best, rig_start={}), train, held)  # {}: the datasheet's values
            room = max_effects - len(current.effects) >= 2
            alternative = offset_alternative(data, runner, current, best) if room else None
            if alternative is not None:
                alternative = _gains(alternative, train, held)
                if alternative["score"] > best["score"] + PAIR_MARGIN:  # restart the single from the pair's levels
                    again = single_from_pair(data, runner, best, alternative)
                    again = again and _gains(again, train, held)
                    if again is not None and again["score"] > best["score"]:
                        best = again
                if alternative["score"] > best["score"] + PAIR_MARGIN and _earns_place(alternative, later):
                    say("verdict", "asymmetric Coulomb friction is better explained as symmetric friction plus an actuator offset")
                    best, alternative = alternative, best
                fitted.append(alternative)  # the explanation not taken competes as an alternative below
        if not _earns_place(best, later):  # judged on the final (polished) model, never on a promise
            rejected.append({"effect": best["effect"], "where": best["where"], "train_gain": best["train_gain"],
                             "held_out_gain": best["held_gain"], "excess_gain": best["excess_gain"],
                             "why": _shortfall(best, later)})
            break
        n = len(current.effects)
        places = lambda r: [(e["effect"], e["where"]) for e in r["model"].effects[n:]]  # noqa: E731
        alternatives += [alternative_entry(data, r, best, n) for r in fitted if places(r) != places(best)
                         and r["held_out"]["noise_ratio"] <= (1 + ALTERNATIVE_MARGIN) * best["held_out"]["noise_ratio"]]
        say("verdict", f"round {round_}: found {best['effect']} at {best['where']}: validation "
            f"{held['noise_ratio']:.2f} -> {best['held_out']['noise_ratio']:.2f} x the noise")
        current, sims = best["model"], best["sims"]
        steps.append({"model": f"+ {best['effect']} at {best['where']}", **_scores(data, sims, current)})
        mismatch = locate(data, sims) or mismatch
    found = len(current.effects)
    current = fold_within_tolerance(data, current)
    if len(current.effects) < found:
        sims = runner.simulate(current) or sims
    while True:  # until every finding's intervals tell it from no effect (explain.indistinct)
        current, sims, ablated = eliminate(data, runner, current, sims, say)
        if len(current.effects) < found:
            steps.append({"model": "after backward elimination", **_scores(data, sims, current)})
        train_f, held_f = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")  # judged before the final refit
        trained = current
        if current.effects:
            say("final refit", "refitting the findings' and the rig's parameters on all the data (training and validation)")
            current, sims = final_refit(data, runner, current, sims)
            steps.append({"model": "parameters refit on all the data", **_scores(data, sims, current)})
        say("intervals", "95 % intervals from the Jacobian at the final model and the training-only fit")
        ranges = final_intervals(data, runner, current, sims, trained)
        vague = vague_findings(data, current, ranges, ablated, held_f)
        if not vague:
            break
        say("elimination", "dropping " + ", ".join(f"{current.effects[i]['effect']} at {current.effects[i]['where']}"
                                                   for i in vague) + ": its 95 % intervals include no effect at all")
        rejected += [{"effect": current.effects[i]["effect"], "where": current.effects[i]["where"],
                      "parameters": {k: v for k, v in current.effects[i].items() if k not in ("effect", "where")},
                      "intervals": ranges.get(i, {}), "why": "its 95 % intervals include no effect at all"} for i in vague]
        found = len(trained.effects)
        current = Model([e for i, e in enumerate(trained.effects) if i not in vague], dict(trained.parameters))
        if current.effects:
            sims = runner.simulate(current) or sims
        else:  # the rig's parameters as refit without effects, not as they were fitted beside the dropped ones
            current, sims = refit_model, refit_sims
    current, ranges = _canonical(current, ranges)
    refit_train, refit_held = fit_scores(data, refit_sims, "train"), fit_scores(data, refit_sims, "held_out")
    findings = []
    for i, effect in sorted(enumerate(current.effects), key=lambda ie: -ablated[ie[0]]["noise_ratio"]):
        scores = {"train_before": refit_train["nrmse"], "train_after": train_f["nrmse"], "held_before": refit_held["nrmse"],
                  "held_after": held_f["nrmse"], "ratio_before": refit_held["noise_ratio"], "ratio_after": held_f["noise_ratio"],
                  "ablated": ablated[i]["noise_ratio"], "held_without": ablated[i]["nrmse"]}
        findings.append(finding(data, effect, ranges.get(i, {}), scores, mismatch))
    share = explained_share(refit_held["noise_ratio"], held_f["noise_ratio"])
    if not current.effects:
        verdict = "nothing_missing" if within_noise(train_f, held_f) else "unexplained"
    else:
        verdict = "explained" if within_noise(train_f, held_f) or share >= EXPLAINED_SHARE else "unexplained"
    alternatives = [a for a in alternatives if any(f["effect"] == a["instead_of"] for f in findings)]
    report = {
        "format": "flexarm-diagnosis/1",
        "rig": data.rig.name,
        "recordings": data.names,
        "verdict": verdict,
        "verdict_reason": _verdict_reason(verdict, train_f, held_f, refit_train, refit_held, share),
        "mismatch": locate(data, sims_nominal),
        "findings": findings,
        "alternatives": alternatives,
        "fit_before": fit_scores(data, sims_nominal, "all"),
        "fit_after": fit_scores(data, sims, "all"),
        "held_out": {"before": fit_scores(data, sims_nominal, "held_out"), "after": held_f,
                     "how": data.how + ("; judged before the final refit, which estimates the parameters reported "
                                        "from all the data" if current.effects else "")},
        "refit_parameters": {n: current.parameters[n] for n in current.parameters},
        "parameters_at_bounds": at_bounds(data, current if current.parameters else refit_model),
        "parameters_not_refit": sorted(data.idle),  # the recordings do not depend on them
        "noise_nrmse": noise_nrmse(data),
        "noise": {"margin": NOISE_MARGIN, "training_ratio": train_f["noise_ratio"], "validation_ratio": held_f["noise_ratio"],
                  "per_channel": _noise_table(data)},
        "steps": steps,
        "screening": screened_report,
        "candidates": fitted_report,
        "rejected": rejected,
        "patch": {"effects": current.effects, "parameters": current.parameters},
        "sims": {"nominal": sims_nominal, "final": sims, "measured": data.recordings},  # canonical order, as "recordings"
    }
    if verdict == "unexplained":
        report["residual"] = {"where": locate(data, sims), "training_noise_ratio": train_f["noise_ratio"],
                              "validation_noise_ratio": held_f["noise_ratio"], "candidates_tried": fitted_report,
                              "parameters_at_bounds": report["parameters_at_bounds"]}
    if propose and alternatives:
        from .experiment import propose_experiment

        say("experiment", f"simulating {len(alternatives) + 1} explanations on the rig's experiment menu")
        report["proposed_experiment"] = propose_experiment(data, current, alternatives, runner)
    return report


def _canonical(model: Model, ranges: dict[int, dict]) -> tuple[Model, dict[int, dict]]:
    """The model's effects in their canonical form (effects.canonical: the same physics), each interval moved
    by the same sign and shift as its parameter (effects.canonical_moves)."""
    moved = {}
    for i, effect in enumerate(model.effects):
        moves = canonical_moves(effect)
        moved[i] = {}
        for name, (lo, hi) in ranges.get(i, {}).items():
            sign, shift = moves.get(name, (1.0, 0.0))
            a, b = sign * lo + shift, sign * hi + shift
            moved[i][name] = (min(a, b), max(a, b))
    return Model([canonical(e) for e in model.effects], dict(model.parameters)), moved


def _noise_table(data: Data) -> list[dict]:
    model = data.discretisation or [{} for _ in data.names]
    return [{"recording": n, "channel": c, "noise": noise[c], "declared": float(data.rig.channels[c].get("noise", 0.0)),
             "discretisation": error.get(c, 0.0), "unit": data.rig.channels[c]["unit"]}
            for n, chans, noise, error in zip(data.names, data.channels, data.noise, model) for c in chans]


def _verdict_reason(verdict: str, train: dict, held: dict, refit_train: dict, refit_held: dict, share: float) -> str:
    worst = max((train, held), key=lambda s: s["worst_ratio"])
    now = (f"training {train['noise_ratio']:.2f} x, validation {held['noise_ratio']:.2f} x the noise; furthest channel "
           f"{worst['worst_channel']} at {worst['worst_ratio']:.2f} x")
    if verdict == "nothing_missing":
        return f"the nominal model, refit within tolerance, is within {NOISE_MARGIN:g} x the noise on every channel: {now}"
    if verdict == "explained":
        within = within_noise(train, held)
        return ((f"the findings bring the model within {NOISE_MARGIN:g} x the noise" if within else
                 f"the findings remove {100 * share:.0f} % of the validation residual above the noise (at least "
                 f"{100 * EXPLAINED_SHARE:.0f} % asked); what is left no further catalogue effect explains")
                + f" ({now}; refit nominal: {refit_train['noise_ratio']:.2f} x, {refit_held['noise_ratio']:.2f} x)")
    return (f"the residual stays above {NOISE_MARGIN:g} x the noise ({now}; refit nominal: {refit_train['noise_ratio']:.2f} x, "
            f"{refit_held['noise_ratio']:.2f} x) and no further catalogue effect earns its place: see 'residual'")


def vague_findings(data: Data, model: Model, ranges: dict[int, dict], ablated: list[dict], held: dict) -> list[int]:
    """Indices of the findings the data do not tell from no effect: every 95 % interval includes the value at which
    the effect vanishes (explain.indistinct), and validation without it (`ablated`, fit_scores by finding) is not
    far worse than with it (`held`): it removes less than EXPLAINED_SHARE of the excess over the noise that
    validation has without it. A finding that removes more is told from no effect by the data themselves; an
    interval that still reaches "none" describes where its value is on a rough or many-valleyed cost, not
    whether it is there (seed 53, watflex-d245fa05: an elbow ripple at a wrong period, validation 7.6 x the noise
    with it and 66.1 x without (90 %), had its amplitude's interval widened to [-1.87, 6.03] by the training-only
    fit's distance; dropped, the case became `unexplained` with no finding). Seed 46's spurious sensor gain x1.09
    [0.968, 1.214] on a cubic strain bridge (8.27 x without it, 7.17 x with: 16 %) is still dropped. An effect on a
    rig parameter's knob is never vague by its interval: that carries the parameter's tolerance by design (the
    data fix their product: tie_knob_columns)."""
    return [i for i, effect in enumerate(model.effects)
            if knob_partner(data, effect) is None and indistinct(data, effect, ranges.get(i, {}))
            and explained_share(ablated[i]["noise_ratio"], held["noise_ratio"]) < EXPLAINED_SHARE]


def eliminate(data: Data, runner: Runner, model: Model, sims: list[Recording], say) -> tuple[Model, list, list[dict]]:
    """Backward elimination: drop, one at a time, the effect whose removal from the final model leaves
    validation best, while that is no worse than MIN_HELD_GAIN (what a finding had to gain to enter);
    returns the model, its simulations and, per remaining effect, fit_scores of validation without it."""
    while True:
        held = fit_scores(data, sims, "held_out")["noise_ratio"]
        if not model.effects:
            return model, sims, []
        say("elimination", f"checking each of the {len(model.effects)} findings on validation data without it")
        without = []
        for i in range(len(model.effects)):
            reduced = Model([e for j, e in enumerate(model.effects) if j != i], dict(model.parameters))
            s = runner.simulate(reduced)
            without.append((fit_scores(data, s, "held_out"), reduced, s))  # a diverging one scores inf
        worst = int(np.argmin([w[0]["noise_ratio"] for w in without]))
        if without[worst][0]["noise_ratio"] > held * (1 + MIN_HELD_GAIN):
            return model, sims, [w[0] for w in without]
        say("elimination", f"dropping {model.effects[worst]['effect']} at {model.effects[worst]['where']}: validation "
            f"{held:.3f} x the noise with it, {without[worst][0]['noise_ratio']:.3f} x without")
        model, sims = without[worst][1], without[worst][2]


def final_refit(data: Data, runner: Runner, model: Model, sims: list[Recording]) -> tuple[Model, list[Recording]]:
    """The chosen model's parameters (its effects' and the rig's) refit on all the data, training and
    validation blocks alike, in noise units (`in_units`): the structure was chosen and judged on data the
    fit did not see; the numbers reported are then estimated from every sample, each channel weighted by
    its noise, or by its misfit where the model is further off than that (what least squares needs to
    be the best estimate). Kept only if it does not diverge."""
    free = effect_slots_of(data, model) + rig_slots(data)
    refit, _, _ = levenberg(in_units(evaluator(runner, "all"), unit_change(data, "all", sims=sims)), model, free,
                            [value_of(model, s) for s in free], None, POLISH_ITERATIONS)
    new = runner.simulate(refit)
    return (refit, new) if new is not None else (model, sims)


def _scores(data: Data, sims: list[Recording], model: Model) -> dict:
    """One stage of the report's 'steps': training and validation NRMSE and noise ratio, and the model."""
    train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    return {"train_nrmse": train["nrmse"], "held_out_nrmse": held["nrmse"], "train_noise_ratio": train["noise_ratio"],
            "held_out_noise_ratio": held["noise_ratio"], "effects": [dict(e) for e in model.effects],
            "parameters": dict(model.parameters)}
