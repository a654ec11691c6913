"""A rig we did not build: the Quanser 2DSFL from its description alone (issue 15 item 7).

Data: tests/data/quanser_2dsfl/ (Quanser's Results/data_{fsf,psf}_*.mat, from
basta/quanser-2-dof-serial-flexible-link @ 48ab0ce, MIT; see LICENSE and SOURCE.md there).
Reference figures: the ABOUT.md of the team's realdata/quanser_2dsfl folder, not shipped (the published gains reproduce
the fsf current command within 2-3 %; hub 2 stops 0.8-1.2 deg short of its +-10 deg target).
"""
import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import solve_continuous_are

from watflex_sim import datasheet
from watflex_sim.controllers.state_feedback import StateFeedback
from watflex_sim.cli import EXIT_BAD_INPUT, main
from watflex_sim.recording import RecordingError, read_recording
from watflex_sim.resim import resimulate
from watflex_sim.rigdesc import load_rig

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "quanser_2dsfl"
RIG = tomllib.loads((ROOT / "rigs" / "quanser_2dsfl.toml").read_text())
DEG = math.pi / 180


STAGES = load_rig("quanser_2dsfl").datasheet["stages"]


def recording(run: str):
    return read_recording(DATA / f"data_{run}_th11.mat")


def test_the_model_generated_from_the_datasheet_has_quansers_numbers():
    """config_2dslf.m: Ks1_th = 40.0, Ks2_th = 6.9 N m/rad (E w t^3 / 4 L); J11 = Kg1^2 Jm1 + J1fix = 0.0635,
    J21 = 0.00302 kg m^2; Ktg = 0.75 Kt Kg = 8.925 / 0.870 N m/A, the command channels' gains."""
    model = load_rig("quanser_2dsfl").spec().compile()
    assert model.joint("link1_j01").stiffness[0] == pytest.approx(40.0, rel=2e-3)
    assert model.joint("link2_j01").stiffness[0] == pytest.approx(6.86, rel=2e-3)
    assert model.joint("drive1").armature[0] == pytest.approx(0.0635, rel=2e-3)
    assert model.joint("drive2").armature[0] == pytest.approx(0.00302, rel=2e-3)
    assert [datasheet.torque_per_amp(s) for s in STAGES] == pytest.approx([8.925, 0.870], rel=1e-9)


def test_datasheet_reproduces_the_published_lqr_gains():
    """setup_2dsfl.m: lqr(A, B, diag(2500, 1, 1, 100 | 50), 10) on the manual's stage models gives
    K1 = [15.81, -42.93, 2.18, -0.71], K2 = [15.81, -40.33, 0.42, -0.71] (the rig's [controller]):
    the datasheet's inertias (Kg^2 Jm + Jfix, not the stale comments 0.0109 / 0.0090) are Quanser's."""
    link2 = STAGES[1]["link"]
    j22 = datasheet.tip_inertia(link2) + link2["tip_mass"] * link2["tip_distance"] ** 2
    stages = ((1, STAGES[0]["link"]["total_inertia"], STAGES[0]["link"]["damping"], 100.0), (2, j22, link2["damping"], 50.0))
    for (n, j_link, b_link, q_rate), row in zip(stages, RIG["controller"]["gains"]):
        stage = STAGES[n - 1]
        j_hub, ks, b_hub, ktg = datasheet.armature(stage), stage["link"]["stiffness"], stage["damping"], datasheet.torque_per_amp(stage)
        s = (j_hub + j_link) / (j_hub * j_link)
        A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [0, ks / j_hub, -b_hub / j_hub, b_link / j_hub],
                      [0, -s * ks, b_hub / j_hub, -b_link * s]])
        B = np.array([[0], [0], [ktg / j_hub], [-ktg / j_hub]])
        P = solve_continuous_are(A, B, np.diag([2500.0, 1.0, 1.0, q_rate]), np.array([[10.0]]))
        gains = (B.T @ P / 10.0).ravel()
        published = row[4 * (n - 1): 4 * n]
        assert gains == pytest.approx(published, rel=3e-3, abs=6e-3)


