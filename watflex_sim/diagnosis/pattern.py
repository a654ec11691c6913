"""The pattern search that carries a fit on where stick-slip makes its cost rough.

Contract: `pattern_search` runs fitting.compass over given slots on the training cost in noise units until training
and validation are within the noise (the verdict's own test) or the noise resolves no step; `compass_worth` says when
a model is near enough the noise to be worth it. The refit of the rig's parameters (refit.refit_nominal) uses it after
Levenberg-Marquardt; `pattern_polish` carries the final model on by it (settle, before the verdict).
"""
from __future__ import annotations

from ..recording import Recording
from .data import Data, Model, residual_vector
from .fitting import Slot, compass, effect_slots_of, rig_slots, value_of
from .refine import in_noise
from .runner import Runner
from .scores import fit_scores
from .validate import NOISE_MARGIN, within, within_noise

COMPASS_SWEEPS = 14  # at most this many pattern-search sweeps after the refit's Levenberg-Marquardt (2 simulations
# per parameter each); it stops once training and validation are within the noise, or once no step changes the
# cost by CHI2_RESOLUTION or by what a move must gain (fitting.compass; 6 sweeps halved the steps to
# 0.4 % of a tolerance at best: a clean Watflex case's strain bridge is 1.3 x its noise at link 2's EI 0.04 % off)
COMPASS_REACH = 3.0  # x NOISE_MARGIN: only a refit within this of the noise gets the pattern search; one further
# off is missing physics, which a harder refit only pushes into the rig's parameters (a 0.33 kg Watflex payload: the
# refit at 11.7 x the noise with elbow inertia at its bound and link 2's EI 4 % low, where its fits then started)
CHI2_RESOLUTION = 0.5  # Huber cost in noise units (chi-square / 2): a change below this the noise does not resolve


def compass_worth(train: dict) -> bool:
    """Whether the refit's training scores ask for the pattern search: short of the noise on some channel,
    but within COMPASS_REACH x the margin (further off, the rig's parameters would only absorb missing physics)."""
    return not within(train) and train["noise_ratio"] <= COMPASS_REACH * NOISE_MARGIN


def pattern_search(data: Data, runner: Runner, evaluate, model: Model, free: list[Slot],
                   sims: list[Recording]) -> tuple[Model, list[Recording] | None]:
    """fitting.compass over `free` from `model` (simulated as `sims`) on the training cost `evaluate` gives (noise
    units, as residual_vector's), stopping once training and validation are within the noise (the verdict's own test:
    a lower cost then changes no verdict); the model it ends at and its simulations (None: they diverged)."""
    checked = {}

    def within_both(trial: Model) -> bool:
        checked.update(model=trial, sims=runner.simulate(trial))
        return checked["sims"] is not None and within_noise(fit_scores(data, checked["sims"], "train"),
                                                            fit_scores(data, checked["sims"], "held_out"))
    moved = compass(evaluate, model, free, [value_of(model, s) for s in free], residual_vector(data, sims, unit="noise"),
                    COMPASS_SWEEPS, resolution=CHI2_RESOLUTION, enough=within_both)
    # the last move judged is where the search ended unless a later move followed: its simulations serve
    return moved, checked["sims"] if checked.get("model") == moved else runner.simulate(moved)


def pattern_polish(data: Data, runner: Runner, model: Model, sims: list[Recording], say,
                   what: str = "the final model") -> tuple[Model, list[Recording]]:
    """The final model (`what` the progress calls it; its findings' and the rig's parameters) carried on by the
    pattern search on the training blocks where it is short of the noise but near it (compass_worth), kept if
    validation is no worse: with the floors calibrated, as the refit before them, a closed loop that sticks and hunts
    makes the cost rough and Levenberg-Marquardt stops short. Seed 83's two-joint watflex-490a4521, an 11 ms command
    delay found to the millisecond with the elbow inertia at x1.010 (truth x1.028): training 1.47 x the noise,
    validation 1.87 x with the elbow encoder at 3.41 x, `unexplained`; carried on, it stops within the noise at 0.94 x
    and 1.04 x, the elbow inertia x1.029 (searched to its end: 0.78 x and 0.84 x)."""
    train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    if within_noise(train, held) or not compass_worth(train):
        return model, sims
    free = effect_slots_of(data, model) + rig_slots(data)
    say("polish", f"{what} is short of the noise (training {train['noise_ratio']:.2f} x, validation "
        f"{held['noise_ratio']:.2f} x): a pattern search over its {len(free)} parameters (stick-slip makes the cost rough)")
    moved, new = pattern_search(data, runner, in_noise(data, runner), model, free, sims)
    if new is None or fit_scores(data, new, "held_out")["noise_ratio"] > held["noise_ratio"]:
        return model, sims
    return moved, new
