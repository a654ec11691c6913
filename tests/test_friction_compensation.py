"""Friction compensation schemes (controllers.friction_compensation; thesis 4.4, 4.5.5).

Elbow friction from rigs.md §2 (+: 4.9589, 0.5232, 1.2563, 0.0402; -: 5.4392, 0.5556, 0.8162,
0.0208); qualified constants k_gamma = 100 s/rad, k_tau = 1 rad/(N m s), delta = 0.01 N m.
"""
import math

import numpy as np
import pytest

from watflex_sim.controllers import PDJoint
from watflex_sim.controllers.friction_compensation import FrictionCompensation, wrap_compensation
from watflex_sim import load_scenario
from watflex_sim.engine import ControlLoop
from watflex_sim.friction import slope_limited
from watflex_sim.params import LASER_ARM, WATFLEX

POS, NEG = WATFLEX.elbow_friction


class Constant:
    """An inner controller commanding constant torques (N m)."""

    def __init__(self, elbow: float, shoulder: float = 1.5):
        self.u = {"elbow_torque_cmd": elbow, "shoulder_torque_cmd": shoulder}
        self.resets = 0

    def reset(self):
        self.resets += 1

    def __call__(self, t, obs):
        return dict(self.u)


def settle(scheme: str, tau: float, speed: float, seconds: float = 2.0, **kw) -> tuple[dict, FrictionCompensation]:
    """Run the wrapper on an encoder ramp theta = speed t (rad/s) for `seconds`; return the last
    command and the wrapper. The 10 Hz Butterworth settles on the backward difference = speed."""
    comp = FrictionCompensation(Constant(tau), "elbow", scheme, POS, NEG, **kw)
    comp.reset()
    out = None
    for k in range(int(round(seconds / 1e-3))):
        out = comp(k * 1e-3, {"elbow_angle": speed * k * 1e-3, "elbow_reference": 0.0})
    assert comp.velocity == pytest.approx(speed, rel=1e-9, abs=1e-12)
    assert out["shoulder_torque_cmd"] == 1.5  # other channels pass through
    return out, comp


@pytest.mark.parametrize("tau, expected", [
    (2.0, 2.0 + 4.9589),  # tau + alpha0_+ sgn(tau)
    (-2.0, -2.0 - 5.4392),  # tau - alpha0_-
    (0.0, 0.0),
])
def test_coulomb_feed_forward(tau, expected):
    """Fig. 4.12a: tau + alpha0_dir sgn(tau), whatever the velocity (here 0.05 rad/s)."""
    out, _ = settle("coulomb_ff", tau, 0.05)
    assert out["elbow_torque_cmd"] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("tau, expected", [
    (0.004, 0.004 + 4.9589 * 0.4),  # on the finite slope: alpha0 tau / dv, dv = 0.01 N m
    (-0.0025, -0.0025 - 5.4392 * 0.25),
    (-0.02, -0.02 - 5.4392),  # beyond dv: Coulomb level
])
def test_finite_slope_feed_forward(tau, expected):
    """Fig. 4.12b: tau + alpha0_dir clip(tau / dv, -1, 1)."""
    out, _ = settle("finite_slope_ff", tau, 0.0)
    assert out["elbow_torque_cmd"] == pytest.approx(expected, rel=1e-12)


def test_feed_forward_plus_velocity_feedback():
    """Fig. 4.13 at tau = 1 N m, v = -0.05 rad/s: alpha0_+ (part 1) plus
    -0.5556 e^-(0.05/0.0208)^2 (1 - e^-15) - 0.8162 x 0.05 (part 2) = 4.9589 - 0.001718 - 0.04081."""
    out, comp = settle("ff_velocity_fb", 1.0, -0.05)
    part2 = -0.5556 * math.exp(-((0.05 / 0.0208) ** 2)) * (1 - math.exp(-15.0)) - 0.8162 * 0.05
    assert part2 == pytest.approx(-0.042529, abs=1e-6)
    assert out["elbow_torque_cmd"] == pytest.approx(1.0 + 4.9589 + part2, rel=1e-9)


def test_velocity_feedback():
    """Fig. 4.14: tau + slope_limited(v); at v = 0.1 rad/s (k_S v = 30):
    (4.9589 + 0.5232 e^-(0.1/0.0402)^2 + 0.12563)(1 - e^-30) = 5.085282 N m; nothing at rest."""
    out, comp = settle("velocity_fb", 0.3, 0.1)
    hand = (4.9589 + 0.5232 * math.exp(-((0.1 / 0.0402) ** 2)) + 0.12563) * (1 - math.exp(-30.0))
    assert comp.compensation == pytest.approx(hand, rel=1e-9)
    assert out["elbow_torque_cmd"] == pytest.approx(0.3 + hand, rel=1e-9)
    out, comp = settle("velocity_fb", 3.0, 0.0)  # below break-away: the joint would never start
    assert out["elbow_torque_cmd"] == 3.0


