"""Recordings that start moving (a logger started late, a long run cut into files): a re-simulation starts at the
values and rates a parabola through each start sensor's first 20 ms gives (resim._start), the laser arm's beam and
the Watflex's links bent as their tip sensor and strain bridges read. Started at rest instead, as before, such a
recording is off by about its whole response (a clean laser case cut 0.15 s into a step was diagnosed `unexplained`,
26.5 x the noise; docs/diagnosis.md, "A recording that starts moving").
"""
from pathlib import Path

import numpy as np
import pytest

from watflex_sim.engine import simulate
from watflex_sim.metrics import nrmse
from watflex_sim.recording import Recording
from watflex_sim.resim import _moving, _start, resimulate, scenario_from_recording
from watflex_sim.rigdesc import load_rig
from watflex_sim.scenario import check, load_scenario

ROTFLEX = Path(__file__).parents[1] / "examples" / "rotary_flexible_link"


def _cut(rec: Recording, t0: float) -> Recording:
    """`rec` from t0 (s) on: a logger started late."""
    keep = rec.time >= t0 - 1e-9
    return Recording(rec.time[keep], {c: v[keep] for c, v in rec.channels.items()}, rec.meta)


def _at_rest(rec: Recording, channels) -> Recording:
    """`rec` with `channels`' first 40 samples held at their first value: its re-simulation starts at rest there."""
    out = Recording(rec.time, {c: v.copy() for c, v in rec.channels.items()}, rec.meta)
    for c in channels:
        out.channels[c][1:40] = out.channels[c][0]
    return out


LASER, ELBOW = ("hub_angle", "tip_sensor"), ("elbow_angle", "strain_2A", "strain_2B")
CUTS = {  # scenario, where it is cut (s), the channels that say it moves, the largest NRMSE from a moving start
    "laser arm, 0.15 s into a 2.5 mm step": ("laser_arm_step", 0.15, LASER, 0.1),
    "laser arm, 0.3 s: the hub nearly still, the beam swinging": ("laser_arm_step", 0.3, LASER, 0.15),
    "watflex single-link, 0.8 s: the elbow mid-step": ("watflex_elbow_step", 0.8, ELBOW, 0.03),
    "a rig described as data (rotary flexible link), 2.034 s: the hub at its fastest":
        (str(ROTFLEX / "steps_with_friction.toml"), 2.034, ("hub", "link"), 0.2),
}


def _run(name: str):
    """(recording of scenario `name` noise off for 2 s (3 s for the rotary link, stepping at 2 s), its rig)."""
    if name.endswith(".toml"):  # the rotary flexible link, its friction left out
        rig = load_rig(str(ROTFLEX / "rig.toml"))
        return simulate(check(load_scenario(name, ["noise=false", "duration_s=3.0"]) | {"effects": []}), rig=rig), rig
    return simulate(load_scenario(name, ["duration_s=2.0", "noise=false"])), None


@pytest.mark.parametrize("case", CUTS)
def test_a_recording_that_starts_moving_is_resimulated_from_its_moving_start(case, monkeypatch):
    """A noise-off run cut mid-move, re-simulated on the same model: every channel within the NRMSE the case
    allows (measured 0.035-0.071 cut at 0.15 s, 0.025-0.11 at 0.3 s, 0.0046-0.0099 for the Watflex, 0.0063-0.13 for
    the rotary link: the rates from 20 ms of quantised samples, the links in their static tip-load shape, the
    Watflex's with a tip moment too (link 2 with a tip force alone: 0.012-0.043); the Watflex's torque command
    0.0995 and the rotary link's voltage 0.37 without the controller warmed up on the past, engine.warm_up,
    0.025 and 0.11 with that past on a line rather than a parabola); started at rest at the same readings (before),
    some channel is off by more than 0.7 of its spread (measured 0.75-1.76)."""
    name, t0, movers, allowed = CUTS[case]
    monkeypatch.setenv("WATFLEX_RIGS", str(ROTFLEX))  # where the rotary link's scenario finds its rig by name
    result, rig = _run(name)
    rec = _cut(result.recording, t0)
    assert scenario_from_recording(rec, rig)["initial_rate"], "the cut recording starts moving"
    again = resimulate(rec, rig=rig)
    measured = [c for c, x in rec.channels.items() if np.nanstd(x) > 0 and "reference" not in c]
    for c in measured:
        assert nrmse(rec.channels[c], again.channels[c]) < allowed, c
    resting = _at_rest(rec, movers)
    assert not scenario_from_recording(resting, rig)["initial_rate"]
    from_rest = resimulate(resting, rig=rig)
    assert max(nrmse(rec.channels[c], from_rest.channels[c]) for c in measured) > 0.7


