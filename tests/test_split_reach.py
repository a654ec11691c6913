"""An added friction and the rig's friction scale: the split between them as far as our discretisation allows
(reach.split_reach).

Stand-in: the data are a finer model's; the residual is S (total friction - truth's) along one direction a and
W (added Coulomb - truth's) along another, b: the data fix the total to S and the split only to W. Our model's
residual is the finer one's plus a discretisation error along b, which moves our estimate along the valley, the total
kept: the added friction DELTA low, the rig's friction scale DELTA / K high (seed 62, watflex-45eef46f: 0.455 N m
for 0.519 beside the scale at 1.012). The noise is orthogonal to a and b, so the estimate is our cost's exact minimum.
"""
import numpy as np
import pytest

from watflex_sim.diagnosis import Model, Slot
from watflex_sim.diagnosis.reach import SPLIT_LINE, split_reach

TRUTH = 0.52  # N m: the added Coulomb friction
K = 5.0  # N m per unit of the friction scale: the rig's own friction level
S, W = 2000.0, 400.0  # residual per N m of total friction and of the split (noise units)
DELTA = -0.064  # N m: where our discretisation moves the added friction
N = 3000


def basis_and_noise():
    rng = np.random.default_rng(3)
    a, b = np.linalg.qr(rng.standard_normal((N, 2)))[0].T
    noise = rng.standard_normal(N)
    return a, b, noise - a * (a @ noise) - b * (b @ noise)


ALONG = -DELTA * S**2 / (S**2 + W**2)  # N m per move to the datasheet's scale: the line's least-squares re-solve


def stand_in(error_sign: float, rough_at: float | None = None):
    """evaluate, slots, the estimate (our model's minimum), the rig's Jacobian column and the discretisation error
    (the finer model's residual less ours; error_sign -1: an error that favours the estimate instead). `rough_at`:
    an added friction (N m) within 1 mN of which the residual jumps by 40 noise units (a stick-slip cliff)."""
    a, b, noise = basis_and_noise()
    jump = np.linalg.qr(np.column_stack([a, b, np.random.default_rng(4).standard_normal(N)]))[0][:, 2] * 40.0
    ours = -W * DELTA * b  # our model's residual less the finer one's: its minimum moves by DELTA along the valley

    def evaluate(models):
        out = []
        for m in models:
            c, f = m.effects[0]["torque_positive"], m.parameters.get("elbow_friction", 1.0)
            cliff = jump if rough_at is not None and abs(c - rough_at) < 1e-3 else 0.0
            out.append(S * (c + K * (f - 1) - TRUTH) * a + W * (c - TRUTH) * b + noise + ours + cliff)
        return out

    slots = [Slot(("effect", 0, "torque_positive"), 0.0, 27.6), Slot(("param", "elbow_friction"), 0.95, 1.05)]
    estimate = Model([{"effect": "coulomb_friction", "where": "elbow", "torque_positive": TRUTH + DELTA,
                       "torque_negative": TRUTH + DELTA}], {"elbow_friction": 1.0 - DELTA / K})
    J = np.column_stack([S * a + W * b, S * K * a])
    return evaluate, slots, estimate, J, -error_sign * ours


def test_the_split_reaches_the_datasheets_where_the_finer_model_favours_it():
    """The estimate is 0.456 N m with the scale at 1.0128; the truth (0.52 N m, scale 1) costs (W DELTA)^2 / 2 =
    328 noise units more in our model, and the finer model's error takes 2 x that off it: along the line to the
    datasheet's scale (the added friction re-solved linearly: 0.0615 N m up per move, S^2 / (S^2 + W^2) of 0.064)
    the excess stays below 1.96^2 / 2 up to twice the move, SPLIT_LINE's end: the reach is 0.456 + 2 x 0.0615 =
    0.579 N m (the Jacobian's own 95 % interval is +-1.96 / W = +-0.005 N m about 0.456)."""
    evaluate, slots, estimate, J, error = stand_in(+1)
    r = evaluate([estimate])[0]
    reach = split_reach(evaluate, estimate, slots, 1, r, J, error)
    low, high = reach[0]
    assert low == pytest.approx(TRUTH + DELTA, abs=1e-9)
    assert high == pytest.approx(TRUTH + DELTA + SPLIT_LINE[-1] * ALONG, abs=1e-4)
    assert high > TRUTH


def test_a_rough_point_on_the_way_does_not_stop_the_line():
    """The same, with a stick-slip cliff at half the move (its cost 800 noise units above the smooth one's): the
    reach is the furthest point kept, 2 x the move, as without the cliff; stopped at the first point above the
    threshold it would be under half the move, short of the truth (seed 61, watflex-4730f348: +1,604 at half
    the move, -1,039 at the whole)."""
    evaluate, slots, estimate, J, error = stand_in(+1, rough_at=TRUTH + DELTA + SPLIT_LINE[0] * ALONG)
    r = evaluate([estimate])[0]
    assert split_reach(evaluate, estimate, slots, 1, r, J, error)[0][1] == pytest.approx(TRUTH + DELTA + SPLIT_LINE[-1] * ALONG, abs=1e-4)


def test_the_split_stays_at_the_estimate_where_nothing_favours_the_datasheets():
    """The same valley with the discretisation error the other way (the finer model favours the estimate), and
    with none: the excess at half the move is 394 and 79 noise units (315 t^2 + 630 t and 315 t^2, t = 0.5), so the
    reach, interpolated to 1.96^2 / 2, stops within 0.5 x 1.92 / 79 of the move (0.0008 N m): the truth is not reached.
    With the rig already at the datasheet's values there is no line: nothing."""
    for sign in (-1, None):
        evaluate, slots, estimate, J, error = stand_in(sign or 0.0)
        r = evaluate([estimate])[0]
        reach = split_reach(evaluate, estimate, slots, 1, r, J, None if sign is None else error)
        assert reach[0][1] - (TRUTH + DELTA) < 0.001
    at_datasheet = Model(estimate.effects, {"elbow_friction": 1.0})
    assert split_reach(evaluate, at_datasheet, slots, 1, evaluate([at_datasheet])[0], J, error) == {}