@pytest.mark.parametrize("tau", [0.004, -0.003, 3.0, -3.0])
def test_qualified_at_rest_uses_the_input_torque(tau):
    """Eq. 4.19 with gamma = 0 (v = 0): tau_f = slope_limited(k_tau clip(tau, +-delta));
    e.g. tau = 0.004 N m: (4.9589 + 0.5232 e^-(0.004/0.0402)^2 + 1.2563 x 0.004)(1 - e^-1.2) = 3.8308."""
    out, comp = settle("qualified", tau, 0.0)
    expected = slope_limited(max(-0.01, min(0.01, tau)), POS, NEG, 300.0)
    assert comp.compensation == pytest.approx(expected, rel=1e-12)
    assert out["elbow_torque_cmd"] == pytest.approx(tau + expected, rel=1e-12)
    if tau == 0.004:
        hand = (4.9589 + 0.5232 * math.exp(-((0.004 / 0.0402) ** 2)) + 1.2563 * 0.004) * (1 - math.exp(-1.2))
        assert comp.compensation == pytest.approx(hand, rel=1e-12) and hand == pytest.approx(3.8308, abs=1e-4)


@pytest.mark.parametrize("speed", [0.2, -0.2, 0.01])
def test_qualified_at_speed_uses_the_velocity(speed):
    """Eq. 4.18: k_gamma |v| >= 1 (|v| >= 0.01 rad/s) -> gamma = 1, tau_f = slope_limited(v),
    whatever the input torque (here -3 N m)."""
    _, comp = settle("qualified", -3.0, speed)
    assert comp.compensation == pytest.approx(slope_limited(speed, POS, NEG, 300.0), rel=1e-9)


def test_qualified_cross_fade():
    """Eq. 4.18-4.19 at v = 0.004 rad/s, tau = -1 N m: gamma = 0.4,
    v~ = 0.4 x 0.004 + 0.6 x (-0.01) = -0.0044 rad/s."""
    _, comp = settle("qualified", -1.0, 0.004)
    assert comp.compensation == pytest.approx(slope_limited(-0.0044, POS, NEG, 300.0), rel=1e-8)
    assert comp.compensation < 0


def test_reset_resets_inner_and_filter():
    inner = Constant(1.0)
    comp = FrictionCompensation(inner, "elbow", "qualified", POS, NEG)
    comp(0.0, {"elbow_angle": 0.0})
    comp(0.001, {"elbow_angle": 1e-3})
    comp.reset()
    assert inner.resets == 2 and comp.velocity == 0.0 and comp._previous is None


def test_wrap_compensation_defaults_and_overrides():
    """Positive/negative default to the rig's nominal friction of the joint; fields override."""
    comp = wrap_compensation(Constant(0.0), {"scheme": "qualified", "joint": "shoulder", "k_s": 200}, WATFLEX)
    assert (comp.positive, comp.negative) == WATFLEX.shoulder_friction and comp.k_s == 200.0
    comp = wrap_compensation(Constant(0.0), {"scheme": "coulomb_ff", "joint": "elbow", "positive": {"alpha0": 4.0}}, WATFLEX)
    assert comp.positive.alpha0 == 4.0 and comp.positive.alpha1 == POS.alpha1 and comp.negative == NEG


@pytest.mark.parametrize("spec, match", [
    ({"scheme": "lugre", "joint": "elbow"}, "unknown scheme 'lugre'"),
    ({"joint": "elbow"}, "missing 'scheme'"),
    ({"scheme": "qualified"}, "missing 'joint'"),
    ({"scheme": "qualified", "joint": "wrist"}, "unknown joint 'wrist'"),
    ({"scheme": "qualified", "joint": "elbow", "k_foo": 1.0}, "unknown field.*k_foo"),
    ({"scheme": "qualified", "joint": "elbow", "delta": "big"}, "delta must be a number"),
    ({"scheme": "qualified", "joint": "elbow", "positive": {"mu": 1.0}}, "compensation.positive"),
    ({"scheme": "qualified", "joint": "elbow", "positive": 3.0}, "positive must be a table"),
])
def test_wrap_compensation_errors(spec, match):
    with pytest.raises(ValueError, match=match):
        wrap_compensation(Constant(0.0), spec, WATFLEX)


