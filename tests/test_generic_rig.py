"""A rig from data alone (issue 15 items 3-5): generic sensors, controllers as data, the rig's
own sample period, and a run that starts where its recording starts.

Expected numbers are worked out by hand in each test from the definitions in rigs.GenericRig
(tip deflection = sum q_i (L - x_i), the static tip-load strain 3 t w (L - x) / (2 L^3)).
"""
import math

import mujoco
import pytest

from watflex_sim.controllers import CONTROLLERS
from watflex_sim.controllers.pid import PID
from watflex_sim.controllers.state_feedback import RateFilter, StateFeedback
from watflex_sim.model import ConfigError
from watflex_sim.rigdesc import _check
from watflex_sim.rigs import GenericRig

# a hub and a two-hinge link along x: hinges at x = 0.1 and 0.3 m from the hub, link length 0.4 m
XML = """
<mujoco><option timestep="0.0005"/><worldbody>
  <body name="hub"><joint name="drive" axis="0 0 1"/><geom size="0.02" mass="0.1" contype="0" conaffinity="0"/>
    <body name="s1" pos="0.1 0 0"><joint name="link_j01" axis="0 0 1" stiffness="50"/>
      <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.005" mass="0.05" contype="0" conaffinity="0"/>
      <body name="s2" pos="0.2 0 0"><joint name="link_j02" axis="0 0 1" stiffness="50"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.005" mass="0.05" contype="0" conaffinity="0"/>
      </body></body></body></worldbody>
<actuator><general name="motor" joint="drive"/></actuator><keyframe><key name="home"/></keyframe></mujoco>
"""
LINK = {"link": "link", "length": 0.4}


@pytest.fixture(autouse=True)
def _model_in_memory(monkeypatch):
    """These rig tables name a model built here from XML, not a file: skip the model-file check."""
    monkeypatch.setattr("watflex_sim.rigdesc._check_model", lambda description, fail: None)


def rig_raw(**channels):
    return {"name": "toy", "model": "toy", "sensors": "generic", "channels": {
        "ref": {"unit": "rad", "kind": "reference"},
        "u": {"unit": "A", "kind": "command", "actuator": "motor", "gain": 2.0, "limit": 1.0, "bits": 4},
        **channels}}


def make(**channels):
    description = _check(rig_raw(**channels), "toy.toml")
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return GenericRig(model, data, description, noise=False, seed=0), data


def test_sensors_read_joint_link_and_strain_with_scale_offset_and_steps():
    rig, data = make(
        angle={"unit": "deg", "kind": "measured", "joint": "drive", "scale": -180 / math.pi, "offset": 1.0},
        speed={"unit": "rad/s", "kind": "measured", "joint": "drive", "quantity": "velocity", "step": 0.01},
        tip={"unit": "m", "kind": "measured", "quantity": "deflection", **LINK},
        bend={"unit": "rad", "kind": "measured", "quantity": "deflection_angle", **LINK},
        gauge={"unit": "-", "kind": "measured", "quantity": "strain", "x": 0.1, "thickness": 0.002, **LINK},
    )
    data.qpos[:] = [0.2, 0.01, 0.03]
    data.qvel[:] = [0.123, 0, 0]
    obs = rig.observe({"ref": 0.5})
    w = 0.01 * (0.4 - 0.0) + 0.03 * (0.4 - 0.2)  # m: hinge 1 at the link's root (its first hinge), hinge 2 0.2 m on
    assert obs["ref"] == 0.5
    assert obs["angle"] == pytest.approx(-0.2 * 180 / math.pi + 1.0, rel=1e-12)
    assert obs["speed"] == pytest.approx(0.12, abs=1e-12)  # quantised to 0.01
    assert obs["tip"] == pytest.approx(w, rel=1e-9)
    assert obs["bend"] == pytest.approx(w / 0.4, rel=1e-9)
    assert obs["gauge"] == pytest.approx(3 * 0.002 * w * (0.4 - 0.1) / (2 * 0.4**3), rel=1e-9)


def test_command_saturates_quantises_and_scales():
    rig, data = make(angle={"unit": "rad", "kind": "measured", "joint": "drive"})
    assert rig.actuate({"u": 5.0}) == {"u": 1.0} and data.ctrl[0] == 2.0  # limit 1 A, gain 2 N m/A
    out = rig.actuate({"u": 0.3})  # 4 bits over +-1 A: steps of 0.125 A
    assert out["u"] == 0.25 and data.ctrl[0] == 0.5


def test_start_at_puts_the_rig_where_the_sensors_read_the_first_samples():
    rig, data = make(
        angle={"unit": "deg", "kind": "measured", "joint": "drive", "scale": 180 / math.pi},
        speed={"unit": "rad/s", "kind": "measured", "joint": "drive", "quantity": "velocity"},
        bend={"unit": "rad", "kind": "measured", "quantity": "deflection_angle", "scale": -1.0, **LINK},
    )
    first = {"angle": 12.0, "speed": -0.4, "bend": 0.02}
    rig.start_at(first)
    obs = rig.observe({})
    for c, v in first.items():
        assert obs[c] == pytest.approx(v, rel=1e-12)
    # the link is bent in the tip-load shape: hinge angles in proportion to their lever arms (0.4, 0.2)
    assert data.qpos[1] / data.qpos[2] == pytest.approx(0.4 / 0.2, rel=1e-9)


