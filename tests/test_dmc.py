"""Tests for watflex_sim.dmc: the rigs as dm_control environments (1 ms control step)."""
import os

os.environ.setdefault("MUJOCO_GL", "disable")  # headless: no renderer is needed

import numpy as np
import pytest
from dm_control.rl import control

from watflex_sim.controllers import PDTip
from watflex_sim import dmc, load_scenario, simulate
from watflex_sim.model import ConfigError
from watflex_sim.params import LASER_ARM, WATFLEX

LASER_KEYS = ["reference", "hub_angle", "tip_sensor"]
# watflex_elbow_step is the single-link set-up (rigs.md §2): link 1 and its bridges are not mounted
WATFLEX_KEYS = ["shoulder_reference", "elbow_reference", "shoulder_angle", "elbow_angle",
                "strain_2A", "strain_2B", "tip_x", "tip_y", "camera_age_s"]


def pd(rig, obs):
    """The brief's PD on measured channels: laser u = 0.127 e_V (V), elbow tau = 60 (ref - angle) (N m)."""
    if rig == "laser_arm":
        return np.array([0.127 * obs["tip_sensor"][0]])
    return np.array([60.0 * (obs["elbow_reference"][0] - obs["elbow_angle"][0])])


def run(env, rig, n):
    """Reset, then n PD steps; the list of n + 1 observations and the n rewards."""
    ts = env.reset()
    observations, rewards = [ts.observation], []
    for _ in range(n):
        ts = env.step(pd(rig, ts.observation))
        observations.append(ts.observation)
        rewards.append(ts.reward)
    return observations, rewards


@pytest.fixture(scope="module", params=["laser_arm", "watflex"])
def episode(request):
    rig = request.param
    env = dmc.load(rig, seed=7)
    observations, rewards = run(env, rig, 200)
    return rig, env, observations, rewards


def test_observations_are_the_rigs_channels(episode):
    rig, env, observations, _ = episode
    keys = LASER_KEYS if rig == "laser_arm" else WATFLEX_KEYS
    spec = env.observation_spec()
    assert list(spec) == keys
    for obs in observations:
        assert list(obs) == keys
        for k in keys:
            assert obs[k].shape == spec[k].shape == (1,) and obs[k].dtype == spec[k].dtype
    assert all(np.isfinite(obs[k]).all() for obs in observations for k in keys)  # never NaN (issue 17)
    if rig == "watflex":  # camera at 25 Hz: a frame every 40 control steps, held between
        frames = [k for k, obs in enumerate(observations) if obs["camera_age_s"][0] == 0.0]
        assert frames == list(range(0, 201, 40))
        assert observations[39]["camera_age_s"][0] == pytest.approx(0.039)
        assert observations[39]["tip_x"][0] == observations[0]["tip_x"][0]


def test_control_step_is_1ms_whole_substeps(episode):
    rig, env, _, _ = episode
    timestep = {"laser_arm": 1e-4, "watflex": 5e-4}[rig]  # s, params.py
    assert env.physics.timestep() == timestep
    assert control.compute_n_steps(1e-3, timestep) == round(1e-3 / timestep)
    assert env.control_timestep() == pytest.approx(1e-3, rel=1e-12)
    assert env.physics.time() == pytest.approx(0.2, abs=1e-9)  # 200 steps


def test_action_bounds_are_the_datasheets(episode):
    rig, env, _, _ = episode
    spec = env.action_spec()
    assert spec.shape == (1,)
    if rig == "laser_arm":  # rigs.md §1: amplifier voltage +-24 V
        assert spec.minimum[0] == -24.0 and spec.maximum[0] == 24.0
    else:  # rigs.md §2: 10 V x 0.4679 A/V x 11.5 N m/A = 53.8 N m
        limit = 10.0 * 0.4679 * 11.5
        assert spec.maximum[0] == pytest.approx(limit, rel=1e-3)
        assert spec.minimum[0] == pytest.approx(-limit, rel=1e-3)
        assert spec.maximum[0] == pytest.approx(53.8, rel=1e-3)


def test_rewards_in_unit_interval(episode):
    _, _, _, rewards = episode
    assert len(rewards) == 200 and all(0.0 <= r <= 1.0 for r in rewards)


def test_laser_arm_hub_moves_towards_reference():
    env = dmc.load("laser_arm", seed=1)
    observations, rewards = run(env, "laser_arm", 200)
    reference = 0.0025 / 1.18  # rad, rigs.md §1 step experiment (2.5 mm at L = 1.18 m)
    assert observations[0]["reference"][0] == 0.0
    assert observations[-1]["reference"][0] == pytest.approx(reference)
    theta = observations[-1]["hub_angle"][0]
    assert 0.0 < theta and abs(reference - theta) < 0.2 * reference  # 0.1 s after the 0.1 s step
    assert env.physics.hub_angle() == pytest.approx(theta, abs=2 * np.pi / (4 * 1024 * 80))
    assert rewards[-1] > rewards[100]  # just after the step the error is 2.5 mm


def test_same_seed_same_observations():
    def trace(seed):
        observations, _ = run(dmc.load("watflex", seed=seed), "watflex", 50)
        laser, _ = run(dmc.load("laser_arm", seed=seed), "laser_arm", 50)
        return np.concatenate([v for o in observations + laser for v in o.values()])

    a, b, c = trace(3), trace(3), trace(4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c, equal_nan=True)  # the noise is the seed's


def test_matches_engine_simulate_step_for_step():
    """Noise off, the environment driven by PDTip reproduces `simulate(laser_arm_step)` exactly
    (both refresh positions after stepping: dm_control's legacy_step, the engine's mj_kinematics)."""
    scenario = load_scenario("laser_arm_step", ["noise=false", "duration_s=0.3"])
    recording = simulate(scenario).recording
    base = dmc.load("laser_arm", payload_kg=scenario["payload_kg"], noise=False)
    env = control.Environment(base.physics, base.task, control_timestep=1e-3, time_limit=0.3)
    controller, ts, hub = PDTip(kp=0.127), env.reset(), []
    while True:
        obs = {k: v[0] for k, v in ts.observation.items()}
        ts = env.step([controller(len(hub) * 1e-3, obs)["voltage_cmd"]])
        hub.append(obs["hub_angle"])
        if ts.last():
            break
    np.testing.assert_array_equal(np.array(hub), recording.channels["hub_angle"])


def test_physics_readouts():
    physics = dmc.FlexArmPhysics.from_rig("watflex", locked_joints={"shoulder": 0.0})
    assert list(physics.joint_angles()) == ["elbow"]
    assert physics.bending_angles("link2").shape == (WATFLEX.n_segments,)
    with pytest.raises(ValueError, match="no flexible chain 'link1'"):  # single-link set-up: link 1 rigid
        physics.bending_angles("link1")
    # m, rigs.md §2; the committed XML's 6 significant digits leave 2 um
    assert physics.tip_position()[0] == pytest.approx(0.13 + 0.47 + 0.115 + 0.14 + 0.47 + 0.083, abs=1e-5)
    with pytest.raises(ValueError, match="no flexible chain 'beam'"):
        physics.bending_angles("beam")
    laser = dmc.FlexArmPhysics.from_rig("laser_arm")
    assert laser.tip_position()[0] == pytest.approx(1.18, abs=1e-5)
    assert laser.bending_angles("beam").shape == (LASER_ARM.n_segments,)


def test_unknown_rig():
    with pytest.raises(ConfigError, match="unknown rig 'scara'"):
        dmc.load("scara")
