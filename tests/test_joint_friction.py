"""Joint friction in the simulator: real sticking, break-away at the law's level, sliding stops.

Sources: rigs.md §2 (friction table = thesis table 4.3 / A.2; the nominal model "must hold a
joint at rest (no creep beyond one encoder count in 10 s) under a constant torque below
alpha0 + alpha1, and a sliding joint must come to rest when the torque driving it drops below
the sliding friction").
"""
import math

import mujoco
import numpy as np
import pytest

from watflex_sim.joint_friction import FrictionCallback, JointFriction, nominal_frictions
from watflex_sim.model import load_model
from watflex_sim.params import STICK_SOLIMP, STICK_SOLREF, WATFLEX

ELBOW = JointFriction(*WATFLEX.elbow_friction)
COUNT = WATFLEX.encoder_step  # rad, one encoder count


def lone_joint(inertia: float = 1.25) -> mujoco.MjModel:
    """A single hinge with the elbow's inertia (kg m^2) and the Watflex sticking constraint."""
    spec = mujoco.MjSpec()
    spec.option.timestep = WATFLEX.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    body = spec.worldbody.add_body(name="rotor")
    j = body.add_joint(name="elbow", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    j.armature = inertia
    j.frictionloss = 1.0
    j.solref_friction = list(STICK_SOLREF)
    j.solimp_friction = list(STICK_SOLIMP)
    g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0])
    g.mass = 1e-3
    spec.add_actuator(name="elbow_motor", target="elbow", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    return spec.compile()


def elbow_on_arm() -> mujoco.MjModel:
    """The Watflex model, shoulder locked, flexible link 2 and end effector on the elbow."""
    return load_model("watflex", locked_joints={"shoulder": 0.0})


def run(model, torque, seconds, friction=ELBOW):
    """Apply torque(t) (N m) to the elbow for `seconds`; return times (s), angles (rad), speeds (rad/s)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    dof = model.joint("elbow").dofadr[0]
    act = model.actuator("elbow_motor").id
    n = int(round(seconds / model.opt.timestep))
    t, q, v = np.empty(n), np.empty(n), np.empty(n)
    with FrictionCallback(model, data, {"elbow": friction}):
        for k in range(n):
            data.ctrl[act] = torque(data.time)
            mujoco.mj_step(model, data)
            t[k], q[k], v[k] = data.time, data.qpos[model.joint("elbow").qposadr[0]], data.qvel[dof]
    return t, q, v


@pytest.mark.parametrize("make_model", [lone_joint, elbow_on_arm], ids=["lone joint", "elbow with flexible link"])
@pytest.mark.parametrize("direction", [+1, -1])
def test_holds_at_90_percent_of_breakaway_for_10_s(make_model, direction):
    """rigs.md §2: at 0.9 (alpha0 + alpha1) the joint moves less than one encoder count in 10 s."""
    torque = 0.9 * ELBOW.breakaway(direction) * direction
    _, q, _ = run(make_model(), lambda t: torque, 10.0)
    assert np.abs(q).max() < COUNT, f"crept {np.abs(q).max():.2e} rad (one count = {COUNT:.2e} rad)"


@pytest.mark.parametrize("direction", [+1, -1])
def test_breaks_away_at_the_laws_level_within_1_percent(direction):
    """A slow torque ramp (0.2 N m/s from 0.97 break-away): motion starts at alpha0 + alpha1 +- 1 %.

    Detection = one encoder count moved, which lags the start by (6 J count / rate)^(1/3) = 0.1 s,
    i.e. 0.02 N m (0.4 %) at this rate.
    """
    level = ELBOW.breakaway(direction)
    start = 0.97 * level
    t, q, _ = run(lone_joint(), lambda t: direction * (start + 0.2 * t), 2.0)
    moved = np.flatnonzero(np.abs(q) > COUNT)
    assert moved.size, "never broke away"
    torque_at_breakaway = start + 0.2 * t[moved[0]]
    assert torque_at_breakaway == pytest.approx(level, rel=0.01)


def test_sliding_joint_stops_when_torque_drops_below_sliding_friction():
    """Driven at 1.5 x break-away for 0.5 s, then at 0.9 x alpha0: it must come to rest and stay."""
    level = ELBOW.breakaway(+1)
    low = 0.9 * WATFLEX.elbow_friction[0].alpha0
    t, q, v = run(lone_joint(), lambda t: 1.5 * level if t < 0.5 else low, 3.0)
    assert v[t < 0.5].max() > 0.1  # it slid (rad/s)
    late = t > 2.5  # it slows at (alpha0 + alpha2 v - 0.9 alpha0) / J >= 0.4 rad/s^2 from ~1 rad/s
    assert np.abs(v[late]).max() < 1e-4 and np.ptp(q[late]) < COUNT


def test_coulomb_stopping_distance():
    """Closed form: from v0 under constant Coulomb friction F alone, theta_stop = J v0^2 / (2 F).

    Pure Coulomb (alpha1 = alpha2 = 0) on the lone joint, J = 1.25 kg m^2, v0 = 0.5 rad/s.
    """
    from watflex_sim.params import Friction

    coulomb = Friction(alpha0=5.0, alpha1=0.0, alpha2=0.0, v_s=1.0)
    model = lone_joint()
    data = mujoco.MjData(model)
    data.qvel[0] = 0.5
    with FrictionCallback(model, data, {"elbow": JointFriction(coulomb, coulomb)}):
        mujoco.mj_step(model, data, nstep=4000)
    assert data.qpos[0] == pytest.approx(1.25 * 0.5**2 / (2 * 5.0), rel=0.01)


def test_dwell_time_raises_breakaway_as_configured():
    """thesis 4.1.6: after 10 s at rest with gain 1, tau 2 s, break-away is (1 + (1 - e^-5)) x nominal."""
    law = JointFriction(*WATFLEX.elbow_friction, dwell_gain=1.0, dwell_time=2.0)
    expected = law.breakaway(+1, rest_time=10.0)
    assert expected == pytest.approx(ELBOW.breakaway(+1) * (2 - math.exp(-5)))
    start = 0.97 * expected  # N m, then 0.2 N m/s as in the break-away test
    t, q, _ = run(lone_joint(), lambda t: 0.0 if t < 10.0 else start + 0.2 * (t - 10.0), 12.0, law)
    moved = np.flatnonzero(np.abs(q) > COUNT)
    torque_at_breakaway = start + 0.2 * (t[moved[0]] - 10.0)
    assert torque_at_breakaway == pytest.approx(expected, rel=0.01)
    assert torque_at_breakaway > 1.5 * ELBOW.breakaway(+1)


def test_callback_is_removed_after_the_block():
    model = lone_joint()
    with FrictionCallback(model, mujoco.MjData(model), nominal_frictions("watflex")):
        assert mujoco.get_mjcb_passive() is not None
    assert mujoco.get_mjcb_passive() is None


def test_actuator_bench_keeps_only_the_identified_inertia():
    """thesis 4.5.6: J_S = 3.41 kg m^2 identified with clamps; the bench adds only the root stub of link 1."""
    model = load_model("watflex", actuator_bench="shoulder")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert model.nv == 1 and model.joint(0).name == "shoulder"
    M = np.zeros((1, 1))
    mujoco.mj_fullM(model, data, M)
    assert M[0, 0] == pytest.approx(WATFLEX.shoulder.inertia, rel=2e-3)
