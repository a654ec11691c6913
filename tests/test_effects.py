"""Every catalogue effect (recordings.md) attaches to a rig, runs, and changes what it should."""
import numpy as np
import pytest

from watflex_sim import load_scenario, simulate
from watflex_sim.effects import CATALOGUE
from watflex_sim.model import ConfigError

# effect -> (scenario, parameters, channel that must change, smallest change in that channel's unit)
CASES = {
    "coulomb_friction": ("laser_arm_step", dict(where="hub", torque_positive=2.778, torque_negative=0.926), "tip_sensor", 1.0),
    "stribeck_friction": ("watflex_elbow_step", dict(where="elbow", breakaway_positive=2.0, breakaway_negative=1.0, v_s=0.03), "elbow_angle", 1e-4),
    "viscous_friction": ("watflex_elbow_step", dict(where="elbow", coefficient=5.0), "elbow_angle", 1e-2),
    "presliding": ("watflex_elbow_step", dict(where="elbow", sigma0=1e4, sigma1=10.0), "elbow_angle", 1e-4),
    "dwell_time_stiction": ("watflex_elbow_step", dict(where="elbow", gain=1.0, time_constant=0.2), "elbow_angle", 1e-4),
    "position_dependent_friction": ("watflex_elbow_step", dict(where="elbow", amplitude=1.0, period=0.5), "elbow_angle", 1e-3),
    "backlash": ("laser_arm_step", dict(where="hub", width=3e-4), "tip_sensor", 0.1),
    "joint_compliance": ("laser_arm_step", dict(where="hub", stiffness=2e3), "tip_sensor", 0.1),
    "payload": ("laser_arm_step", dict(where="tip", mass=0.3), "tip_sensor", 0.1),
    "link_stiffness_change": ("laser_arm_step", dict(where="beam", ratio=0.7), "tip_sensor", 0.05),
    "structural_damping": ("watflex_elbow_step", dict(where="link2", ratio=5.0), "strain_2A", 0.01),
    "actuator_gain": ("watflex_elbow_step", dict(where="elbow_torque_cmd", ratio=0.8), "elbow_angle", 1e-2),
    "actuator_offset": ("laser_arm_step", dict(where="voltage_cmd", offset=0.2), "tip_sensor", 0.5),
    "current_saturation": ("watflex_elbow_step", dict(where="elbow_torque_cmd", limit=10.0), "elbow_angle", 1e-2),
    "sensor_gain": ("laser_arm_step", dict(where="tip_sensor", ratio=0.9), "tip_sensor", 0.5),
    "sensor_offset": ("laser_arm_step", dict(where="tip_sensor", offset=0.05), "tip_sensor", 0.04),
    "delay": ("laser_arm_step", dict(where="command", seconds=0.005), "tip_sensor", 0.1),
    "bearing_friction": ("watflex_elbow_step", dict(where="end_effector_bearing", force=5.0), "elbow_angle", 1e-2),
    "table_tilt": ("watflex_elbow_step", dict(where="", angle=0.005), "elbow_angle", 3e-4),
}


def test_every_catalogue_effect_has_a_case():
    assert set(CASES) == set(CATALOGUE)


@pytest.mark.parametrize("effect", sorted(CASES))
def test_effect_changes_its_channel(effect):
    name, params, channel, least = CASES[effect]
    overrides = ["noise=false", "duration_s=1.5" if name.startswith("watflex") else "duration_s=1.0"]
    nominal = simulate(load_scenario(name, overrides)).recording
    scenario = load_scenario(name, overrides)
    scenario["effects"] = [dict(effect=effect, **params)]
    changed = simulate(scenario).recording
    difference = np.nanmax(np.abs(changed.channels[channel] - nominal.channels[channel]))
    assert difference > least


