"""Recordings that start away from the nominal pose (the arm not stretched along +x, the laser arm's hub
turned): a scenario's `initial` starts the laser arm and the Watflex at their encoders' values, at rest with
the links straight, and a re-simulation starts where its recording starts. An independent simulator of
rigs.md may run the thesis' passivity move from rest at (1.1, 0.4) m, a real rig's encoders read wherever
the arm was left; re-simulated from the stretched pose, such a recording is off by the whole move.
"""
import copy

import numpy as np
import pytest

from watflex_sim.engine import ControlLoop, simulate
from watflex_sim.lockstep import simulate_batch
from watflex_sim.metrics import nrmse
from watflex_sim.model import ConfigError
from watflex_sim.params import LASER_ARM, WATFLEX
from watflex_sim.resim import resimulate
from watflex_sim.scenario import check, load_scenario


def _on_counts(angle: float, step: float) -> float:
    """The encoder reading nearest `angle` (rad): a run started there is re-simulated from the same state."""
    return float(round(angle / step) * step)


def _two_joint(start: tuple[float, float], move: tuple[float, float], locked: bool = False) -> dict:
    """Observer control of both joints (or the elbow alone, shoulder locked) from `start` (rad), steps of
    `move` (rad) at 0.2 s, 0.8 s long, noise off."""
    sc = copy.deepcopy(load_scenario("watflex_observer_two_joint"))
    s = [_on_counts(a, WATFLEX.encoder_step) for a in start]
    names = ("shoulder", "elbow")
    sc["reference"] = [dict(channel=f"{j}_reference", kind="staircase", levels=[a, a + m], times_s=[0.0, 0.2])
                       for j, a, m in zip(names, s, move)]
    sc["initial"] = {f"{j}_angle": a for j, a in zip(names, s)}
    if locked:  # the single-link set-up: the elbow's observer alone
        sc["locked_joints"] = {"shoulder": 0.0}
        sc["reference"], sc["initial"] = sc["reference"][1:], {"elbow_angle": s[1]}
        sc["controller"] = {k: (v[1:] if isinstance(v, list) else v) for k, v in sc["controller"].items()}
    return check(sc | {"duration_s": 0.8, "noise": False})


def _laser(start: float) -> dict:
    """The laser arm's tip PD from the hub at `start` (rad), a 2.5 mm step of the spot at 0.1 s, 0.5 s."""
    sc = copy.deepcopy(load_scenario("laser_arm_step"))
    s = _on_counts(start, LASER_ARM.encoder_step)
    step = 0.0025 / LASER_ARM.beam.length  # rad
    sc["reference"] = [dict(channel="reference", kind="staircase", levels=[s, s + step], times_s=[0.0, 0.1])]
    return check(sc | {"initial": {"hub_angle": s}, "duration_s": 0.5, "noise": False})


ENCODERS = ("shoulder_angle", "elbow_angle", "hub_angle")
CASES = {
    "watflex, both joints": lambda: _two_joint((0.3, -0.5), (-0.4, 0.8)),
    "watflex, single-link set-up": lambda: _two_joint((0.0, 0.7), (0.0, -0.5), locked=True),
    "laser arm": lambda: _laser(0.2),
}


@pytest.mark.parametrize("case", CASES)
def test_a_recording_that_starts_away_from_the_nominal_pose_is_resimulated_from_there(case):
    """The recording of a run started at a pose, re-simulated from its own first samples (resim), gives every
    channel back bit for bit (the same physics from the same state; start angles on encoder counts, else the
    re-simulation starts up to half a count away; each further from 0 than an offset would be, 0.5 x its channel's
    spread: resim._away_from_nominal). Started from the nominal pose instead (as before), its angles
    are off by about the whole start pose: NRMSE > 0.3 on every encoder (measured 1.05-203)."""
    rec = simulate(CASES[case]()).recording
    again = resimulate(rec)
    for c, x in rec.channels.items():
        y, ok = again.channels[c], np.isfinite(x)
        assert np.array_equal(ok, np.isfinite(y)), c
        assert np.array_equal(x[ok], y[ok]), c
    nominal = resimulate(_started_at_nominal(rec))
    for c in (c for c in ENCODERS if c in rec.channels and np.ptp(rec.channels[c])):
        assert nrmse(rec.channels[c], nominal.channels[c]) > 0.3, c


def _started_at_nominal(rec):
    """`rec` with its encoders' first samples at 0: its re-simulation starts at the nominal pose."""
    out = copy.deepcopy(rec)
    for c in ENCODERS:
        if c in out.channels:
            out.channels[c][0] = 0.0
    return out


