"""A shape or quantised parameter profiled (diagnosis/level.py): the 95 % intervals along a valley no Jacobian sees.

Stand-ins: a dwell-time stiction's extra break-away gain x (1 - e^(-T / time constant)) after rests T, against the
truth's, plus a rig parameter's column; and a delayed command, against the truth's delay. Each is smooth in
everything but the profiled parameter, so a first-order re-solve at each of its values is near exact.
"""
import math

import numpy as np

from watflex_sim.diagnosis import Model, Slot, level
from watflex_sim.diagnosis.fitting import intervals
from watflex_sim.diagnosis.level import level_profile, level_reach, level_start, shape_name

from test_period_profile import jacobian_of  # central differences in internal units

RESTS = np.repeat(np.linspace(0.3, 0.9, 7), 60)  # s: the rests before each break-away (seed 59's staircase: 0.3-0.9 s)
BEND = np.linspace(-1.0, 1.0, RESTS.size) ** 2  # a rig parameter's column: any shape the dwell's is not


def test_shape_names():
    """The shape parameter beside an effect's sizes: a dwell's time constant, a Stribeck velocity; none for a delay
    (quantised, no size beside it) or a ripple (its period is profiled by period.py)."""
    assert shape_name("dwell_time_stiction") == "time_constant"
    assert shape_name("stribeck_friction") == "v_s"
    assert shape_name("delay") == ""
    assert shape_name("position_dependent_friction") == ""


def test_a_parameter_the_catalogue_marks_profiled_is_profiled_like_a_shape():
    """effects.Param.profiled: presliding has no shape (no parameter of it has a neutral value), but its bristle damping
    sigma1 is profiled (level.levels): the final refit restarts from along its short profile and its interval walks
    it. Seed 121's watflex-c6b358de (sigma0 9,047 N m/rad, sigma1 19.87 N m s/rad): sigma1 was left at 9.93 by its
    10.0 start, the interval [6.99, 18.07] missing the truth; profiled, 20.27 [16.2, 25.4] and sigma0 9,004 [8,116,
    9,959] (measured, `tools/score_benchmark.py` on that case). A joint compliance's stiffness, log-scaled with no
    neutral too, is not marked: only what the catalogue says is profiled."""
    from watflex_sim.diagnosis.level import levels

    assert shape_name("presliding") == ""
    effect = {"effect": "presliding", "where": "elbow", "sigma0": 1e4, "sigma1": 10.0}
    assert levels(None, effect) == [("sigma1", (0.1, 100.0), 0.0)]  # the catalogue's bounds, no scale
    assert levels(None, {"effect": "joint_compliance", "where": "elbow", "stiffness": 1e4}) == []


def test_a_time_constants_profile_reaches_along_its_valley_where_the_jacobian_cannot():
    """level_reach(): rests of 0.3-0.9 s only (seed 59, watflex-1e32daae: 0.29 / 0.58 s fitted for a gain of 0.51 and
    0.98 s; a fit from 1.13 s ends 0.06 % costlier) leave the gain and the time constant along a curved valley. The
    estimate at 0.5 s (its best gain there, 0.33) sits ~16 cost units up the valley's wall under noise of 0.05 (the
    gain's units); the Jacobian's interval there stops short of the truth (0.5 at 1.0 s). The profile's range must
    reach it, the gain's follow to 0.5, and both stop short of what the noise resolves (a time constant of 0.25 s or
    2 s: two rungs of LEVEL_RATIO from the truth)."""
    truth = {"gain": 0.5, "time_constant": 1.0}
    noise = np.random.default_rng(5).normal(0.0, 0.05, RESTS.size)

    def dwell(e: dict) -> np.ndarray:
        return e["gain"] * (1.0 - np.exp(-RESTS / e["time_constant"]))

    def evaluate(models):
        return [(dwell(m.effects[0]) + (m.parameters.get("elbow_friction", 1.0) - 1.0) * BEND - dwell(truth) + noise) / 0.05
                for m in models]

    slots = [Slot(("effect", 0, "gain"), 0.0, 3.0), Slot(("effect", 0, "time_constant"), 0.05, 30.0, log=True),
             Slot(("param", "elbow_friction"), 0.9, 1.1)]
    start = Model([{"effect": "dwell_time_stiction", "where": "elbow", "gain": 0.3, "time_constant": 0.5}], {"elbow_friction": 1.0})
    estimate = level_profile(evaluate, start, 0, "time_constant", slots, jacobian_of(evaluate, start, slots), [0.5])[0][1]
    assert 0.3 < estimate.effects[0]["gain"] < 0.36  # the gain that fits best at 0.5 s
    r, J = evaluate([estimate])[0], jacobian_of(evaluate, estimate, slots)
    assert intervals(slots, estimate, J, r)[1][1] < truth["time_constant"]  # the Jacobian's interval misses it
    reach, kept = level_reach(evaluate, estimate, 0, "time_constant", (0.05, 30.0), 0.0, slots, J, r, [], None)
    assert 0.25 < reach[1][0] < truth["time_constant"] < reach[1][1] < 2.0
    assert reach[0][0] < truth["gain"] < reach[0][1]
    assert any(abs(k - 1.0) < 1e-9 for k in kept) and all(0.25 < k < 2.0 for k in kept)


