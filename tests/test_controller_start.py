"""A controller's state at a recording's first sample (an observer's estimate, a PID's integral) identified from the
commands the recording holds (resim._controller_start): where a recording starts mid-run, the warm-up on the past the
start implies (engine.warm_up) leaves such a state off, and the re-simulation is off by about its whole response."""
import math

import numpy as np
import pytest

import watflex_sim.resim as resim
from controllers.observer import Observer
from controllers.pid import PID
from watflex_sim.diagnosis.data import prepare
from watflex_sim.diagnosis.experiment import _variant
from watflex_sim.engine import simulate
from watflex_sim.metrics import nrmse
from watflex_sim.model import ConfigError
from watflex_sim.recording import Recording
from watflex_sim.scenario import check, load_scenario

ELBOW_PID = dict(type="pid", command="elbow_torque_cmd", position="elbow_angle", reference="elbow_reference",
                 kp=60.0, ki=150.0, kd=12.0, rate_hz=10.0)  # N m/rad, N m/(rad s), N m s/rad; Hz


def _cut(rec: Recording, t0: float) -> Recording:
    """`rec` from t0 (s) on: a logger started late."""
    keep = rec.time >= t0 - 1e-9
    return Recording(rec.time[keep], {c: v[keep] for c, v in rec.channels.items()}, rec.meta)


def _worst(rec: Recording, again: Recording) -> float:
    """The largest NRMSE over the recording's measured and command channels that vary (camera frames where both have
    them)."""
    return max(float(nrmse(x, again.channels[c])) for c, x in rec.channels.items()
               if "reference" not in c and np.nanstd(x) > 0 and not c.startswith("tip_"))


def _observer_two_joint() -> Recording:
    return simulate(load_scenario("watflex_observer_two_joint", ["duration_s=2.0", "noise=false"])).recording


def _elbow_pid() -> Recording:
    scenario = load_scenario("watflex_elbow_step", ["duration_s=3.0", "noise=false"])
    return simulate(check(scenario | {"controller": ELBOW_PID})).recording


@pytest.mark.parametrize("make, t0, bound", [(_observer_two_joint, 1.1, 0.05), (_elbow_pid, 1.0, 0.01),
                                            (_elbow_pid, 2.0, 0.01)], ids=["observer 1.1 s", "pid 1.0 s", "pid 2.0 s"])
def test_a_controllers_state_is_taken_from_the_recordings_first_commands(make, t0, bound, monkeypatch):
    """Noise-off runs cut mid-run, re-simulated on the same model: every channel within `bound` (measured: the two-joint
    observer cut at 1.1 s 0.0036-0.018; cut at 1.3 s, its fitted estimate was the full run's within 1e-3 rad and rad/s;
    the elbow PID with an integral 0.0004-0.001 cut at 1.0 s, 0.0006-0.0022 at 2.0 s); without the state (the warm-up
    only, as before) some channel is off by more than 0.5 of its spread (measured 1.28, 1.15 and 1.00)."""
    rec = _cut(make(), t0)
    assert resim.scenario_from_recording(rec)["controller_state"]
    assert _worst(rec, resim.resimulate(rec)) < bound
    monkeypatch.setattr(resim, "STATE_TOLERANCE", math.inf)
    monkeypatch.setattr(resim, "_STARTS", resim.Latest(4))
    assert not resim.scenario_from_recording(rec)["controller_state"]
    assert _worst(rec, resim.resimulate(rec)) > 0.5