def test_coulomb_on_the_laser_hub_sticks_at_its_level():
    """Paper: 2.778 N m clockwise stiction; with the voltage drive's current limit the hub can push
    at most 12.48 N m/A x 1.9 A = 23.7 N m, so a 2.5 mm step still moves, but it stops short."""
    scenario = load_scenario("laser_arm_step", ["noise=false"])
    scenario["effects"] = [dict(effect="coulomb_friction", where="hub", torque_positive=2.778, torque_negative=0.926)]
    rec = simulate(scenario).recording
    error = rec.channels["tip_sensor"][-1]
    assert abs(error) > 0.05  # V: a steady-state error the frictionless model (0 V) does not have


def test_unknown_effect_and_bad_parameters_are_config_errors():
    scenario = load_scenario("laser_arm_step")
    scenario["effects"] = [dict(effect="gremlins", where="hub")]
    with pytest.raises(ConfigError, match="unknown effect 'gremlins'"):
        simulate(scenario)
    scenario["effects"] = [dict(effect="payload", where="tip", kilos=1)]
    with pytest.raises(ConfigError, match="effect 'payload'.*parameters: mass"):
        simulate(scenario)


def _tip_during_step(effects, direction):
    """Tip sensor (V) over 1 s of a laser step (step at 0.1 s), noise off."""
    scenario = load_scenario("laser_arm_step", ["noise=false", "duration_s=1.0", f"direction={direction}"])
    scenario["effects"] = effects
    return simulate(scenario).recording.channels["tip_sensor"]


def test_backlash_is_a_dead_band_and_can_open_one_way_only():
    """A band of 1e-5 rad changes the laser step at least 2.5x less than a band of 3e-4 rad (a hard
    stop: with MuJoCo's default soft limit any width acted as the same spring; measured 0.34 V vs
    1.11 V, the 0.34 V being the 5e-3 kg m^2 clamp's inertia, effects.EXTRA_HINGE_ARMATURE); a band starting
    against its positive stop (position +1) changes the first swing of a positive (clockwise)
    step far more than a negative one's: the paper's bolted root that slips one way and tightens
    the other (laser_arm_paper section 5). (The loop's rebound later opens it both ways.)"""
    base = {d: _tip_during_step([], d) for d in ("positive", "negative")}
    tiny = _tip_during_step([dict(effect="backlash", where="hub", width=1e-5)], "positive")
    wide = _tip_during_step([dict(effect="backlash", where="hub", width=3e-4)], "positive")
    rms = lambda a, b: float(np.sqrt(np.mean((a - b) ** 2)))  # noqa: E731
    assert 2.5 * rms(tiny, base["positive"]) < rms(wide, base["positive"])
    slip = [dict(effect="backlash", where="hub", width=2.88e-4, position=0.95)]
    first_swing = slice(100, 160)  # the 60 ms after the step, before the loop's rebound opens the band too
    change = {d: rms(_tip_during_step(slip, d)[first_swing], base[d][first_swing]) for d in ("positive", "negative")}
    assert change["positive"] > 2.5 * change["negative"], change  # measured 0.85 vs 0.30 V rms


def test_sensor_delay_starts_with_the_first_reading():
    """A tip-sensor delay holds the first reading until the delay has passed: no NaN, no divergence."""
    scenario = load_scenario("laser_arm_step", ["noise=false", "duration_s=0.3"])
    scenario["effects"] = [dict(effect="delay", where="tip_sensor", seconds=0.004)]
    rec = simulate(scenario).recording
    assert np.isfinite(rec.channels["tip_sensor"]).all()


def test_sensor_effects_reach_monitored_channels():
    """motor_current is monitored, not fed back: an offset there shows in the recording as it is."""
    scenario = load_scenario("laser_arm_step", ["noise=false", "duration_s=0.2"])
    plain = simulate(scenario).recording.channels["motor_current"]
    scenario["effects"] = [dict(effect="sensor_offset", where="motor_current", offset=0.01)]
    shifted = simulate(scenario).recording.channels["motor_current"]
    assert np.allclose(shifted - plain, 0.01, atol=1e-9)