def test_a_delays_interval_holds_every_step_the_noise_cannot_tell_from_the_found_one():
    """level_reach() on a quantised parameter: a command delayed 11 ms found at 10 ms (seed 64, watflex-7c2659f4,
    [9.5, 10.5] ms) where a step of 1 ms moves the residual by about the noise: the steps within the limit must hold
    11 ms and none 4 ms or more away (each such step costs ~16 x what a step does, beyond 1.92 x the noise)."""
    t = np.arange(0.0, 2.0, 0.001)
    noise = np.random.default_rng(2).normal(0.0, 1.0, t.size)

    def command(delay: float) -> np.ndarray:
        return 600.0 * np.sin(2 * np.pi * 0.5 * (t - delay)) / math.sqrt(t.size)

    def evaluate(models):
        return [command(m.effects[0]["seconds"]) - command(0.011) + noise for m in models]

    estimate = Model([{"effect": "delay", "where": "command", "seconds": 0.010}], {})
    r = evaluate([estimate])[0]
    reach, kept = level_reach(evaluate, estimate, 0, "seconds", (0.0, 0.05), 0.001, [], np.zeros((t.size, 0)), r, [], None)
    assert reach == {}
    assert any(abs(k - 0.011) < 1e-9 for k in kept)
    assert all(abs(k - 0.010) < 0.0035 for k in kept)


def test_the_final_refit_starts_again_from_a_step_the_profile_says_costs_less_beyond_the_noise(monkeypatch):
    """level_start(): a command delayed 11 ms kept at 10 ms (seed 64, watflex-7c2659f4: the 10 ms step costs 3.5 x the
    11 ms one's 0.5 |r|^2 of 2,668) is restarted from 11 ms; at 11 ms, and where the 11 ms step gains less than the
    noise resolves (1.96^2 / 2 x s^2, 1.92 here), there is nothing to restart from."""
    monkeypatch.setattr(level, "scale_of", lambda data, param, where: 1.0)  # seconds are seconds on any rig
    t = np.arange(0.0, 2.0, 0.001)
    noise = np.random.default_rng(2).normal(0.0, 1.0, t.size)

    def evaluate_for(amplitude: float):
        def command(delay: float) -> np.ndarray:
            return amplitude * np.sin(2 * np.pi * 0.5 * (t - delay)) / math.sqrt(t.size)
        return lambda models: [command(m.effects[0]["seconds"]) - command(0.011) + noise for m in models]

    def start(evaluate, seconds: float):
        model = Model([{"effect": "delay", "where": "command", "seconds": seconds}], {})
        return level_start(None, evaluate, model, [], np.zeros((t.size, 0)), evaluate([model])[0])

    assert start(evaluate_for(2000.0), 0.010).effects[0]["seconds"] == 0.011
    assert start(evaluate_for(2000.0), 0.011) is None
    assert start(evaluate_for(300.0), 0.010) is None  # 0.5 |r|^2 differs by ~0.22 per step