def test_an_arm_held_still_by_friction_starts_bent_and_its_integral_charged():
    """The elbow PID with a slow integral (ki 20 N m/(rad s)), noise on, stuck by the harmonic drive's friction 3 s
    in and cut there: it starts at rest, link 2 bent as its bridges read (a load held: they read beyond any offset)
    and the integral as the commands say (measured NRMSE: angle 0.054, torque 0.22, strains 0.40, the friction's
    stick-slip left; at rest with links straight and the integral empty, as before, 0.72, 1.48 and 1.25). An experiment
    the diagnosis proposes from it starts at the joints' readings, links straight, its controller reset."""
    scenario = load_scenario("watflex_elbow_step", ["duration_s=6.0"])
    rec = _cut(simulate(check(scenario | {"controller": dict(ELBOW_PID, ki=20.0)})).recording, 3.0)
    start = resim.scenario_from_recording(rec)
    assert not start["initial_rate"] and {"strain_2A", "strain_2B"} <= set(start["initial"])
    assert start["controller_state"]
    again = resim.resimulate(rec)
    assert max(nrmse(rec.channels[c], again.channels[c]) for c in ("elbow_angle", "elbow_torque_cmd")) < 0.3
    assert _worst(rec, again) < 0.6
    encoders = {c: v for c, v in start["initial"].items() if c.endswith("_angle")}
    before = dict(start, initial=encoders, controller_state={})
    assert _worst(rec, simulate(check(before)).recording) > 1.0
    proposed = _variant(prepare([rec], ["held.csv"]), 0, 2.0, 1.0)  # what the rig would run: straight, reset
    assert set(proposed["initial"]) == set(encoders) and proposed["controller_state"] == {}


def test_a_recording_from_the_controllers_start_sets_no_state():
    """A run recorded from its controller's reset, noise on, the observer's reference stepping 0.2 rad at the first
    sample: its replayed first commands repeat the recorded ones but for the converter's 12-bit steps (measured rms
    0.0013 of the command's spread; 0.005 for a 0.05 rad step), within STATE_TOLERANCE, so the re-simulation starts it
    reset."""
    scenario = load_scenario("watflex_observer_step", ["duration_s=1.0"])
    scenario["reference"][0].update(levels=[0.2, 0.0], times_s=[0.0, 10.0])  # rad, s
    rec = simulate(check(scenario)).recording
    assert np.nanstd(rec.channels["elbow_torque_cmd"][:20]) > 0.01 * np.nanstd(rec.channels["elbow_torque_cmd"])
    assert resim.scenario_from_recording(rec)["controller_state"] == {}


def test_an_observer_reports_and_takes_its_state():
    observer = Observer(joints=("shoulder", "elbow"))
    assert observer.state() == {}  # before its first step: it starts at rest at its first encoder reading
    observer(0.0, {"shoulder_angle": 0.1, "shoulder_reference": 0.2, "elbow_angle": -0.1, "elbow_reference": 0.0})
    state = observer.state()
    assert set(state) == {f"{j}_{n}" for j in ("shoulder", "elbow")
                          for n in ("theta_m", "theta_a", "rate_m", "rate_a", "torque")}
    moved = {name: value + 0.01 for name, value in state.items()}
    observer.set_state(moved)
    assert observer.state() == pytest.approx(moved)
    with pytest.raises(ValueError, match="name no joint"):
        observer.set_state({"wrist_theta_m": 0.0})
    with pytest.raises(ValueError, match="needs"):
        observer.set_state({"elbow_theta_m": 0.0})


def test_a_pid_has_a_state_only_with_an_integral():
    assert PID("u", "q", "r", kp=1.0).state() == {}
    pid = PID("u", "q", "r", kp=1.0, ki=2.0)
    pid.set_state({"integral": 0.3})
    assert pid.state() == {"integral": 0.3}
    with pytest.raises(ValueError, match="pid state"):
        PID("u", "q", "r", kp=1.0).set_state({"integral": 0.3})


@pytest.mark.parametrize("state, message", [({"elbow_theta_m": math.nan}, "finite number"),
                                            ({"wrist_theta_m": 0.0}, "name no joint")])
def test_a_bad_controller_state_is_a_one_line_error(state, message):
    scenario = load_scenario("watflex_observer_step", ["duration_s=0.01"])
    with pytest.raises(ConfigError, match=message):
        simulate(check(scenario | {"controller_state": state}))


def test_a_controller_without_state_refuses_one():
    scenario = load_scenario("watflex_elbow_step", ["duration_s=0.01"])
    with pytest.raises(ConfigError, match="no state to set"):
        simulate(check(scenario | {"controller_state": {"integral": 0.0}}))
