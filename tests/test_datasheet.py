"""A model from a datasheet in TOML (issue 15 item 2): watflex_sim/datasheet.py checked against
physics (Euler-Bernoulli modes and static deflection, the DC motor's closed form), a rig that exists
only in a temporary folder run and diagnosed from the command line, and bad rig files (one line, exit 2)."""
import json
import math

import mujoco
import numpy as np
import pytest

from watflex_sim import datasheet
from watflex_sim.beam_theory import clamped_free_frequencies, tip_deflection
from watflex_sim.cli import EXIT_BAD_INPUT, main
from watflex_sim.effects import Patch, knob_body_inertia
from watflex_sim.model import MODELS_DIR, ConfigError
from watflex_sim.params import LASER_ARM, WATFLEX

# A one-link arm [ours, test data]: an aluminium strip 0.5 m x 30 mm x 4 mm (E = 70 GPa, EI = E w t^3 / 12
# = 11.2 N m^2, rho A = 2700 x 0.03 x 0.004 = 0.324 kg/m) with 0.2 kg at its tip, on a geared current drive.
LINK = ('{ type = "flexible", name = "beam", length = "0.5 m", E = 70e9, width = 0.03, thickness = 0.004, '
        'mass_per_length = 0.324, tip_mass = 0.2 }')
PID_LAW = """[controller]
type = "pid"
command = "current_cmd"
position = "hub"
reference = "hub_reference"
kp = 5.0
kd = 0.5
rate_hz = 50.0
"""  # the rig's law, and the law its recordings name
RIG = """name = "labarm"
description = "a one-link flexible arm described by its datasheet only"
sensors = "generic"
model = "datasheet"

[channels]
hub_reference = {{ unit = "rad", kind = "reference" }}
hub = {{ unit = "rad", kind = "measured", joint = "shoulder", step = 1e-4, noise = 3e-5 }}
link = {{ unit = "rad", kind = "measured", link = "beam", quantity = "deflection_angle", length = 0.5, noise = 1e-4 }}
current_cmd = {{ unit = "A", kind = "command", actuator = "shoulder_motor", joint = "shoulder" }}

""" + PID_LAW + """
[parameters]
shoulder_damping = {{ knob = "damping", target = "shoulder", tolerance = 0.25 }}

[effects]
coulomb_friction = ["shoulder"]
viscous_friction = ["shoulder"]
sensor_offset = ["hub", "link"]

[datasheet]
timestep = 5e-4                       # s

[[datasheet.stages]]
joint = "shoulder"
gear = 50.0                           # -
rotor_inertia = 2e-5                  # kg m^2 at the motor
hub_inertia = 0.02                    # kg m^2
damping = 0.1                         # N m s/rad
drive = {{ type = "current", actuator = "shoulder_motor", torque_constant = 0.1, efficiency = 0.8, limit = 2.0, bits = 12 }}
link = {link}
"""
SCENARIO = """rig = "labarm"
experiment = "labarm_moves"
duration_s = 2.5
reference = { channel = "hub_reference", kind = "triangle", amplitude = 0.5, slope = 1.0, periods = 1 }
effects = [{ effect = "coulomb_friction", where = "shoulder", torque_positive = 0.5, torque_negative = 0.5 }]
""" + PID_LAW


def stage_datasheet(link: str, drive: str = '{ type = "current", torque_constant = 0.1 }', extra: str = "",
                    timestep: float = 5e-4) -> dict:
    """A checked one-stage datasheet (hub `drive1`) from TOML snippets."""
    import tomllib

    text = f"timestep = {timestep}\n[[stages]]\n{extra}\ndrive = {drive}\nlink = {link}\n"
    return datasheet.check(tomllib.loads(text), "test.toml")


def clamped_chain_modes(model: mujoco.MjModel, prefix: str, n_modes: int = 3) -> np.ndarray:
    """Frequencies (rad/s) of the chain `{prefix}_jNN`, every other dof held (a clamped root)."""
    return datasheet.chain_frequencies(model, datasheet.chain_dofs(model, prefix), n_modes)