def test_the_final_refit_starts_again_on_a_valley_narrower_than_the_profiles_steps(monkeypatch):
    """fine_start(): a one-way Stribeck friction whose data sample it at 0.020-0.030 rad/s (break-away x
    exp(-(v / v_s)^2) there) leaves a valley diagonal in v_s and break-away; the final refit stopped on its wall (seed
    111, watflex-26368bfd: 1.055 N m positive only at v_s 0.02451 rad/s, refit at 1.150 / 0.0152 N m and 0.02356, the
    truth 13,348 |r|^2 lower; level_start's steps of 2^(1/2) in v_s land on the walls). The fine profile's least point
    lies below the estimate beyond what the noise resolves (1.96^2 s^2, s = 1 here), its break-away within 3 % and
    its v_s within 1 % of the truth; at the truth there is nothing to start from."""
    monkeypatch.setattr(level, "scale_of", lambda data, param, where: 10.0 if param.scale else 1.0)  # 10 N m peak
    speeds = np.linspace(0.020, 0.030, 50)  # rad/s
    noise = np.random.default_rng(4).normal(0.0, 1.0, speeds.size)
    truth = {"breakaway_positive": 1.055, "breakaway_negative": 0.0, "v_s": 0.02451}

    def evaluate(models):
        def excess(e: dict) -> np.ndarray:
            return e["breakaway_positive"] * np.exp(-(speeds / e["v_s"]) ** 2)
        return [(excess(m.effects[0]) - excess(truth)) / 0.01 + noise for m in models]  # noise of 0.01 N m

    def start(values: dict) -> tuple[Model, Model | None]:
        model = Model([{"effect": "stribeck_friction", "where": "elbow", **values}], {})
        return model, level.fine_start(None, evaluate, model, 3, evaluate([model])[0])

    model, found = start({"breakaway_positive": 1.150, "breakaway_negative": 0.0152, "v_s": 0.02356})
    cost = lambda m: float(evaluate([m])[0] @ evaluate([m])[0])  # noqa: E731
    assert cost(found) < cost(model) - 1.96**2
    assert abs(found.effects[0]["breakaway_positive"] / truth["breakaway_positive"] - 1) < 0.03
    assert abs(found.effects[0]["v_s"] / truth["v_s"] - 1) < 0.01
    assert start(truth)[1] is None


def test_a_findings_step_held_since_its_round_is_searched_again_on_the_training_blocks(monkeypatch):
    """refit.levels_on_training(): seed 120's laser_arm-91f8db5b, a 5 ms tip-sensor delay found at 4 ms in round 1 and
    held there while round 2 found a voltage offset beside it, was judged at 5.76 x the noise (`unexplained`). Here a
    delay found at 10 ms for 11 ms (the step costs far beyond the noise): moved to 11 ms on the training residual and
    kept; not kept where validation gets worse; left alone where no finding has a step or a shape."""
    from watflex_sim.diagnosis import refit

    monkeypatch.setattr(level, "scale_of", lambda data, param, where: 1.0)  # seconds are seconds on any rig
    t = np.arange(0.0, 2.0, 0.001)
    noise = np.random.default_rng(2).normal(0.0, 1.0, t.size)

    def command(delay: float) -> np.ndarray:
        return 2000.0 * np.sin(2 * np.pi * 0.5 * (t - delay)) / math.sqrt(t.size)

    class Runner:
        def simulate(self, model):
            return [model.effects[0]["seconds"]]  # "simulations" that say which step they are at

    held = {0.010: 5.76, 0.011: 0.78}  # validation noise ratios of the two steps
    bend = np.linspace(-1.0, 1.0, t.size) ** 2  # a rig parameter's column, fitted beside the step
    monkeypatch.setattr(refit, "in_noise", lambda data, runner: lambda models: [
        command(m.effects[0]["seconds"]) - command(0.011) + 50.0 * (m.parameters["x"] - 1.0) * bend + noise
        for m in models])
    monkeypatch.setattr(refit, "effect_slots_of", lambda data, model: [])
    monkeypatch.setattr(refit, "rig_slots", lambda data: [Slot(("param", "x"), 0.9, 1.1)])
    monkeypatch.setattr(refit, "fit_scores", lambda data, sims, part: {"noise_ratio": held[round(sims[0], 6)]})
    found = Model([{"effect": "delay", "where": "tip_sensor", "seconds": 0.010}], {"x": 1.0})
    moved, sims = refit.levels_on_training(None, Runner(), found, [0.010])
    assert moved.effects[0]["seconds"] == 0.011 and sims == [0.011]
    held[0.011] = 6.0  # validation worse at the new step: kept as it was
    assert refit.levels_on_training(None, Runner(), found, [0.010]) == (found, [0.010])
    monkeypatch.setattr(refit, "levels", lambda data, effect: [])
    assert refit.levels_on_training(None, Runner(), found, [0.010]) == (found, [0.010])
