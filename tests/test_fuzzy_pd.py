"""Fuzzy PD of laser_arm_paper section 2.4 (controllers/fuzzy_pd.py): surface, symmetry, closed loop."""
from __future__ import annotations

import numpy as np
import pytest

from watflex_sim.controllers import CONTROLLERS
from watflex_sim.controllers.fuzzy_pd import RULES, FuzzyPD, memberships
from watflex_sim import ConfigError, run_scenario
from watflex_sim.metrics import step_metrics
from watflex_sim.params import LASER_ARM

DESIGNS = [  # (kwargs, label): the default and a non-uniform one with other singletons
    ({}, "default"),
    ({"e_inner": 0.3, "de_inner": 0.7, "singletons": (-1.0, -0.2, 0.0, 0.2, 1.0)}, "non-uniform"),
]


@pytest.mark.parametrize("inference", ["product", "min"])
@pytest.mark.parametrize("kwargs", [d[0] for d in DESIGNS], ids=[d[1] for d in DESIGNS])
def test_surface_equals_rule_table_at_the_set_centres(kwargs, inference):
    """At the centre of error set i and rate set j only rule (i, j) fires, with degree 1:
    the defuzzified output is that rule's singleton exactly."""
    f = FuzzyPD(inference=inference, **kwargs)
    for i, e in enumerate(f.e_centres):
        for j, de in enumerate(f.de_centres):
            assert f.surface(e, de) == f.singletons[RULES[i][j]], (i, j)


def test_memberships_are_a_partition_of_unity_with_shoulders():
    centres = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
    for x in np.linspace(-3, 3, 601):
        mu = memberships(x, centres)
        assert mu.sum() == pytest.approx(1.0, abs=1e-15)
        assert np.count_nonzero(mu) <= 2 and mu.min() >= 0.0
    assert memberships(-7.0, centres)[0] == 1.0 and memberships(7.0, centres)[-1] == 1.0  # shoulders
    assert memberships(0.25, centres) == pytest.approx([0, 0, 0.5, 0.5, 0])


def test_rule_table_is_antisymmetric_and_the_surface_odd():
    rules = np.array(RULES)
    assert np.array_equal(rules[::-1, ::-1], 4 - rules)  # RULES[4-i][4-j] = 4 - RULES[i][j]
    rng = np.random.default_rng(0)
    for inference in ("product", "min"):
        f = FuzzyPD(inference=inference, e_inner=0.4, de_inner=0.6)
        for e, de in rng.uniform(-1.5, 1.5, size=(500, 2)):
            assert f.surface(-e, -de) == pytest.approx(-f.surface(e, de), abs=1e-15)


def test_small_signals_give_the_linear_pd_of_the_scaling_gains():
    """Uniform sets, product inference: F = E + DE in the central square, so u = Kp e + Kd de
    with Kp = u_scale/e_scale, Kd = u_scale/de_scale; large inputs saturate at +-u_scale."""
    f = FuzzyPD(e_scale=10.0, de_scale=800.0, u_scale=2.0)
    rng = np.random.default_rng(1)
    for e, de in rng.uniform(-0.5, 0.5, size=(200, 2)):
        assert f.surface(e, de) == pytest.approx(e + de, abs=1e-12)
    f.reset()
    assert f(0.0, {"tip_sensor": 3.0}) == {"voltage_cmd": pytest.approx(0.2 * 3.0)}  # first call: de = 0
    u = f(0.001, {"tip_sensor": 2.8})["voltage_cmd"]  # de = -200 V/s
    assert u == pytest.approx(0.2 * 2.8 + 2.0 / 800.0 * -200.0)
    assert f(0.002, {"tip_sensor": 50.0})["voltage_cmd"] == pytest.approx(2.0)  # shoulders: +u_scale
    f.reset()
    assert f(0.0, {"tip_sensor": 1.0})["voltage_cmd"] == pytest.approx(0.2)  # reset forgets e(k-1)


def test_registered_and_bad_arguments_rejected():
    assert CONTROLLERS["fuzzy_pd"] is FuzzyPD
    with pytest.raises(ValueError, match="inference"):
        FuzzyPD(inference="max")
    with pytest.raises(ValueError, match="e_inner"):
        FuzzyPD(e_inner=1.0)
    with pytest.raises(ValueError, match="5x5"):
        FuzzyPD(rules=[[2] * 5] * 4)
    with pytest.raises(ConfigError, match="fuzzy_pd"):
        run_scenario("laser_arm_fuzzy_step", controller__gain=1.0)


@pytest.mark.parametrize("noise", [False, True])
def test_nominal_step_settles_with_zero_steady_state_error(noise):
    """laser_arm_fuzzy_step (0.7 kg, 2.5 mm): settles into 2 % and stays; the mean tip error
    over the last 0.3 s is below 1 um (noise off) or 5 um = 0.017 V (noise on; the sensor's
    noise is 0.01 V rms per sample)."""
    rec = run_scenario("laser_arm_fuzzy_step", noise=noise)
    ch, L = rec.channels, LASER_ARM.beam.length
    tip = L * ch["reference"] - ch["tip_sensor"] / LASER_ARM.sensor_gain  # m along the arc
    target = L * ch["reference"][-1]
    assert target == pytest.approx(0.0025)
    m = step_metrics(rec.time, tip, t_step=0.1, initial=0.0, final=target)
    assert m["settling_time_s"] < 0.3 and m["overshoot_pct"] < 10.0
    tail = rec.time >= rec.time[-1] - 0.3
    assert abs(np.mean(target - tip[tail])) < (5e-6 if noise else 1e-6)
    assert np.max(np.abs(rec.channels["voltage_cmd"])) <= 2.0 + 1e-12  # within +-u_scale
