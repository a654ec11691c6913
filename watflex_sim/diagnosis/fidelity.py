"""How fine the diagnosis simulates: half as fine as the rig's model where that is as good against the noise.

Contract: `choose_fidelity` simulates the nominal model SCREEN_FINER x as fine and sets `runner.fidelity` to that where
it is within COARSE_MARGIN x the noise of the model's own on every channel; `keep_fidelity` goes back to as fine once a
model with effects is not (each finding as it is taken), `fine_for_round` once one of a round's fitted candidates is
not (their fits carried on there, refine.carry_on_each). Each returns the simulations at the fidelity kept.
"""
from __future__ import annotations

from dataclasses import replace

from ..recording import Recording
from .data import Data, Model
from .effect_fit import scored
from .refine import carry_on_each
from .runner import Runner
from .scores import channel_ratios
from .screening import SCREEN_FINER

COARSE_MARGIN = 0.15  # x the noise: the whole diagnosis simulates SCREEN_FINER x as fine as the rig's model where the
# nominal model so simulated is within this of the model's own (RMS) on every channel of every recording: it adds at
# most 2 % to a channel's noise variance, and the 2 x finer comparison (floors.calibrate_noise) then counts it. Measured:
# the laser arm 0.04-0.07 x (6 segments at 0.2 ms for 11 at 0.1 ms, half the cost), Watflex 0.5-7.5 x (seeds 65-66)



def choose_fidelity(data: Data, runner: Runner, sims: list[Recording], say) -> tuple[list[Recording], float | None]:
    """Simulate the nominal model SCREEN_FINER x as fine as the rig's (`sims`: as fine) and, where it is within
    COARSE_MARGIN x the noise of `sims` (RMS) on every channel of every recording, set `runner.fidelity` to that:
    every later simulation of the diagnosis then costs about half (the laser arm). Returns the nominal model's
    simulations at the fidelity chosen and the coarse one's largest difference in noise units (None: no coarser
    discretisation, or it diverged)."""
    if not runner.refinable(SCREEN_FINER):
        return sims, None
    coarse = runner.simulate(Model(), finer=SCREEN_FINER)
    if coarse is None:
        return sims, None
    worst = _largest_difference(data, sims, coarse)
    if worst > COARSE_MARGIN:
        return sims, worst
    runner.fidelity = SCREEN_FINER
    say("nominal", f"the model simulated {SCREEN_FINER:g} x as fine is within {worst:.2f} x the noise of its own on every "
        f"channel (at most {COARSE_MARGIN:g} x): the diagnosis simulates at that")
    return coarse, worst


def keep_fidelity(data: Data, runner: Runner, model: Model, sims: list[Recording], say) -> list[Recording]:
    """Where the runner simulates coarser than the rig's model (choose_fidelity) and `model` has effects (called as each
    finding is taken): simulate it as fine as the rig's model too, and if its coarse `sims` are beyond COARSE_MARGIN x
    the noise of that on some channel (a dead band or stick-slip can make the coarse model far from its own where the
    nominal one was not: the laser demo's backlash fitted coarse ends at 2.2 x the noise, as fine at 0.84 x), simulate
    as fine as the rig's model from now on (the pipeline then carries the finding's fit on there: refine.carry_on).
    Returns `model`'s simulations at the fidelity kept."""
    if runner.fidelity == 1.0 or not model.effects:
        return sims
    effects = ", ".join(e["effect"] for e in model.effects)
    say("fidelity", f"checking the model with {effects}, simulated {runner.fidelity:g} x as fine, against its own")
    (fine, worst), = _as_fine(data, runner, [model], [sims])
    if worst <= COARSE_MARGIN:
        return sims
    runner.fidelity = 1.0
    say("fidelity", f"with {effects} the model simulated {SCREEN_FINER:g} x as fine is {worst:.2f} x the noise from its own "
        f"(more than {COARSE_MARGIN:g} x): simulating as fine as the rig's model from now on")
    return fine


def fine_for_round(data: Data, runner: Runner, current: Model, sims: list[Recording], results: list[dict],
                   say) -> tuple[list[dict], list[Recording]]:
    """Where the runner simulates coarser than the rig's model: simulate each fitted candidate of a round (`results`,
    scored as effect_fit.scored) as fine as the rig's model too, and if one is beyond COARSE_MARGIN x the noise of
    its own, simulate as fine from now on: every candidate's fit carried on there (refine.carry_on) and the current
    model re-simulated, so that the round compares like with like before it chooses. keep_fidelity checks the
    winner only; a candidate that the coarse model misjudges may never win (seed 74, laser_arm-366700d8: a 6.9e-5 rad
    hub backlash keeps the loop hunting at 3.9 Hz, at another phase half as fine; the truth scores 6.0 x the noise
    half as fine, 3.1 x as fine, and a joint compliance fitted half as fine won at 6.6 x).
    Returns (the candidates, the current model's simulations) at the fidelity kept."""
    if runner.fidelity == 1.0 or not results:
        return results, sims
    say("fidelity", f"checking the round's {len(results)} candidates, simulated {runner.fidelity:g} x as fine, against their own")
    checked = _as_fine(data, runner, [r["model"] for r in results], [r["sims"] for r in results])
    worst, which = max(((w, r) for (_, w), r in zip(checked, results)), key=lambda o: o[0])
    if worst <= COARSE_MARGIN:
        return results, sims
    now = runner.simulate(current, finer=1.0 / runner.fidelity)
    if now is None:
        return results, sims
    runner.fidelity = 1.0
    say("fidelity", f"{which['effect']} at {which['where']} simulated {SCREEN_FINER:g} x as fine is {worst:.2f} x the noise "
        f"from its own (more than {COARSE_MARGIN:g} x): simulating as fine as the rig's model from now on, the round's "
        "candidates carried on there")
    fine = [k for k, (f, _) in enumerate(checked) if f is not None]
    carried = dict(zip(fine, carry_on_each(data, runner, [(scored(data, results[k], checked[k][0]), None) for k in fine])))
    return [carried.get(k, r) for k, r in enumerate(results)], now


def _as_fine(data: Data, runner: Runner, models: list[Model], coarse: list[list[Recording]]
             ) -> list[tuple[list[Recording] | None, float]]:
    """Each model simulated as fine as the rig's model (one lockstep call), with how far its `coarse` simulations are
    from that: the largest channel's RMS difference in noise units (0 where the fine simulation diverged)."""
    fine = runner.simulate_models(models, finer=1.0 / runner.fidelity)
    return [(f, _largest_difference(data, f, c) if f is not None else 0.0) for f, c in zip(fine, coarse)]


def _largest_difference(data: Data, ours: list[Recording], other: list[Recording]) -> float:
    """The largest RMS difference of two simulations of the recordings over every channel, in units of its noise
    (scores.channel_ratios with `ours` standing for the measurements)."""
    return max((r["ratio"] for r in channel_ratios(replace(data, recordings=ours), other)), default=0.0)