def test_a_watflex_run_started_at_a_pose_rests_there_with_its_tip_where_rigid_kinematics_puts_it():
    """At rest at (0.3, -0.5) rad with the references there, the observer holds the arm (angles exactly the
    start for 0.8 s) and the camera sees the end effector where the straight arm's pose rotated puts it:
    tip = R(theta1) (e + R(theta2) (t0 - e)), e the elbow's and t0 the tip's place at the nominal pose (the
    nominal run's own first frame), within 1e-6 m (the links bend under no load: the air bearings carry them)."""
    still = _two_joint((0.3, -0.5), (0.0, 0.0))
    rec = simulate(still).recording
    th1, th2 = still["initial"]["shoulder_angle"], still["initial"]["elbow_angle"]
    assert np.all(rec.channels["shoulder_angle"] == th1) and np.all(rec.channels["elbow_angle"] == th2)
    straight = ControlLoop(_two_joint((0.0, 0.0), (0.0, 0.0)))
    model, data = straight.model, straight.data
    e, t0 = data.xanchor[model.joint("elbow").id][:2], data.site_xpos[model.site("tip").id][:2]

    def rot(a):
        return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])

    expected = rot(th1) @ (e + rot(th2) @ (t0 - e))
    np.testing.assert_allclose([rec.channels["tip_x"][0], rec.channels["tip_y"][0]], expected, atol=1e-6)


def test_a_start_from_a_channel_the_rig_cannot_start_from_is_bad_input():
    """The Watflex starts from its encoders and strain bridges: its camera is refused with a one-line error naming
    what it starts from."""
    sc = _two_joint((0.3, -0.5), (0.0, 0.0))
    sc["initial"]["tip_x"] = 0.1
    with pytest.raises(ConfigError, match="cannot start from tip_x .*shoulder_angle, elbow_angle, strain_1A"):
        simulate(sc)


def test_runs_started_at_their_own_poses_in_lockstep_match_their_single_runs():
    """lockstep.simulate_batch (the diagnosis' re-simulations): members set up at different poses, one at the
    nominal pose among them, give their single runs' recordings bit for bit."""
    scenarios = [_two_joint((0.3, -0.5), (-0.4, 0.8)), _two_joint((-0.2, 0.9), (0.3, -0.6)),
                 _two_joint((0.0, 0.0), (0.2, 0.2))]
    for scenario, result in zip(scenarios, simulate_batch(scenarios, nthread=2, always=True)):
        single = simulate(scenario).recording
        for c, x in single.channels.items():
            assert np.array_equal(x, result.recording.channels[c], equal_nan=True), c


def test_an_encoder_offset_is_seen_from_the_nominal_pose_and_inverted_away_from_it():
    """An elbow encoder that reads 0.012 rad high (sensor_offset), single-link elbow steps. From the nominal pose (as
    a rig is started, the benchmark's cases): the reading is within an offset the diagnosis fits (0.5 x the channel's
    spread) of the pose, so the re-simulation starts at the pose, without the offset in the model reads 0.012 rad
    less throughout the rest before the step, and with it gives every channel back bit for bit. From a pose 0.6 rad
    away: the run starts at the reading less the offset, and the re-simulation with the offset gives the recording back
    bit for bit; without it, it starts 0.012 rad about the elbow away, and the camera's first frame sees that (> 8 mm;
    noise off)."""
    offset = [{"effect": "sensor_offset", "where": "elbow_angle", "offset": 0.012}]
    step = load_scenario("watflex_elbow_step", ["duration_s=0.8", "noise=false"]) | {"effects": offset}
    rec = simulate(step).recording
    assert rec.channels["elbow_angle"][0] == 0.012
    for c, x in rec.channels.items():
        assert np.array_equal(x, resimulate(rec, offset).channels[c], equal_nan=True), c
    before_step = rec.time < 0.5  # s
    assert np.allclose(rec.channels["elbow_angle"][before_step] - resimulate(rec).channels["elbow_angle"][before_step],
                       0.012, atol=WATFLEX.encoder_step)
    start = _on_counts(0.6 - 0.012, WATFLEX.encoder_step) + 0.012  # rad: the reading at the start
    posed = step | {"initial": {"elbow_angle": start}, "reference": [dict(
        channel="elbow_reference", kind="staircase", levels=[start, start - 0.5], times_s=[0.0, 0.5])]}
    rec = simulate(check(posed)).recording
    for c, x in rec.channels.items():
        assert np.array_equal(x, resimulate(rec, offset).channels[c], equal_nan=True), c
    nominal = resimulate(rec)
    assert np.hypot(*(nominal.channels[c][0] - rec.channels[c][0] for c in ("tip_x", "tip_y"))) > 8e-3