@pytest.mark.parametrize("channel, why", [
    ({"unit": "rad", "kind": "measured", "joint": "drive", "sign": -1}, "unknown key(s) sign"),
    ({"unit": "rad", "kind": "measured", "joint": "drive", "quantity": "speed"}, "quantity must be one of"),
    ({"unit": "-", "kind": "measured", "link": "link", "quantity": "strain", "length": 0.4}, "needs the link's thickness"),
    ({"unit": "rad", "kind": "measured", "quantity": "deflection_angle"}, "needs a joint"),
    ({"unit": "rad", "kind": "measured", "joint": "drive", "scale": 0}, "scale must not be 0"),
    ({"unit": "rad", "kind": "measured", "link": "link", "length": 0.4}, "quantity 'position' needs a joint"),
    ({"unit": "rad", "kind": "measured", "joint": "drive", "step": -1e-3}, "step must be >= 0"),
])
def test_bad_channel_is_one_line_naming_file_and_channel(channel, why):
    with pytest.raises(ConfigError) as err:
        _check(rig_raw(bad=channel), "toy.toml")
    message = str(err.value)
    assert message.startswith("toy.toml: channel 'bad'") and why in message and "\n" not in message


def test_control_period_must_be_whole_engine_ticks():
    with pytest.raises(ConfigError, match="control_period_s must be a whole multiple"):
        _check({**rig_raw(), "control_period_s": 0.0015}, "toy.toml")
    assert _check({**rig_raw(), "control_period_s": 0.002}, "toy.toml").control_period_s == 0.002


@pytest.mark.parametrize("method", RateFilter.METHODS)
def test_rate_filter_follows_a_ramp(method):
    """On x = 3 t every discretisation of s wn^2 / (s^2 + 2 zeta wn s + wn^2) settles at 3 (units/s)."""
    f = RateFilter(40.0, 0.9, 0.002, method)
    rates = [f(3.0 * k * 0.002) for k in range(500)]
    assert rates[0] == 0.0 and rates[-1] == pytest.approx(3.0, rel=1e-6)


def test_state_feedback_is_k_times_the_error_and_checks_its_tables():
    assert CONTROLLERS["state_feedback"] is StateFeedback and CONTROLLERS["pid"] is PID
    law = StateFeedback(commands=["u"], states=["q", "d", "rate:q"], gains=[[10.0, -4.0, 0.5]],
                        references={"q": "ref"}, limits=[1.5], period=0.002)
    law.reset()
    assert law(0.0, {"q": 0.1, "d": 0.02, "ref": 0.15})["u"] == pytest.approx(10 * 0.05 + 4 * 0.02)  # rate 0 at first
    u = law(0.002, {"q": 0.102, "d": 0.02, "ref": 0.15})["u"]  # rate (0.002 / 0.002 s) = 1 rad/s, plain difference
    assert u == pytest.approx(10 * 0.048 + 4 * 0.02 - 0.5 * 1.0)
    assert law(0.004, {"q": -1.0, "d": 0.0, "ref": 0.15})["u"] == 1.5  # limit
    with pytest.raises(ValueError, match="gains must be 1 row"):
        StateFeedback(commands=["u"], states=["q"], gains=[[1.0, 2.0]])
    with pytest.raises(ValueError, match="not in states"):
        StateFeedback(commands=["u"], states=["q"], gains=[[1.0]], references={"x": "ref"})


def test_pid_integrates_saturates_and_stops_winding_up():
    pid = PID(command="u", position="q", reference="r", kp=2.0, ki=10.0, limit=1.0, period=0.01)
    pid.reset()
    assert pid(0, {"q": 0.0, "r": 0.1})["u"] == pytest.approx(0.2)  # integral starts at 0, then holds 0.1 x 0.01
    assert pid(0, {"q": 0.0, "r": 0.1})["u"] == pytest.approx(0.2 + 10 * 0.001)
    for _ in range(5):
        assert pid(0, {"q": 0.0, "r": 10.0})["u"] == 1.0  # saturated: the integral is frozen
    assert pid.integral == pytest.approx(0.002)


def test_sensor_filters_first_and_second_order():
    """1st order at f: y1 = a x with a = 1 - exp(-2 pi f T) for a unit step from rest at 0;
    2nd order (Tustin, zeta) settles at the step with unit gain."""
    rig, data = make(
        one={"unit": "rad", "kind": "measured", "joint": "drive", "filter_hz": 5.0},
        two={"unit": "rad", "kind": "measured", "joint": "drive", "filter_hz": 5.0, "filter_zeta": 0.9},
    )
    rig.observe({})  # at rest at 0
    data.qpos[0] = 1.0
    first = rig.observe({})
    assert first["one"] == pytest.approx(1 - math.exp(-2 * math.pi * 5.0 * 1e-3), rel=1e-12)  # the rig's 1 ms period
    for _ in range(2000):
        last = rig.observe({})
    assert last["one"] == pytest.approx(1.0, abs=1e-9) and last["two"] == pytest.approx(1.0, abs=1e-6)


def test_a_rig_with_its_own_sensor_model_runs_at_1_ms_only():
    from watflex_sim import load_scenario, simulate

    with pytest.raises(ConfigError, match="runs at 1 ms only"):
        simulate(load_scenario("laser_arm_step", ["control_period_s=0.002", "duration_s=0.01"]))
