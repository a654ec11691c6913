"""Controllers, filters and reference signals against their definitions."""
import numpy as np
import pytest
from scipy import signal

from watflex_sim.controllers import PDJoint, PDTip
from watflex_sim.controllers.filters import Butterworth2
from watflex_sim.model import ConfigError
from watflex_sim.params import WATFLEX
from watflex_sim.scenario import load_scenario
from watflex_sim.signals import make_signal


def test_butterworth_matches_scipy_lfilter():
    """Per-sample filter = scipy.signal.lfilter with butter(2, 10 Hz, fs=1 kHz), to 1e-12."""
    rng = np.random.default_rng(0)
    x = rng.standard_normal(2000)
    f = Butterworth2(10.0, 1000.0)
    b, a = signal.butter(2, 10.0, fs=1000.0)
    zi = signal.lfilter_zi(b, a) * x[0]
    expected, _ = signal.lfilter(b, a, x, zi=zi)
    assert np.allclose([f(v) for v in x], expected, atol=1e-12)


def test_pd_tip_is_rigs_md_law():
    """u = Kp e + Kd (e_k - e_{k-1}) / T (rigs.md §1), derivative 0 on the first sample."""
    c = PDTip(kp=0.5, kd=0.01)
    assert c(0.0, {"tip_sensor": 2.0}) == {"voltage_cmd": 1.0}
    assert c(0.001, {"tip_sensor": 3.0})["voltage_cmd"] == pytest.approx(0.5 * 3 + 0.01 * 1.0 / 0.001)
    c.reset()
    assert c(0.0, {"tip_sensor": 3.0})["voltage_cmd"] == pytest.approx(1.5)


def test_pd_joint_on_a_ramp_reaches_kd_times_slope():
    """A ramp of 1 rad/s: the filtered difference tends to 1 rad/s, so tau -> Kp e - Kd * 1."""
    c = PDJoint(joints=["elbow"], kp=[60.0], kd=[12.0])
    for k in range(1000):
        tau = c(k * 1e-3, {"elbow_angle": k * 1e-3, "elbow_reference": k * 1e-3})["elbow_torque_cmd"]
    assert tau == pytest.approx(-12.0, rel=1e-3)


def test_staircase_and_step_signals():
    stairs = make_signal({"kind": "staircase", "levels": [0.1, 0.2, 0.1, 0.0], "times_s": [2, 4, 6, 8]})
    assert [stairs(t) for t in (0, 1.999, 2, 5, 6.5, 9)] == [0, 0, 0.1, 0.2, 0.1, 0.0]
    step = make_signal({"kind": "step", "amplitude": 0.5, "time_s": 0.5}, sign=-1)
    assert (step(0.499), step(0.5)) == (0.0, -0.5)


def test_a_signals_table_gives_its_own_values():
    """`f.table(times)` (engine.ControlLoop tabulates references with it) is the same numbers as f at each time,
    to the last bit, for every kind that has one."""
    times = np.arange(0, 10, 1e-3)
    for spec in ({"kind": "step", "amplitude": 0.5, "time_s": 0.5}, {"kind": "constant", "value": -0.3},
                 {"kind": "staircase", "levels": [0.1, 0.2, 0.1, 0.0], "times_s": [2, 4, 6, 8]},
                 {"kind": "samples", "time_s": [0.0, 1.0, 2.5], "values": [1.0, float("nan"), -2.0]}):
        f = make_signal(spec, sign=-1, scale=1.7)
        assert np.array_equal(f.table(times), [f(t) for t in times.tolist()]), spec["kind"]


def test_triangle_is_rigs_md_sub_breakaway_input():
    """rigs.md §2: amplitude 0.75 alpha0+ and slope 2.4 N m/s, 4 periods, then zero."""
    sc = load_scenario("watflex_elbow_triangle")
    spec = sc["command"][0]
    assert spec["amplitude"] == pytest.approx(0.75 * WATFLEX.elbow_friction[0].alpha0, rel=1e-3)
    tri = make_signal(spec)
    quarter = spec["amplitude"] / 2.4
    t = np.arange(0, 4 * 4 * quarter, 1e-3)
    y = np.array([tri(v) for v in t])
    assert y.max() == pytest.approx(spec["amplitude"], rel=1e-3) and y.min() == pytest.approx(-spec["amplitude"], rel=1e-3)
    assert np.abs(np.diff(y) / 1e-3).max() == pytest.approx(2.4, rel=1e-6)
    assert sc["duration_s"] == pytest.approx(4 * 4 * quarter, abs=0.01)  # file rounds to 10 ms
    assert tri(4 * 4 * quarter + 0.01) == 0.0


def test_signal_errors_are_config_errors():
    with pytest.raises(ConfigError, match="unknown signal kind 'sine'"):
        make_signal({"kind": "sine"})
    with pytest.raises(ConfigError, match="'times_s' must increase"):
        make_signal({"kind": "staircase", "levels": [1, 2], "times_s": [2, 1]})