def test_recordings_read_as_they_come():
    rec = recording("fsf")
    assert rec.rig == "quanser_2dsfl" and rec.time.size == 9719
    assert np.diff(rec.time) == pytest.approx(0.002)
    assert rec.channels["hub2"][-1] == pytest.approx(9.92109375 * DEG)  # data_th21(end, 3), deg
    assert rec.channels["current1_cmd"][-1] == pytest.approx(-0.05995095469662959)  # data_Im1(end, 2), A
    assert set(rec.channels) == set(RIG["mat_channels"])


def test_missing_file_or_variable_names_it(tmp_path):
    for f in DATA.glob("data_fsf_*"):
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "data_fsf_th22.mat").unlink()
    with pytest.raises(RecordingError, match=r"data_fsf_th22\.mat: file not found"):
        read_recording(tmp_path / "data_fsf_th11.mat")
    shutil.copy(DATA / "data_fsf_th21.mat", tmp_path / "data_fsf_th22.mat")  # holds data_th21, not data_th22
    with pytest.raises(RecordingError, match=r"data_fsf_th22\.mat: no variable 'data_th22' \(for 'link2'\)"):
        read_recording(tmp_path / "data_fsf_th11.mat")
    (tmp_path / "other.mat").write_bytes(b"")
    assert main(["diagnose", str(tmp_path / "other.mat"), "--rig", "quanser_2dsfl", "--report", str(tmp_path / "r")]) == EXIT_BAD_INPUT


@pytest.mark.parametrize("run, method, limit", [
    ("fsf", "euler", (0.014, 0.016)), ("psf", "euler", (0.007, 0.005)),  # measured 1.22 / 1.38 %, 0.58 / 0.36 %
    ("fsf", "backward_diff", (0.055, 0.026)), ("psf", "backward_diff", (0.06, 0.02)),  # 4.95 / 2.32 %, 5.47 / 1.74 %
])
def test_the_law_as_data_reproduces_the_recorded_command(run, method, limit):
    """The sidecar's law on the recorded states gives the recorded current command (rms error over
    the command's rms); forward Euler, the rig file's rate filter, does it best of the discretisations."""
    rec = recording(run)
    spec = dict(rec.meta["controller"])
    spec.pop("type")
    spec["rate_method"] = method
    law = StateFeedback(**spec, period=0.002)
    law.reset()
    names = law.channels()
    out = [law(t, {c: rec.channels[c][k] for c in names}) for k, t in enumerate(rec.time)]
    for command, lim in zip(("current1_cmd", "current2_cmd"), limit):
        u, rec_u = np.array([o[command] for o in out]), rec.channels[command]
        assert np.sqrt(np.mean((u - rec_u) ** 2)) / np.sqrt(np.mean(rec_u**2)) < lim


def test_nominal_model_reaches_the_target_the_rig_stops_short_of():
    """What the data visibly shows (ABOUT.md): after hub 1 has moved, hub 2 holds 0.8-1.2 deg
    short of +-10 deg with 0.27-0.32 A commanded (0.5-1 s before each of its steps at 8, 13,
    18 s); the nominal model (no friction) holds within 0.1 deg of it, with under 0.05 A."""
    rec = recording("fsf")
    sim = resimulate(rec)
    for start in (7.0, 12.0, 17.0):
        window = (rec.time >= start) & (rec.time < start + 0.5)
        ref = rec.channels["hub2_reference"][window]
        short = np.abs(ref - rec.channels["hub2"][window]) / DEG
        assert 0.75 < short.mean() < 1.25 and 0.25 < np.abs(rec.channels["current2_cmd"][window]).mean() < 0.33
        assert np.abs(ref - sim.channels["hub2"][window]).mean() / DEG < 0.1
        assert np.abs(sim.channels["current2_cmd"][window]).mean() < 0.05


