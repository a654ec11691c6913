"""The Watflex single-link set-up (rigs.md §2 "Single-link set-up", thesis 5.2.4): a shoulder lock
means link 1 is a rigid link and the elbow housing is fixed (a cross beam to the wall), so the
elbow drives link 2 and the end effector, still on its air bearing, from a fixed base; link 1's
strain bridges are not mounted. Checked against Euler-Bernoulli closed forms
(watflex_sim/beam_theory.py) and against the old set-up (shoulder hinge locked, link 1 flexible).
"""
import functools
import json

import mujoco
import numpy as np
import pytest

from watflex_sim import engine, load_scenario, simulate
from watflex_sim.beam_theory import clamped_free_frequencies, clamped_tip_body_frequencies
from watflex_sim.datasheet import chain_dofs, chain_frequencies
from watflex_sim.engine import ControlLoop
from watflex_sim.metrics import nrmse
from watflex_sim.model import load_model
from watflex_sim.params import WATFLEX
from watflex_sim.recording import Recording, read_recording, write_recording
from watflex_sim.resim import resimulate
from watflex_sim.rigs import WatflexRig

SHOULDER = {"shoulder": 0.0}
CLAMPED = {"shoulder": 0.0, "elbow": 0.0}
LINK1_STRAINS = ("strain_1A", "strain_1B", "strain_1C")


# --- (a) elbow clamped: link 2's modes with the end effector ----------------------------------


def test_clamped_link2_modes_match_beam_with_offset_end_effector():
    """Single-link set-up with the elbow locked too: link 2 is a cantilever clamped at its root
    clamp (l2a rigid, housing fixed) carrying the 8.1 kg end effector on the rigid end clamp
    l2c = 83 mm beyond its flexible end (rigs.md §2). Its first three modes within 1 % of
    beam_theory.clamped_tip_body_frequencies(link 2, 8.1 kg, 83 mm): 7.344, 367.1, 1242 rad/s.
    Measured +0.05 %, +0.22 %, +0.38 % (N = 12). The mass put at the beam's end instead
    (clamped_free_frequencies) would give 9.34 rad/s, 27 % off: the offset matters.
    The model's dofs are link 2's hinges and the end effector's vertical air-bearing slide only.
    """
    model = load_model("watflex", locked_joints=CLAMPED)
    assert sorted(model.joint(j).name for j in range(model.njnt)) == sorted(
        [f"link2_j{i:02d}" for i in range(1, WATFLEX.n_segments + 1)] + ["end_effector_float"])
    expected = clamped_tip_body_frequencies(WATFLEX.link2, WATFLEX.end_effector_mass, WATFLEX.l2c, 3)
    np.testing.assert_allclose(chain_frequencies(model, chain_dofs(model, "link2")), expected, rtol=0.01)
    assert expected[0] == pytest.approx(7.344, rel=1e-3)


def test_tip_body_closed_form_reduces_to_tip_mass_at_zero_offset():
    """clamped_tip_body_frequencies with offset 0 is the tip-mass equation of
    clamped_free_frequencies (Blevins table 8-1): equal to 1e-9 for 0, 1 and 8.1 kg."""
    for mass in (0.0, 1.0, 8.1):
        np.testing.assert_allclose(clamped_tip_body_frequencies(WATFLEX.link2, mass, 0.0, 3),
                                   clamped_free_frequencies(WATFLEX.link2, mass, 3), rtol=1e-9)


# --- (b) strains under a static elbow torque ---------------------------------------------------


