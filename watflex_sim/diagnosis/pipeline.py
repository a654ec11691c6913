"""The whole diagnosis, stage by stage, and its verdict.

Contract: `diagnose(recordings, names)` returns the report of recordings.md section 2 (plus 'sims' for
plotting). Stages: re-simulate with the nominal model; refit the rig's parameters within tolerance
(kept only if validation does not get worse); locate; rounds of screening, candidate fits (in the first round also
the one the screening puts first against the nominal model's residual: what the refit took up) and a polish
of the best, each kept only if its *final* model improves training by MIN_GAIN per parameter and
validation by MIN_HELD_GAIN, the noise floor then measured again with it in (floors.raise_noise_floor: a loop that
hunts leaves more to noise than the nominal one; measured again without the findings elimination drops); a later
candidate short only of the excess it must remove fitted again with the earlier findings' sizes restarted
(earlier.restart_earlier: two effects that each fit worse alone than neither); each
earlier round's runners-up refit in its winner's place beside the later findings (earlier.swap_earlier: a round chose
with the later effects missing), and one friction law in the place of two found at one joint (laws.one_law); where no
finding is left, the rig's parameters refit in the floors' units (refit.without_findings); the findings settled
(settle.settle: backward elimination, the final refit, 95 % intervals, vague findings dropped); alternatives within
noise of the chosen one and, when there are any, the experiment that would tell them apart. Verdict: `nothing_missing` only when
the refit nominal model is within NOISE_MARGIN x the noise on training AND validation data and no window stands
far above what noise and discretisation leave there (locate.local_excess: such windows get a round of their own),
`explained` when the findings bring both there, `unexplained` otherwise, and where a channel's residual is a static
curve of its own value or carries a steady line or drift no catalogue effect makes (disturbance.disturbances).
"""
from __future__ import annotations

import time
from copy import deepcopy

import numpy as np

from ..recording import Recording
from .characteristic import curved_channels
from .data import Data, Model, prepare, residual_vector, unit_change
from .disturbance import disturbances
from .earlier import restart_earlier, swap_earlier
from .effect_fit import FIT_ITERATIONS, fit_candidates, scored
from .explain import canonical_form, finding
from .fidelity import fine_for_round, keep_fidelity
from .fitting import value_of
from .floors import FLOORS, calibrate_noise, raise_noise_floor
from .laws import one_law
from .locate import LOCAL_WINDOW_S, local_excess, local_gain, locate
from .refine import alternative_entry, carry_on, inside_catalogue, offset_alternative, polish, single_from_pair
from .refit import refit_nominal, without_findings
from .rescreen import RESCREEN, rescreen
from .runner import Runner, evaluator, in_units
from .scores import fit_scores, noise_nrmse, noise_table, step
from .screening import candidates, concealed, make_candidate, screen, signatures, with_findings
from .selection import LEADER_FIRST, SCREEN_TOP, leader_first, shortlist
from .settle import settle
from .tolerance import at_bounds, beyond_tolerance
from .validate import (NOISE_MARGIN, earns_place, explained_share, far_gain, gains, near_place, rival, shortfall,
                       told_apart, within_noise)
from .verdict import verdict_of, verdict_reason

PAIR_MARGIN = 1e-3  # symmetric friction + an actuator offset replaces one asymmetric friction only when it
# scores better by this much (one effect before two on a tie; the pair is then listed as an alternative)


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


def settling_fit(data: Data, results: list[dict]) -> dict | None:
    """The first of `fit_candidates`' results that fits training and validation to within the noise on every
    channel (validate.within_noise), or None: the round's leader fitted, its deferred runners-up can at most tie it
    (selection.leader_first)."""
    return next((r for r in results if "sims" in r and within_noise(
        fit_scores(data, r["sims"], "train"), fit_scores(data, r["sims"], "held_out"))), None)


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