def test_a_start_rate_comes_from_a_parabola_through_the_first_samples():
    """A parabola through y = 0.3 + 2 t - 40 t^2 gives its value, rate and acceleration at the first sample exactly; an
    encoder at rest (one reading) or accelerating from rest (a quantised y = 50 t^2, counts of 1e-4 rad: EMPS' and
    Quanser's runs start so) does not move; one turning at 0.05 rad/s (10 counts in 20 ms) does."""
    t = np.arange(0.0, 0.1, 1e-3)
    value, rate, acceleration, _sd = _start(t, 0.3 + 2 * t - 40 * t**2)
    assert value == pytest.approx(0.3, abs=1e-9) and rate == pytest.approx(2.0, abs=1e-9)
    assert acceleration == pytest.approx(-80.0, abs=1e-6)
    count = 1e-4  # rad

    def encoder(angle):
        return np.round(angle / count) * count

    def moving(values):
        _value, rate, _acceleration, sd = _start(t, values)
        return _moving(t, values, rate, sd)

    for still in (np.full(t.shape, 0.2), encoder(50 * t**2)):
        assert not moving(still)
    assert moving(encoder(0.1 + 0.05 * t))


def test_a_start_rate_that_is_not_a_number_is_bad_input():
    """`initial_rate` takes finite numbers (unit/s): a word or a NaN is refused in one line naming the key."""
    from watflex_sim.model import ConfigError

    for value in ('"fast"', "nan"):
        with pytest.raises(ConfigError, match=r"initial_rate\.elbow_angle must be a finite number"):
            load_scenario("watflex_elbow_step", [f"initial_rate={{elbow_angle={value}}}"])


def test_moving_starts_in_lockstep_match_their_single_runs():
    """lockstep.simulate_batch (the diagnosis' re-simulations): a Watflex recording cut mid-move and the same run
    from rest, side by side, give their single runs' recordings bit for bit (the moving one takes the per-member
    control half: the column form has no warm-up)."""
    from watflex_sim.lockstep import simulate_batch

    rec = _cut(_run("watflex_elbow_step")[0].recording, 0.8)
    scenarios = [scenario_from_recording(rec), scenario_from_recording(_at_rest(rec, ELBOW))]
    assert scenarios[0]["initial_rate"] and not scenarios[1]["initial_rate"]
    for scenario, result in zip(scenarios, simulate_batch(scenarios, nthread=2, always=True)):
        single = simulate(scenario).recording
        for c, x in single.channels.items():
            assert np.array_equal(x, result.recording.channels[c], equal_nan=True), c


def test_an_experiment_proposed_from_a_moving_recording_starts_at_rest():
    """The experiment a diagnosis proposes varies a recording's experiment for the rig to run: from a recording cut
    mid-move it starts at rest at the joints' first readings, the links straight (the strain bridges read 0 V at the
    first sample: noise off), with no rate or acceleration."""
    from watflex_sim.diagnosis.data import prepare
    from watflex_sim.diagnosis.experiment import _variant

    rec = _cut(_run("watflex_elbow_step")[0].recording, 0.8)
    proposed = _variant(prepare([rec], ["cut.csv"]), 0, 2.0, 1.0)
    assert set(proposed["initial"]) == {"shoulder_angle", "elbow_angle"}
    assert not proposed["initial_rate"] and not proposed["initial_acceleration"]
    assert simulate(proposed).recording.channels["strain_2A"][0] == 0.0


@pytest.mark.parametrize("name", ["laser_arm_step", "watflex_elbow_step", "watflex_observer_two_joint"])
def test_a_step_at_the_first_samples_starts_at_rest(name):
    """A step 0, 1 or 5 ms into a recording moves an arm at rest as fast as a cut mid-move shows it moving (their
    parabolas alone read each as moving, measured); the nominal model started at rest follows the first 0.1 s closer,
    so the re-simulation starts at rest (noise on, as a rig records)."""
    for t0 in (0.0, 0.001, 0.005):
        sc = load_scenario(name, ["duration_s=1.0"])
        for signal in sc["reference"]:
            if "time_s" in signal:
                signal["time_s"] = t0
            if "times_s" in signal:
                signal["times_s"] = [t0 + t - signal["times_s"][0] for t in signal["times_s"]]
        rec = simulate(check(sc)).recording
        assert not scenario_from_recording(rec)["initial_rate"], t0


def test_the_choice_holds_for_a_log_at_half_the_loop_rate():
    """The choice between a moving and a resting start compares the recording at its own times: logged every 2 ms
    (the Watflex loop runs at 1 ms), an elbow step cut 0.8 s in still starts moving and a step 1 ms in at rest."""
    def every_other(rec):
        return Recording(rec.time[::2], {c: v[::2] for c, v in rec.channels.items()}, rec.meta)

    cut = _cut(simulate(load_scenario("watflex_elbow_step", ["duration_s=1.5"])).recording, 0.8)
    assert scenario_from_recording(every_other(cut))["initial_rate"]
    sc = load_scenario("watflex_elbow_step", ["duration_s=1.0"])
    sc["reference"][0]["time_s"] = 0.001
    assert not scenario_from_recording(every_other(simulate(check(sc)).recording))["initial_rate"]