def _roller_under_end_effector(spec: mujoco.MjSpec) -> None:
    """Hold the end-effector centre on the line y = 0 (a pin on a roller free along the straight
    link's axis x): a ball joint to a carriage on a frictionless world slide along x. The carriage
    weighs 10 kg, like the end effector: MuJoCo softens a constraint by the bodies' inverse masses,
    and a light carriage lets the pin give way sideways."""
    x = WATFLEX.l1a + WATFLEX.link1.length + WATFLEX.l1c + WATFLEX.l2a + WATFLEX.link2.length + WATFLEX.l2c
    carriage = spec.worldbody.add_body(name="roller", pos=[x, 0, WATFLEX.bearing_radius])
    carriage.add_joint(name="roller_x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    g = carriage.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[1e-3, 0, 0])
    g.mass, g.contype, g.conaffinity = 10.0, 0, 0  # kg
    pin = spec.add_equality(type=mujoco.mjtEq.mjEQ_CONNECT, name="pin", name1="end_effector", name2="roller",
                            objtype=mujoco.mjtObj.mjOBJ_BODY)
    pin.data[:3] = [0.0, 0.0, 0.0]  # anchor at the end effector's origin (the spec's default is not 0)


@pytest.mark.parametrize("torque", [10.0, -10.0])
def test_link2_strains_under_static_elbow_torque_with_end_effector_on_a_roller(torque):
    """Single-link set-up, the end-effector centre held on the link's straight line by a pin on a
    roller (free along the link, so it takes no axial force), a constant elbow torque tau (N m),
    joint friction and gravity off, simulated to rest. Link 2 (elbow hinge, rigid l2a, flexible
    L, rigid l2c to the pin) is then statically determinate: the pin pushes normal to the link
    with tau / R, R = l2a + L + l2c = 0.693 m, so the bending moment at distance s from the elbow
    axis is M(s) = -tau (R - s) / R (statics of a simply supported beam loaded by an end moment:
    the moment falls linearly from tau at the loaded end to 0 at the support) and the gauge
    reads eps = -(t/2) M / EI (thesis eq. 5.4), V = eps / K (rigs.md §2, table 3.2).
    Bridge volts (noise off, 12-bit converter) within 2 % at 2A and 2B: measured -0.01 % and
    +0.08 % (3.73 and 2.27 V at 10 N m; the converter's half step is 0.07 / 0.11 %). A fixed
    pin instead would take an axial force as the bent link's chord shortens, growing as tau^2
    (2A 7.5 % low at 10 N m with a plain MuJoCo connect to the world): not this closed form.
    """
    model = load_model("watflex", locked_joints=SHOULDER, edits=[_roller_under_end_effector])
    model.dof_frictionloss[:] = 0.0
    model.opt.gravity[:] = 0.0
    dofs = chain_dofs(model, "link2")
    w1 = clamped_tip_body_frequencies(WATFLEX.link2, WATFLEX.end_effector_mass, WATFLEX.l2c, 1)[0]
    model.dof_damping[dofs] = model.jnt_stiffness[model.dof_jntid[dofs]] * 2.0 / w1  # to rest faster
    model.dof_damping[model.joint("elbow").dofadr[0]] = 50.0  # N m s/rad; no force at rest
    data = mujoco.MjData(model)
    data.ctrl[model.actuator("elbow_motor").id] = torque
    mujoco.mj_step(model, data, nstep=int(round(4.0 / model.opt.timestep)))
    assert np.abs(data.qvel).max() < 1e-4  # at rest (measured 3e-5 rad/s)
    assert abs(data.body("end_effector").xpos[1]) < 1e-3  # held on the line
    obs = WatflexRig(model, data, WATFLEX, noise=False, seed=0, locked=SHOULDER).observe({})
    beam, reach = WATFLEX.link2, WATFLEX.l2a + WATFLEX.link2.length + WATFLEX.l2c
    for gauge in ("2A", "2B"):
        _link, x_gauge, k_bridge = WATFLEX.gauges[gauge]
        moment = -torque * (reach - (WATFLEX.l2a + x_gauge)) / reach  # N m
        expected = -0.5 * beam.thickness * moment / beam.EI / k_bridge  # V
        assert obs[f"strain_{gauge}"] == pytest.approx(expected, rel=0.02), gauge
        assert np.sign(obs[f"strain_{gauge}"]) == np.sign(torque)  # root pushed to +angle, end held: w'' < 0


# --- (c) the housing is fixed, no link-1 channel ------------------------------------------------


def test_elbow_housing_does_not_move_and_link1_is_not_recorded(tmp_path):
    """watflex_elbow_step (locked_joints = {shoulder = 0}): the elbow housing and link 1 carry no
    dof (welded to the world), the housing stays at l1a + l1b + l1c = 0.715 m through the 0.5 rad
    step (exactly: measured displacement 0), and the recording carries no strain_1A/1B/1C, in
    memory, on disk and in its re-simulation."""
    scenario = load_scenario("watflex_elbow_step")
    with ControlLoop(scenario) as loop:
        model, data = loop.model, loop.data
        housing = model.body("elbow_housing").id
        assert model.body_weldid[housing] == 0 and model.body_weldid[model.body("link1_seg06").id] == 0
        assert model.body_weldid[model.body("end_effector").id] != 0  # its air bearing still floats
        start = data.xpos[housing].copy()
        moved = 0.0
        for k in range(loop.n_ticks):
            loop.tick(k)
            moved = max(moved, float(np.linalg.norm(data.xpos[housing] - start)))
        assert data.qpos[model.joint("elbow").qposadr[0]] > 0.4  # the elbow did step
    assert start[0] == pytest.approx(WATFLEX.l1a + WATFLEX.link1.length + WATFLEX.l1c, abs=1e-5)
    assert moved == 0.0

    rec = simulate(scenario).recording
    assert not set(LINK1_STRAINS) & set(rec.channels)
    assert {"strain_2A", "strain_2B", "elbow_angle"} <= set(rec.channels)
    header = write_recording(rec, tmp_path, "step").read_text().splitlines()[0]
    assert "strain_1" not in header and "strain_2A" in header
    again = resimulate(read_recording(tmp_path / "step.csv"))
    assert set(again.channels) == set(rec.channels)


def test_link1_channels_of_a_single_link_recording_are_left_out(tmp_path):
    """A single-link recording that carries strain_1* columns (an other implementation mounted
    them): the writer omits them, the reader leaves them out, and the re-simulation, which has no
    link 1 to read, reproduces the rest (strain_2A NRMSE 0.006, the recorded noise; < 0.05)."""
    rec = simulate(load_scenario("watflex_elbow_step", ["duration_s=2.0"])).recording
    extra = {c: np.full(rec.time.size, 0.01) for c in LINK1_STRAINS}
    two_link_meta = {**rec.meta, "locked_joints": {}}
    write_recording(Recording(rec.time, {**rec.channels, **extra}, two_link_meta), tmp_path, "other")
    sidecar = tmp_path / "other.json"
    sidecar.write_text(json.dumps({**json.loads(sidecar.read_text()), "locked_joints": {"shoulder": 0.0}}))
    assert "strain_1A" in (tmp_path / "other.csv").read_text().splitlines()[0]  # on disk as given
    read = read_recording(tmp_path / "other.csv")
    assert not set(LINK1_STRAINS) & set(read.channels)
    sim = resimulate(read)
    assert set(sim.channels) == set(read.channels)
    assert nrmse(read.channels["strain_2A"], sim.channels["strain_2A"]) < 0.05

    header = write_recording(Recording(rec.time, {**rec.channels, **extra}, rec.meta), tmp_path, "ours")
    assert "strain_1" not in header.read_text().splitlines()[0]


# --- (d) the old rig is a different rig --------------------------------------------------------


def test_shoulder_lock_is_not_the_hinge_lock_with_link1_flexible():
    """The previous behaviour, the shoulder hinge locked with link 1 flexible and the elbow on its
    air bearing (load_model(single_link=False)), is a different rig: with the elbow locked as well,
    the arm's first mode is 3.41 rad/s against link 2's 7.35 rad/s from a fixed base (7.344 closed
    form); the shoulder lock gives the latter, with no link-1 hinge and no elbow air-bearing slide.
    """
    rigid = load_model("watflex", locked_joints=CLAMPED)
    flexible = load_model("watflex", locked_joints=CLAMPED, single_link=False)
    names = {rigid.joint(j).name for j in range(rigid.njnt)}
    assert not any(n.startswith("link1_j") for n in names) and "elbow_float" not in names
    assert {"elbow_float", "link1_j01"} <= {flexible.joint(j).name for j in range(flexible.njnt)}
    expected = clamped_tip_body_frequencies(WATFLEX.link2, WATFLEX.end_effector_mass, WATFLEX.l2c, 1)[0]
    both = np.concatenate([chain_dofs(flexible, "link1"), chain_dofs(flexible, "link2")])
    assert chain_frequencies(rigid, chain_dofs(rigid, "link2"), 1)[0] == pytest.approx(expected, rel=0.01)
    assert chain_frequencies(flexible, both, 1)[0] < 0.5 * expected  # measured 3.41 rad/s


def test_elbow_step_strains_are_1_7_times_the_old_set_up(monkeypatch):
    """rigs.md §2: the two rigs' link-2 strain responses are "about 1.7x apart in peak". The
    watflex_elbow_step scenario (noise off) as the thesis built it against the same scenario with
    link 1 flexible (engine's load_model with single_link=False): peak |strain_2A| ratio within
    1.6-1.8, measured 7.14 / 4.12 V = 1.73; the old rig records link 1 bending, the new one none."""
    scenario = load_scenario("watflex_elbow_step", ["noise=false", "duration_s=3.0"])
    new = simulate(scenario).recording
    monkeypatch.setattr(engine, "load_model", functools.partial(load_model, single_link=False))
    old = simulate(scenario).recording
    ratio = np.abs(new.channels["strain_2A"]).max() / np.abs(old.channels["strain_2A"]).max()
    assert 1.6 < ratio < 1.8, ratio