def _diagnose(data: Data, runner: Runner, max_effects: int, screen_top: int, say: Stages, propose: bool) -> dict:
    nominal = Model()
    refit = refit_nominal(data, runner, say)
    sims_nominal, current, sims, free, rig_columns = refit.sims_nominal, refit.model, refit.sims, refit.free, refit.rig_columns
    calibrate_noise(data, runner, current, sims, say)
    nominal_floors = deepcopy({k: getattr(data, k) for k in FLOORS})  # judged by again where findings are dropped
    raised = False  # whether a finding raised the floors (raise_noise_floor)
    per = unit_change(data)  # the effect fits' noise units, with the closed-loop floor the workers' data lack
    steps = [step("nominal", data, sims_nominal, nominal), step("parameters refit", data, sims, current)]
    refit_sims, refit_model = sims, current
    mismatch = locate(data, sims)
    rejected, screened_report, fitted_report, alternatives, rounds = [], [], [], [], []
    round_ = 0
    bounds_tried = False  # a round for rig parameters at their tolerance bounds (beyond_tolerance) runs once
    limited = None  # max_effects where the search stopped at it (verdict.verdict_reason)
    round_models = {}  # each round's chosen model, fitted on the training blocks, by its effects' places
    shortlisted = {}  # (effect, place) -> its candidate in the latest round that fitted it
    local, local_tried = [], False  # windows far above their local null (locate.local_excess) where the refit model is
    # within the noise on the whole: a round of their own; they then judge its findings to the end

    def judge(result: dict) -> dict:
        """gains of a fitted candidate, and in the round for local windows the share of their excess it removes."""
        out = gains(result, train, held)
        return out | {"local_gain": local_gain(data, local, sims, result["sims"])} if local and not current.effects else out

    while len(current.effects) < max_effects:
        train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
        pinned = beyond_tolerance(data, current)
        beyond = []
        if within_noise(train, held):
            beyond = [] if bounds_tried else pinned
            bounds_tried = True
            if not (beyond or current.effects or local_tried):
                local, local_tried = local_excess(data, sims), True
            if not beyond and (current.effects or not local):
                say("verdict", f"training {train['noise_ratio']:.2f} x and validation {held['noise_ratio']:.2f} x the noise, "
                    f"every channel within {NOISE_MARGIN:g} x: nothing left to explain")
                break
            if beyond:
                say("verdict", "within the noise, but with " + ", ".join(sorted({c.where for c in beyond}))
                    + " at a tolerance bound: is the datasheet wrong beyond it?")
            else:
                w = local[0]
                say("verdict", f"within the noise on the whole, but {len(local)} windows of {LOCAL_WINDOW_S:g} s stand up to "
                    f"{w['ratio']:.1f} x above what noise and discretisation leave there ({w['channel']} in {w['recording']}, "
                    f"{w['t_start']:.2f}-{w['t_end']:.2f} s, {w['regime']}): a round for them")
        round_ += 1
        # the screening compares in noise units, as the fits and the verdict: in spread units a noisy channel's
        # misfit outweighs a precise one's and the shortlist can miss what the verdict needs. The residual is this
        # process' (its noise has the closed-loop floor); the simulations' come from the workers, turned by `per`
        r0 = residual_vector(data, sims, unit="noise")
        # signatures are taken around the current model: an effect can look different once
        # another is in (a slip shows only where stiction lets the joint move)
        live = beyond or [make_candidate(data, e, w) for e, w in candidates(data, current.effects)]
        say("signatures", f"round {round_}: taking the signatures of {len(live)} candidate effects "
            f"({sum(len(c.probes()) for c in live)} probe simulations)")
        signatures(data, runner, current, sims, r0, live, per)
        evaluate = in_units(evaluator(runner), per)
        columns, slots, at = with_findings(evaluate, data, current, r0, rig_columns / per[:, None], free,
                                           np.array([value_of(current, s) for s in free]))
        screen(live, columns, slots, at, r0)
        live.sort(key=lambda c: (-c.gain, c.effect, c.where))
        rescreen(evaluate, live[:RESCREEN], current, columns, slots, at, r0)
        screened_report.append([{"effect": c.effect, "where": c.where, "explained": round(c.gain, 4)}
                                | ({} if c.checked is None else {"simulated": round(c.checked, 4)}) for c in live[:8]])
        top = shortlist(live, screen_top)
        hidden = None
        if round_ == 1 and not beyond and current.parameters:  # what the refit may have taken up
            hidden = concealed(live, columns, slots, np.array([value_of(nominal, s) for s in free]),
                               residual_vector(data, sims_nominal, unit="noise"), top)
            top += [hidden] if hidden else []
        if not top:
            break
        first, deferred = (top, []) if beyond or (local and not current.effects) else leader_first(top, hidden)
        named = lambda cands: ", ".join(f"{c.effect}@{c.where} ({100 * c.gain:.0f} %)" for c in cands)  # noqa: E731
        say("candidate fits", f"round {round_}: fitting the {len(first)} whose signatures match the residual best: "
            + named(c for c in first if c is not hidden)
            + (f", and {hidden.effect}@{hidden.where}, first against the datasheet model's residual" if hidden else "")
            + (f"; then, unless one fits to within the noise, {named(deferred)}" if deferred else ""))
        results = fit_candidates(data, runner, current, first, rig_columns, FIT_ITERATIONS, per, others=top)
        done = settling_fit(data, results) if deferred else None
        if done is not None:
            say("candidate fits", f"round {round_}: {done['effect']} at {done['where']} fits to within the noise; "
                + ", ".join(f"{c.effect}@{c.where}" for c in deferred) + f", screened below {LEADER_FIRST:g} x the "
                "leader, not fitted")
            skipped = {(c.effect, c.where) for c in deferred}
            for entry in screened_report[-1]:
                if (entry["effect"], entry["where"]) in skipped:
                    entry["fitted"] = False
        elif deferred:
            results += fit_candidates(data, runner, current, deferred, rig_columns, FIT_ITERATIONS, per, others=top)
        rejected += [{"effect": r["effect"], "where": r["where"], "error": r["error"]} for r in results if "error" in r]
        fitted = [scored(data, r, r["sims"]) for r in results if "error" not in r]
        if not fitted:
            break
        fitted, sims = fine_for_round(data, runner, current, sims, fitted, say)  # a candidate may not stand the coarser model
        train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")  # judge's baseline
        fitted = [judge(r) for r in fitted]
        fitted.sort(key=lambda r: (-r.get("local_gain", r["score"]), r["effect"], r["where"]))
        fitted_report.append([{"effect": r["effect"], "where": r["where"], "parameters": r["n_params"],
                               "train_gain": round(r["train_gain"], 4), "held_out_gain": round(r["held_gain"], 4),
                               "validation_noise_ratio": round(r["held_out"]["noise_ratio"], 4),
                               "score": round(r["score"], 4)} | ({"start": r["start"]} if "start" in r else {})
                              for r in fitted])
        # a later finding must remove the excess that asked for its round, but for the effect that frees a rig
        # parameter pinned at its tolerance bound (beyond_tolerance): that is evidence of its own
        freeing = {(c.effect, c.where) for c in pinned}
        is_later = lambda r: bool(current.effects) and (r["effect"], r["where"]) not in freeing  # noqa: E731
        best = inside_catalogue(data, fitted, is_later(fitted[0]), len(current.effects))
        if best is not fitted[0]:
            say("candidate fits", f"round {round_}: {fitted[0]['effect']} at {fitted[0]['where']} has a parameter at its "
                f"catalogue bound; {best['effect']} at {best['where']}, within noise of it on validation, is taken")
        later = is_later(best)
        if earns_place(best, later):
            say("polish", f"round {round_}: polishing {best['effect']} at {best['where']} and trying alternatives")
            best = judge(polish(data, runner, best, rig_start={}))  # {}: the datasheet's values
            room = max_effects - len(current.effects) >= 2
            alternative = offset_alternative(data, runner, current, best) if room else None
            if alternative is not None:
                alternative = judge(alternative)
                if alternative["score"] > best["score"] + PAIR_MARGIN:  # restart the single from the pair's levels
                    again = single_from_pair(data, runner, best, alternative)
                    again = again and judge(again)
                    if again is not None and again["score"] > best["score"]:
                        best = again
                if alternative["score"] > best["score"] + PAIR_MARGIN and earns_place(alternative, later):
                    say("verdict", "asymmetric Coulomb friction is better explained as symmetric friction plus an actuator offset")
                    best, alternative = alternative, best
                fitted.append(alternative)  # the explanation not taken competes as an alternative below
        if near_place(best, later):  # short only of the excess a later finding must remove: the earlier ones restarted
            say("candidate fits", f"round {round_}: {best['effect']} at {best['where']} fitted again with the earlier "
                "findings' sizes restarted a decade away")
            cand = [c for c in top if (c.effect, c.where) == (best["effect"], best["where"])][:1]
            restarted = restart_earlier(data, current, lambda base: [
                judge(scored(data, r, r["sims"])) for r in fit_candidates(data, runner, base, cand, rig_columns,
                                                                          FIT_ITERATIONS, per) if "error" not in r])
            if restarted is not None and earns_place(restarted, later):
                best = restarted
        if not earns_place(best, later):  # judged on the final (polished) model, never on a promise
            rejected.append({"effect": best["effect"], "where": best["where"], "train_gain": best["train_gain"],
                             "held_out_gain": best["held_gain"], "excess_gain": best["excess_gain"],
                             "why": shortfall(best, later)})
            break
        n = len(current.effects)
        places = lambda r: r["model"].places()[n:]  # noqa: E731
        alternatives += [alternative_entry(data, r, best, n) for r in fitted
                         if places(r) != places(best) and rival(r, best, later, data.absorbable)]
        rounds.append((best, [r for r in fitted if (r["effect"], r["where"]) != (best["effect"], best["where"])]))
        shortlisted |= {(c.effect, c.where): c for c in top}  # a runner-up's candidate, fitted anew in the swap
        say("verdict", f"round {round_}: found {best['effect']} at {best['where']}: validation "
            f"{held['noise_ratio']:.2f} -> {best['held_out']['noise_ratio']:.2f} x the noise"
            + (f" (far from the noise: {100 * best['train_gain']:.1f} % better on training, {100 * best['held_gain']:.1f} % "
               f"on validation, {100 * best['excess_gain']:.0f} % of its excess)" if later and far_gain(best) else ""))
        current, sims = best["model"], best["sims"]
        coarse = runner.fidelity
        sims = keep_fidelity(data, runner, current, sims, say)  # a finding may not stand the coarser model
        if runner.fidelity != coarse:  # fitted coarse, carried on as fine (else a later round refits it and takes the gain)
            say("polish", f"round {round_}: carrying {best['effect']} at {best['where']} on as fine as the rig's model")
            best = carry_on(data, runner, scored(data, best, sims))
            current, sims = best["model"], best["sims"]
        steps.append(step(f"+ {best['effect']} at {best['where']}", data, sims, current))
        round_models[current.places()] = current
        if raise_noise_floor(data, runner, current, sims, say):  # later rounds, the verdict and elimination judge by it
            raised = True
            per = unit_change(data)
            steps.append(step("the same, judged by the floors it raises", data, sims, current))
        mismatch = locate(data, sims) or mismatch
    else:  # the loop ran to the limit: whether a further effect would earn its place was never asked
        limited = max_effects
    if len(rounds) > 1:  # an earlier round's choice, with the later findings in (earlier.swap_earlier)
        say("swap", "refitting each earlier finding's runners-up in its place beside the later findings")
        def anew(base: Model, effect: str, where: str) -> Model | None:
            """The round's candidate fitted anew on `base` (a ripple's period scanned again; of its fits the one that
            leaves the least), or None."""
            if (effect, where) not in shortlisted:
                return None
            out = fit_candidates(data, runner, base, [shortlisted[effect, where]], rig_columns, FIT_ITERATIONS, per)
            return min((r for r in out if "model" in r), key=lambda r: r["cost"], default={}).get("model")

        now, tried = swap_earlier(data, runner, scored(data, {"model": current}, sims), rounds[:-1], PAIR_MARGIN, anew)
        if now["model"] is not current:
            current, sims = now["model"], now["sims"]
            steps.append(step(f"{now['effect']} at {now['where']} in an earlier finding's place", data, sims, current))
        judged = {(loser["effect"], loser["where"], winner["effect"]) for loser, winner in tried}  # judged again beside the later findings
        alternatives = [a for a in alternatives if (a["effect"], a["where"], a["instead_of"]) not in judged] + [
            alternative_entry(data, loser, winner, len(loser["model"].effects) - 1) for loser, winner in tried
            if rival(loser, winner, later=True, absorbable=data.absorbable)]
    if len(current.effects) > 1:  # one friction law where two were found at one joint (laws.one_law)
        now, tried = one_law(data, runner, scored(data, {"model": current}, sims), PAIR_MARGIN)
        if now["model"] is not current:
            say("swap", f"{now['effect']} at {now['where']} explains better than the two friction laws found there")
            current, sims = now["model"], now["sims"]
            steps.append(step(f"{now['effect']} at {now['where']} in place of two laws there", data, sims, current))
        alternatives += [alternative_entry(data, loser, winner, before) for loser, winner, before in tried
                         if rival(loser, winner, later=True, absorbable=data.absorbable)]
    if not current.effects:  # nothing earned its place
        current, sims = without_findings(data, runner, current, refit_model, refit_sims, say)
        if current is not refit_model:
            steps.append(step("parameters refit in the floors' units", data, sims, current))
    current, sims, ranges, ablated, train_f, held_f = settle(
        data, runner, current, sims, say, local=local, raised=raised, nominal_floors=nominal_floors,
        refit=(refit_model, refit_sims), round_models=round_models, steps=steps, rejected=rejected)
    current, ranges = canonical_form(current, ranges)
    refit_train, refit_held = fit_scores(data, refit_sims, "train"), fit_scores(data, refit_sims, "held_out")
    findings = []
    for i, effect in sorted(enumerate(current.effects), key=lambda ie: -ablated[ie[0]]["noise_ratio"]):
        scores = {"train_before": refit_train["nrmse"], "train_after": train_f["nrmse"], "held_before": refit_held["nrmse"],
                  "held_after": held_f["nrmse"], "ratio_before": refit_held["noise_ratio"], "ratio_after": held_f["noise_ratio"],
                  "ablated": ablated[i]["noise_ratio"], "held_without": ablated[i]["nrmse"]}
        findings.append(finding(data, effect, ranges.get(i, {}), scores, mismatch))
    share = explained_share(refit_held["noise_ratio"], held_f["noise_ratio"])
    curved, disturbed = curved_channels(data, sims), disturbances(data, sims)
    verdict = verdict_of(current, train_f, held_f, share, curved, local, disturbed)
    alternatives = [a for a in alternatives if any(f["effect"] == a["instead_of"] for f in findings)
                    and not told_apart(a, held_f)]
    report = {
        "format": "flexarm-diagnosis/1",
        "rig": data.rig.name,
        "recordings": data.names,
        "verdict": verdict,
        "verdict_reason": verdict_reason(verdict, train_f, held_f, refit_train, refit_held, share, curved, local, limited,
                                         disturbed, len(findings)),
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
                  "per_channel": noise_table(data), "fidelity": runner.fidelity, "coarse_error": refit.coarse_error},
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
                              "curved_channels": curved, "disturbances": disturbed, "local_windows": local,
                              "parameters_at_bounds": report["parameters_at_bounds"]}
    if propose and alternatives:
        from .experiment import propose_experiment

        say("experiment", f"simulating {len(alternatives) + 1} explanations on the rig's experiment menu")
        report["proposed_experiment"] = propose_experiment(data, current, alternatives, runner)
    return report