def test_the_engine_runs_at_the_rigs_period_and_checks_the_laws_channels():
    from watflex_sim.engine import simulate
    from watflex_sim.model import ConfigError
    from watflex_sim.resim import scenario_from_recording

    scenario = scenario_from_recording(recording("fsf"))
    scenario["duration_s"] = 0.02
    assert np.diff(simulate(scenario).recording.time) == pytest.approx(0.002)  # control_period_s, not 1 ms
    scenario["control_period_s"] = 0.001  # a sidecar may say otherwise
    assert np.diff(simulate(scenario).recording.time) == pytest.approx(0.001)
    scenario["controller"]["states"][1] = "link_1"
    with pytest.raises(ConfigError, match="reads unknown channel.s. of quanser_2dsfl: link_1"):
        simulate(scenario)


def test_recording_files_of_different_lengths_name_the_file(tmp_path):
    from scipy.io import savemat

    for f in DATA.glob("data_fsf_*.mat"):
        shutil.copy(f, tmp_path / f.name)
    savemat(tmp_path / "data_fsf_Im2.mat", {"data_Im2": np.zeros((100, 3))})
    with pytest.raises(RecordingError, match=r"data_fsf_Im2\.mat: variable 'data_Im2' has 100 samples, the time .data_fsf_th11\.mat. has 9719"):
        read_recording(tmp_path / "data_fsf_th11.mat", sidecar=load_rig("quanser_2dsfl").sidecar)


@pytest.mark.slow
def test_diagnosis_finds_the_soft_link_but_not_the_friction_at_drive_2():
    """`diagnose` on the fsf run (fitted) and the psf run (held out), both cropped to their first
    10 s to keep the test under a minute (45 s on 2 cores; the full runs give the same answer, README
    "A rig we did not build"). It finds link 2 softer than beam theory, near Quanser's own
    torque-impulse value Ks2_exp = 2.5 N m/rad (config_2dslf.m; found 2.50, full runs 2.46), and
    ranks an effect at a drive next but below the bar although the data show drive 2 sticking: drive
    2's dry friction (training 2.5 %, held-out 2.7 %) until d1d1747, its backlash (3.4 %, 2.7 %) until
    each recording's split was salted with its content (2026-11-27), drive 1's joint compliance then
    (23 % of the validation excess against the 25 % bar), as on the full runs (docs/rigs.md), drive 2's
    viscous friction since the blocks are split in pairs (training 2.5 %, validation 1.4 %; its Coulomb
    friction next), drive 2's backlash since a later finding far from the noise pays its parameters instead
    (validate.far_gain, 2026-12-04: 2.5 % / 2.6 %, under the 4 % its two parameters cost; the full runs take drive
    1's compliance there, docs/rigs.md). This test pins that disagreement, it does not endorse it."""
    from watflex_sim.diagnosis import diagnose
    from watflex_sim.recording import Recording

    recs = []
    for run in ("fsf", "psf"):
        rec = recording(run)
        keep = rec.time < 10.0
        recs.append(Recording(rec.time[keep], {c: v[keep] for c, v in rec.channels.items()}, rec.meta))
    report = diagnose(recs, ["fsf", "psf"], workers=2, max_effects=2)
    assert [(f["effect"], f["where"]) for f in report["findings"]] == [("link_stiffness_change", "link2")]
    ks2 = STAGES[1]["link"]["stiffness"] * report["findings"][0]["parameters"]["ratio"] \
        * report["refit_parameters"]["link2_stiffness"]  # a ratio to nominal
    assert ks2 == pytest.approx(2.5, rel=0.2)
    assert report["held_out"]["after"]["nrmse"] < 0.95 * report["held_out"]["before"]["nrmse"]
    best_rejected = report["rejected"][0]
    assert best_rejected["where"] in ("drive1", "drive2") and best_rejected["effect"] in (
        "coulomb_friction", "stribeck_friction", "viscous_friction", "backlash", "joint_compliance")