def test_wrap_compensation_on_a_rig_without_joint_friction():
    with pytest.raises(ValueError, match="unknown joint 'hub'"):
        wrap_compensation(Constant(0.0), {"scheme": "qualified", "joint": "hub"}, LASER_ARM)
    comp = wrap_compensation(Constant(0.0), {"scheme": "qualified", "joint": "hub",
                                             "positive": {"alpha0": 2.778, "alpha1": 0.0, "alpha2": 0.0, "v_s": 1.0},
                                             "negative": {"alpha0": 0.926, "alpha1": 0.0, "alpha2": 0.0, "v_s": 1.0}}, LASER_ARM)
    assert comp.negative.alpha0 == 0.926


# Closed loop (thesis 4.5.5, fig. 4.27): P-controlled elbow actuator, 5 N m/rad, 0.5 rad step.
BENCH = ['actuator_bench="elbow"', "controller.kp=[5.0]", "controller.kd=[0.0]", "noise=false"]


def elbow_step(extra=(), scheme=None) -> np.ndarray:
    """Elbow angle (rad) every 1 ms of watflex_elbow_step on the bench, optionally compensated."""
    scenario = load_scenario("watflex_elbow_step", BENCH + list(extra))
    angles = []
    with ControlLoop(scenario) as loop:
        if scheme is not None:
            assert isinstance(loop.controller, PDJoint)
            loop.controller = FrictionCompensation(loop.controller, "elbow", scheme, POS, NEG)
            loop.controller.reset()
        for k in range(loop.n_ticks):
            obs, _ = loop.tick(k)
            angles.append(obs["elbow_angle"])
    return np.array(angles)


@pytest.fixture(scope="module")
def responses():
    return {"frictionless": elbow_step(['friction="none"']), "uncompensated": elbow_step(),
            "qualified": elbow_step(scheme="qualified"), "velocity_fb": elbow_step(scheme="velocity_fb")}


def correlation(a, b) -> float:
    """Pearson correlation; 0 when either signal is constant (no linear relation)."""
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def test_qualified_compensation_reaches_the_step(responses):
    """Uncompensated the P torque 5 x 0.5 = 2.5 N m stays below the break-away 5.48 N m: the joint
    never moves and the final error is the whole 0.5 rad. Compensated, the loop is the ideal
    motor's undamped oscillator (omega = sqrt(5/1.25) = 2 rad/s, 0 <-> 1 rad): measured final
    error -0.136 rad (phase-dependent), mean angle over the last period 0.4975 rad (error 0.0025)."""
    ref = 0.5
    unc, comp, free = responses["uncompensated"], responses["qualified"], responses["frictionless"]
    assert np.abs(unc).max() < WATFLEX.encoder_step and abs(ref - unc[-1]) == pytest.approx(0.5)
    assert abs(ref - comp[-1]) < 0.2  # measured 0.136 rad
    last_period = slice(len(comp) - int(round(math.pi * 1000)), None)  # 2 pi / omega
    assert abs(ref - comp[last_period].mean()) < 0.01  # measured 0.0025 rad (frictionless: 0.0001)
    assert comp.max() == pytest.approx(free.max(), abs=0.01)  # 1.0004 vs 1.0012 rad


def test_qualified_compensation_tracks_the_frictionless_motor(responses):
    """The compensated response correlates with the frictionless one (measured 0.991) and stays
    within 0.051 rad rms of it; the uncompensated joint does not move (correlation 0, 0.62 rad rms)."""
    free = responses["frictionless"]
    r_comp, r_unc = correlation(responses["qualified"], free), correlation(responses["uncompensated"], free)
    rms = {k: float(np.sqrt(np.mean((x - free) ** 2))) for k, x in responses.items()}
    assert rms["qualified"] == pytest.approx(0.0506, abs=0.02) and rms["uncompensated"] == pytest.approx(0.6212, abs=0.01)
    assert r_comp > 0.98 and r_comp > r_unc
    assert rms["qualified"] < 0.1 < 0.5 < rms["uncompensated"]


def test_scenario_compensation_table_matches_the_wrapper(responses):
    """The lead's [controller.compensation] hook (engine.make_controller) builds the same loop."""
    scenario = load_scenario("watflex_elbow_step", BENCH + ['controller.compensation={scheme="qualified", joint="elbow"}'])
    with ControlLoop(scenario) as loop:
        assert isinstance(loop.controller, FrictionCompensation)
        angles = np.array([loop.tick(k)[0]["elbow_angle"] for k in range(loop.n_ticks)])
    np.testing.assert_array_equal(angles, responses["qualified"])


def test_velocity_feedback_alone_cannot_start_from_rest(responses):
    """Thesis 4.4.3: pure velocity feed-back adds nothing at rest, so 2.5 N m below break-away
    never starts the joint (the drawback the qualified scheme removes)."""
    assert np.abs(responses["velocity_fb"]).max() < WATFLEX.encoder_step