def hub_inertia(model: mujoco.MjModel) -> float:
    """Inertia (kg m^2) about the hub at the straight pose, reflected motor included: M[0, 0]."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    return mass[0, 0]


def test_flexible_link_modes_are_euler_bernoulli_within_1_percent():
    """The first three clamped modes of a flexible link built from length, EI, rho A and tip mass are
    within 1 % of the closed form (Blevins table 8-1, beam_theory.clamped_free_frequencies), with the
    fewest segments that do it (one fewer misses); measured: 0.12 %, 0.53 %, 0.93 % at 11 segments."""
    d = stage_datasheet(LINK)
    link = d["stages"][0]["link"]
    model = datasheet.build(d).compile()
    beam = datasheet.beam(link, 0.2)
    exact = clamped_free_frequencies(beam, 0.2, 3)
    error = clamped_chain_modes(model, "beam") / exact - 1
    assert np.all(np.abs(error) < 0.01), error
    n = datasheet.n_segments(d["stages"], 0)
    assert model.njnt == 1 + n
    assert np.any(np.abs(datasheet.clamped_modes(beam, n - 1, 0.2) / exact - 1) >= 0.01)
    # the damping rule of build.py: c = beta k with beta = 2 zeta / w1 (zeta 0.01, w1 with the tip mass)
    j = model.joint("beam_j01")
    assert j.damping[0] / j.stiffness[0] == pytest.approx(2 * 0.01 / exact[0], rel=1e-12)


def test_flexible_link_static_tip_deflection_is_pl3_over_3ei():
    """A tip force F on the clamped link: linear statics K q = J^T F give F L^3 / 3EI (tip_deflection)
    less exactly 1 / (4 N^2) of it: the RFE hinges at the segment midpoints integrate (L - x)^2 by the
    midpoint rule, whose error is L dx^2 / 12 of L^3 / 3 [ours: derivation in the docstring]."""
    d = stage_datasheet(LINK)
    model = datasheet.build(d).compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    dofs = [model.jnt_dofadr[j] for j in range(model.njnt) if model.joint(j).name.startswith("beam_j")]
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacp, None, model.site("tip").id)
    force = 1.0  # N along y at the tip
    q = jacp[1, dofs] * force / model.jnt_stiffness[model.dof_jntid[dofs]]
    w = jacp[1, dofs] @ q
    beam = datasheet.beam(d["stages"][0]["link"], 0.2)
    n = len(dofs)
    assert w / tip_deflection(beam, force) - 1 == pytest.approx(-1 / (4 * n * n), rel=1e-6)
    assert abs(w / tip_deflection(beam, force) - 1) < 0.01


@pytest.mark.parametrize("damping", [0.0, 0.05])
def test_voltage_drive_is_the_dc_motor_closed_form(damping):
    """A voltage-driven DC motor (Km 0.05 N m/A, R 2 ohm, Kg 10, eta 0.9 [ours]) under a constant 6 V turns
    a stage of inertia J against viscous b: J dw/dt = eta Kg Km (V - Km Kg w) / R - b w, so
    w_ss = eta Kg Km V / (R b + eta Kg^2 Km^2) (no load: V / (Km Kg) = 12 rad/s) and tau = J / (b + eta Kg^2 Km^2 / R).
    Simulated (1e-4 s steps, the load on a stiff spring): w_ss to 1e-4 (measured 6e-6), the time to
    1 - 1/e of it within 1 % of tau (measured 0.2 % / 0.3 %)."""
    d = stage_datasheet(
        '{ type = "torsional_spring", name = "load", length = 0.1, stiffness = 5000.0, damping = 2.0, inertia = 1e-3 }',
        drive='{ type = "voltage", torque_constant = 0.05, resistance = 2.0, efficiency = 0.9, limit = 12.0 }',
        extra=f"gear = 10.0\nrotor_inertia = 1e-5\nhub_inertia = 1e-3\ndamping = {damping}", timestep=1e-4)
    model = datasheet.build(d).compile()
    data = mujoco.MjData(model)
    km, kg, r, eta, volts = 0.05, 10.0, 2.0, 0.9, 6.0
    inertia = model.dof_armature[0] + model.body_inertia[1:, 2].sum()  # kg m^2, all on the hub axis
    w_ss = eta * kg * km * volts / (r * damping + eta * kg**2 * km**2)
    tau = inertia / (damping + eta * kg**2 * km**2 / r)
    if damping == 0:
        assert w_ss == pytest.approx(volts / (km * kg), rel=1e-12)
    data.ctrl[0] = volts
    times, speeds = [], []
    while data.time < 12 * tau:
        mujoco.mj_step(model, data)
        times.append(data.time)
        speeds.append(data.qvel[model.joint("drive1").dofadr[0]])
    assert speeds[-1] == pytest.approx(w_ss, rel=1e-4)
    t63 = np.interp((1 - math.exp(-1)) * w_ss, speeds[: len(speeds) // 2], times[: len(times) // 2])
    assert t63 == pytest.approx(tau, rel=0.01)


def test_the_laser_arm_is_the_datasheet_model_of_its_params():
    """models/laser_arm.xml IS datasheet.build of params.py's laser arm (laser_arm_datasheet: one stage, the
    reflected motor N^2 J_e = 0.768 kg m^2 as armature, J_hub as a disc geom `hub`, voltage drive, the beam
    with the 0.15 kg tip sensor): the same XML as the generator writes. Its first three clamped modes
    (hub held) are within 1 % of Euler-Bernoulli with the tip sensor (Blevins table 8-1,
    beam_theory.clamped_free_frequencies); measured +0.15, +0.57, +0.97 % at 11 segments (README
    "Discretisation": the tip sensor a point mass)."""
    header, text = (MODELS_DIR / "laser_arm.xml").read_text().split("\n", 1)
    assert header.startswith("<!-- Generated by tools/build_models.py")
    assert text == datasheet.build(datasheet.laser_arm_datasheet(LASER_ARM), "laser_arm").to_xml()
    model = mujoco.MjModel.from_xml_path(str(MODELS_DIR / "laser_arm.xml"))
    exact = clamped_free_frequencies(LASER_ARM.beam, LASER_ARM.tip_sensor_mass, 3)
    error = clamped_chain_modes(model, "beam") / exact - 1
    assert np.all(np.abs(error) < 0.01), error
    assert model.dof_armature[model.joint("hub").dofadr[0]] == pytest.approx(LASER_ARM.reflected_motor_inertia, rel=1e-12)
    assert hub_inertia(model) - model.dof_armature[0] == pytest.approx(LASER_ARM.arm_inertia, rel=1e-4)  # 0.639 kg m^2
    j = model.joint("beam_j01")
    assert j.damping[0] / j.stiffness[0] == pytest.approx(LASER_ARM.beam.damping_beta, rel=1e-6)  # the XML's 6-7 digits


def test_a_hub_disc_carries_hub_inertia_and_a_stage_mass_is_a_point():
    """`hub_radius`: hub_inertia (0.02 kg m^2) becomes a solid disc's own inertia about z (geom named after the
    joint, mass 2 J / r^2 = 16 kg at r = 0.05 m) instead of armature, so M[0, 0] is unchanged (to 1e-6: the
    XML's digits) and a geom_mass knob on it scales J alone; a stage `mass` (kg) adds only 4e-7 m kg m^2
    (a 1 mm sphere) about the joint [ours: m r^2 / 2, 2/5 m r^2]. Only a flexible link's stage has a disc."""
    plain = stage_datasheet(LINK, extra="hub_inertia = 0.02\nmass = 3.0")
    disc = stage_datasheet(LINK, extra="hub_inertia = 0.02\nmass = 3.0\nhub_radius = 0.05")
    spec = datasheet.build(disc)
    assert spec.geom("drive1").size[0] == 0.05 and spec.geom("drive1").mass == pytest.approx(16.0)
    a, b = datasheet.build(plain).compile(), spec.compile()
    assert b.dof_armature[0] == 0 and a.dof_armature[0] == pytest.approx(0.02)
    assert hub_inertia(b) == pytest.approx(hub_inertia(a), rel=1e-6)
    patch = Patch()
    knob_body_inertia(patch, "drive1", 1.03)
    patch.spec_edits[0](spec)
    assert hub_inertia(spec.compile()) - hub_inertia(b) == pytest.approx(0.03 * 0.02, rel=1e-6)
    bare = datasheet.build(stage_datasheet(LINK, extra="hub_inertia = 0.02")).compile()
    assert hub_inertia(a) - hub_inertia(bare) == pytest.approx(0.4 * 3.0 * 1e-3**2, rel=1e-6)
    with pytest.raises(ConfigError, match=r"stages\[1\].hub_radius: a hub disc only on a flexible link's stage"):
        stage_datasheet('{ type = "torsional_spring", name = "load", length = 0.1, stiffness = 5.0 }',
                        extra="hub_inertia = 0.02\nhub_radius = 0.05")
    with pytest.raises(ConfigError, match=r"stages\[1\].hub_radius: the hub disc carries hub_inertia, which is missing"):
        stage_datasheet(LINK, extra="hub_radius = 0.05")


def test_watflex_link2_numbers_give_the_bundled_models_link():
    """Watflex link 2 (rigs.md section 2, params.py): the 470 mm plate between rigid clamps l2a, l2c with the
    8.1 kg end effector at the end of l2c, as a datasheet link: its first three clamped modes within 1 % of
    models/watflex.xml's link 2 (elbow held), same beta. Measured: 11 segments here, 12 there; 0.01, 0.02, 0.06 %."""
    p, b = WATFLEX, WATFLEX.link2
    link = (f'{{ type = "flexible", name = "link2", length = {b.length}, EI = {b.EI}, mass_per_length = {b.mass_per_length}, '
            f'thickness = {b.thickness}, height = {b.height}, root_clamp = {p.l2a}, tip_clamp = {p.l2c}, '
            f'tip_mass = {p.end_effector_mass} }}')
    ours = datasheet.build(stage_datasheet(link, extra=f'joint = "elbow"\nhub_inertia = {p.elbow.inertia}')).compile()
    bundled = mujoco.MjModel.from_xml_path(str(MODELS_DIR / "watflex.xml"))
    error = clamped_chain_modes(ours, "link2") / clamped_chain_modes(bundled, "link2") - 1
    assert np.all(np.abs(error) < 0.01), error
    j = ours.joint("link2_j01")
    assert j.damping[0] / j.stiffness[0] == pytest.approx(b.damping_beta, rel=1e-9)


VOLTAGE_DRIVE = '{ type = "voltage", actuator = "shoulder_motor", torque_constant = 0.1, resistance = 1.5, limit = 6.0 }'


@pytest.mark.parametrize("drive", ["current", "voltage"])
def test_motor_current_channel_is_the_drive_closed_form(tmp_path, monkeypatch, drive):
    """quantity = "current" on labarm's drive (A): a current drive reads the commanded current after the
    amplifier limit (2 A), i.e. the command held since the last tick; a voltage drive (Km 0.1 N m/A,
    Kg 50, R 1.5 ohm, 6 V [ours]) reads i = (V - Km Kg w) / R, w the hub speed at the sample (rad/s).
    Noise off, 1 s, a 0.5 rad step: equal to 1e-12 A (rounding: the sensor multiplies by 1/R or 1/(eta Kt Kg);
    measured 4.4e-16 A); measured peaks: 2.0 A (the limit) on the current drive, 3.2 A on the voltage
    drive with a back-EMF term up to 4.3 A."""
    monkeypatch.setenv("WATFLEX_RIGS", str(tmp_path / "labarm"))
    rig = RIG.format(link=LINK).replace(
        'current_cmd = { unit = "A"',
        'current = { unit = "A", kind = "measured", quantity = "current", actuator = "shoulder_motor" }\n'
        'hub_rate = { unit = "rad/s", kind = "measured", joint = "shoulder", quantity = "velocity" }\n'
        'current_cmd = { unit = "A"')
    scenario = SCENARIO.replace("kp = 5.0", "kp = 40.0").replace("kd = 0.5", "kd = 2.0").replace(
        'kind = "triangle", amplitude = 0.5, slope = 1.0, periods = 1', 'kind = "step", amplitude = 0.5, time_s = 0.1')
    if drive == "voltage":
        rig = rig.replace('drive = { type = "current", actuator = "shoulder_motor", torque_constant = 0.1, efficiency = 0.8, '
                          'limit = 2.0, bits = 12 }', f"drive = {VOLTAGE_DRIVE}")
        rig, scenario = (text.replace("current_cmd", "voltage_cmd").replace('unit = "A", kind = "command"', 'unit = "V", kind = "command"')
                         for text in (rig, scenario))
        assert "voltage_cmd = { unit = \"V\"" in rig
    (tmp_path / "labarm").mkdir()
    (tmp_path / "labarm" / "rig.toml").write_text(rig)
    (tmp_path / "moves.toml").write_text(scenario)
    from watflex_sim.engine import simulate
    from watflex_sim.scenario import load_scenario

    rec = simulate(load_scenario(str(tmp_path / "moves.toml"), ["noise=false", "duration_s=1.0", "effects=[]"])).recording
    current = rec.channels["current"]
    if drive == "current":
        command = rec.channels["current_cmd"]
        expected = np.concatenate([[0.0], np.clip(command[:-1], -2.0, 2.0)])
        assert np.abs(command).max() == pytest.approx(2.0)  # the limit is reached
    else:
        volts = np.concatenate([[0.0], np.clip(rec.channels["voltage_cmd"][:-1], -6.0, 6.0)])
        expected = (volts - 0.1 * 50.0 * rec.channels["hub_rate"]) / 1.5
        assert np.abs(0.1 * 50.0 * rec.channels["hub_rate"]).max() / 1.5 > 0.5  # back-EMF matters
    np.testing.assert_allclose(current, expected, rtol=0, atol=1e-12)
    assert np.abs(current).max() > 0.5


@pytest.mark.slow
def test_a_rig_only_in_a_temporary_folder_is_simulated_and_diagnosed(tmp_path, monkeypatch, capsys):
    """Done-when of issue 15 item 2: rig.toml (datasheet, sensors, a PID) in tmp_path and nothing else; its
    model is generated at load (and written on request by build-model). A 2.5 s recording with 0.5 N m of
    Coulomb friction at the shoulder, run by `watflex-sim run`, is diagnosed by `watflex-sim diagnose`
    (one worker): coulomb_friction at the shoulder, 0.5 N m within 10 % (measured 0.485 / 0.480)."""
    monkeypatch.setenv("WATFLEX_RIGS", "")
    rig = tmp_path / "lab" / "labarm"
    rig.mkdir(parents=True)
    (rig / "rig.toml").write_text(RIG.format(link=LINK))
    (tmp_path / "moves.toml").write_text(SCENARIO)
    out, report = tmp_path / "out", tmp_path / "report"
    assert main(["run", str(tmp_path / "moves.toml"), "--rig", str(rig), "--out", str(out), "--no-rrd", "--no-plot"]) == 0
    assert main(["diagnose", str(out / "moves.csv"), "--rig", str(rig), "--report", str(report), "--workers", "1",
                 "--max-effects", "1", "--no-rrd"]) == 0
    found = json.loads((report / "report.json").read_text())
    assert [(f["effect"], f["where"]) for f in found["findings"]] == [("coulomb_friction", "shoulder")]
    p = found["findings"][0]["parameters"]
    assert 0.5 * (p["torque_positive"] + p["torque_negative"]) == pytest.approx(0.5, rel=0.1)
    assert found["held_out"]["after"]["nrmse"] < 0.1 * found["held_out"]["before"]["nrmse"]
    assert main(["build-model", "--rig", str(rig)]) == 0
    assert mujoco.MjModel.from_xml_path(str(rig / "labarm.xml")).njnt == 1 + 11  # the shoulder and 11 segments


@pytest.mark.parametrize("edit, key", [
    (lambda t: t.replace("mass_per_length = 0.324", "mass_per_length = 0.324, colour = 1"), "stages[1].link.colour: unknown key"),
    (lambda t: t.replace("mass_per_length = 0.324, ", ""), "stages[1].link.mass_per_length: missing"),
    (lambda t: t.replace('length = "0.5 m"', "length = -0.5"), "stages[1].link.length: must be > 0"),
    (lambda t: t.replace('length = "0.5 m"', 'length = "50 cm"'), "stages[1].link.length: unit 'cm', expected m"),
    (lambda t: t.replace('type = "current"', 'type = "hydraulic"'), "stages[1].drive.type: must be one of current, voltage"),
    (lambda t: t.replace('timestep = 5e-4', 'time_step = 5e-4'), "datasheet.time_step: unknown key"),
    (lambda t: t.replace('joint = "shoulder" }', 'joint = "shoulder", gain = 2.0 }'), "channel 'current_cmd': gain 2.0 is not"),
])
@pytest.mark.parametrize("command", ["build-model", "run"])
def test_bad_datasheet_is_one_line_naming_file_and_key(tmp_path, monkeypatch, capsys, edit, key, command):
    monkeypatch.setenv("WATFLEX_RIGS", "")
    path = tmp_path / "bad.toml"
    path.write_text(edit(RIG.format(link=LINK)))
    (tmp_path / "moves.toml").write_text(SCENARIO)
    argv = ["build-model", "--rig", str(path)] if command == "build-model" else \
        ["run", str(tmp_path / "moves.toml"), "--rig", str(path), "--out", str(tmp_path / "out"), "--no-rrd", "--no-plot"]
    assert main(argv) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and key in err, err
    assert not (tmp_path / "out").exists()


def test_a_torsional_link_needs_its_stiffness():
    with pytest.raises(ConfigError, match=r"test.toml: datasheet.stages\[1\].link.EI: missing"):
        stage_datasheet('{ type = "torsional_spring", name = "load", length = 0.1 }')


@pytest.mark.parametrize("edit, why", [
    (lambda t: t.replace('quantity = "current", actuator = "shoulder_motor"', 'quantity = "current"'),
     "channel 'current': quantity 'current' needs the actuator of a datasheet drive"),
    (lambda t: t.replace('quantity = "current", actuator = "shoulder_motor"', 'quantity = "current", actuator = "nope"'),
     "channel 'current': actuator 'nope' is not a datasheet drive"),
])
def test_a_current_channel_names_a_datasheet_drive(tmp_path, edit, why):
    from watflex_sim.rigdesc import load_rig

    rig = RIG.format(link=LINK).replace(
        'current_cmd = { unit = "A"',
        'current = { unit = "A", kind = "measured", quantity = "current", actuator = "shoulder_motor" }\ncurrent_cmd = { unit = "A"')
    (tmp_path / "labarm.toml").write_text(edit(rig))
    with pytest.raises(ConfigError, match=f"labarm.toml: {why}"):
        load_rig(str(tmp_path / "labarm.toml"))


@pytest.mark.parametrize("drive", ["current", "voltage"])
def test_the_diagnosis_measures_effort_in_newton_metres(tmp_path, monkeypatch, drive):
    """A friction level is sized from the peak actuator torque (diagnosis.motion.scale_of, "effort"): on
    a current drive the command channel's gain (eta Kt Kg = 0.8 x 0.1 x 50 = 4 N m/A); on a voltage
    drive, whose channel gain is 1 (V into the motor), the model's stall torque per volt
    eta Kg Km / R = 1 x 50 x 0.1 / 1.5 = 3.333 N m/V. Taking the volts for N m made the friction
    probes of a 70:1 servo 8x too large, and the diagnosis named viscous friction for a Coulomb one."""
    from watflex_sim.rigdesc import load_rig

    rig = RIG.format(link=LINK)
    if drive == "voltage":
        rig = rig.replace('drive = { type = "current", actuator = "shoulder_motor", torque_constant = 0.1, efficiency = 0.8, '
                          'limit = 2.0, bits = 12 }', f"drive = {VOLTAGE_DRIVE}").replace('unit = "A", kind = "command"',
                                                                                      'unit = "V", kind = "command"')
    (tmp_path / "labarm").mkdir()
    (tmp_path / "labarm" / "rig.toml").write_text(rig)
    per_unit = load_rig(str(tmp_path / "labarm" / "rig.toml")).effort_per_unit("current_cmd")
    assert per_unit == pytest.approx(4.0 if drive == "current" else 50 * 0.1 / 1.5, rel=1e-5)  # the MJCF text keeps 6 digits
