"""The findings settled: backward elimination, the final refit on all the data and the 95 % intervals, again until
every finding's intervals tell it from no effect at all.

Contract: `settle(data, runner, model, sims, say, ...)` takes the rounds' model (and its simulations) and returns the
final model, its simulations, its intervals (by effect index), each finding's validation without it (`ablated`,
validate.eliminate) and the training and validation scores it is judged by (before the final refit). Rig parameters
beyond their tolerance are folded into effects first (tolerance.fold_within_tolerance). A finding is dropped when
its final model does not need it on validation (validate.eliminate) or its intervals include no effect and validation
without it is not far worse (validate.vague_findings); what is left is refit on the training blocks, from the round's
fit of the same findings if there was one, and the floors measured again without the dropped (refit.floors_after_dropping)
where a finding had raised them. Before it is judged, a model short of the noise but near it is carried on by the
pattern search on the training blocks (pattern.pattern_polish). `steps` and `rejected` (the report's lists) get what
happened appended.
"""
from __future__ import annotations

from .data import Data, Model
from .pattern import pattern_polish
from .refit import final_refit, floors_after_dropping, held_without, refit_on_training, without_findings
from .runner import Runner
from .scores import fit_scores, step
from .tolerance import fold_within_tolerance
from .uncertainty import final_intervals
from .validate import eliminate, vague_findings

NO_EFFECT = "no effect at all (on a rig parameter's knob: a value within its tolerance)"  # what a vague finding's
# intervals include (validate.vague_findings)


def settle(data: Data, runner: Runner, current: Model, sims: list, say, *, local: list[dict], raised: bool,
           nominal_floors: dict, refit: tuple, round_models: dict, steps: list[dict], rejected: list[dict]) -> tuple:
    """(final model, its simulations, intervals, ablated, training scores, validation scores): see the module.
    `refit`: the refit nominal model and its simulations (what is left when no finding stays); `round_models`: each
    round's chosen model by its places (Model.places); `raised`: whether a finding raised the floors, `nominal_floors`
    the floors before (refit.FLOORS)."""
    refit_model, refit_sims = refit
    found = len(current.effects)
    current = fold_within_tolerance(data, current)
    if len(current.effects) < found:
        sims = runner.simulate(current) or sims
    while True:  # until every finding's intervals tell it from no effect (explain.indistinct)
        kept = len(current.effects)
        current, sims, ablated = eliminate(data, runner, current, sims, say, local)
        if raised and len(current.effects) < kept:  # judged by what noise leaves without the dropped findings
            floors_after_dropping(data, runner, current, sims, nominal_floors, say)
        if kept and not current.effects:
            current, sims = without_findings(data, runner, current, refit_model, refit_sims, say)
        if len(current.effects) < found:
            steps.append(step("after backward elimination", data, sims, current))
        polished, sims = pattern_polish(data, runner, current, sims, say)
        if polished is not current:
            current = polished
            steps.append(step("parameters carried on by a pattern search", data, sims, current))
        train_f, held_f = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")  # judged before the final refit
        trained = current
        if current.effects:
            say("final refit", "refitting the findings' and the rig's parameters on all the data (training and validation)")
            current, sims, trained = final_refit(data, runner, current, sims)
            steps.append(step("parameters refit on all the data", data, sims, current))
        say("intervals", "95 % intervals from the Jacobian at the final model and the training-only fit")
        ranges = final_intervals(data, runner, current, sims, trained)
        vague = vague_findings(data, current, ranges, ablated, held_f, lambda i: held_without(data, runner, trained, i))
        if not vague:
            break
        say("elimination", "dropping " + ", ".join(f"{current.effects[i]['effect']} at {current.effects[i]['where']}"
                                                   for i in vague) + f": its 95 % intervals include {NO_EFFECT}")
        rejected.extend({"effect": current.effects[i]["effect"], "where": current.effects[i]["where"],
                         "parameters": {k: v for k, v in current.effects[i].items() if k not in ("effect", "where")},
                         "intervals": ranges.get(i, {}),
                         "why": f"its 95 % intervals include {NO_EFFECT} and validation without it is not far worse"}
                        for i in vague)
        found = len(trained.effects)
        current = Model([e for i, e in enumerate(trained.effects) if i not in vague], dict(trained.parameters))
        if current.effects:  # its numbers were fitted beside the dropped: fitted again, from a round's fit of it if any
            say("elimination", "refitting the rest on the training blocks")
            current, new = refit_on_training(data, runner, round_models.get(current.places(), current))
            sims = new or sims
            if raised:
                floors_after_dropping(data, runner, current, sims, nominal_floors, say)
        else:
            if raised:
                floors_after_dropping(data, runner, current, sims, nominal_floors, say)  # no simulation
            current, sims = without_findings(data, runner, current, refit_model, refit_sims, say)
    return current, sims, ranges, ablated, train_f, held_f
