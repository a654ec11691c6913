"""A rig file that `extends` another names only what differs (a lab's own file layout, its controller), and the lab's
files are then read as they are: the Quanser 2DSFL's lab runs (tests/data/quanser_2dsfl/lab/, SOURCE.md there) through
rigs/quanser_2dsfl_lab_lqg.toml and rigs/quanser_2dsfl_lab_hinf.toml."""
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from watflex_sim.model import ConfigError
from watflex_sim.recording import read_recording
from watflex_sim.rigdesc import load_rig

from test_recording import save_v73
from test_rig_folder import make_rig

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "tests" / "data" / "quanser_2dsfl" / "lab"

CHILD = """extends = "../myrig/rig.toml"
description = "the same rig, its carriage noisier"
[channels]
qm = { unit = "m", kind = "measured", joint = "carriage", noise = 5e-6 }
[parameters]
carriage_damping = { knob = "damping", target = "carriage", tolerance = 0.5 }
"""


def test_a_rig_file_extends_another_naming_only_what_differs(tmp_path, monkeypatch):
    """The child (another folder) takes the base's model (its own file, beside the base), sensors, controller and
    sidecar; its [channels] and [parameters] are merged entry by entry (qm's noise its own, the other channels the
    base's), any other key it sets replaces the base's; its name is its own."""
    monkeypatch.setenv("WATFLEX_RIGS", "")
    base = load_rig(str(make_rig(tmp_path / "myrig")))
    (tmp_path / "variant").mkdir()
    (tmp_path / "variant" / "rig.toml").write_text(CHILD)
    child = load_rig(str(tmp_path / "variant"))
    assert child.name == "variant" and base.name == "myrig"
    assert child.model_path == base.model_path == (tmp_path / "myrig" / "myrig.xml").resolve()
    assert child.channels["qm"]["noise"] == 5e-6 and base.channels["qm"]["noise"] == 2e-6
    others = {c: s for c, s in base.channels.items() if c != "qm"}
    assert {c: s for c, s in child.channels.items() if c != "qm"} == others
    assert set(child.parameters) == set(base.parameters) | {"carriage_damping"}
    assert child.controller == base.controller and child.sidecar == base.sidecar and child.effects == base.effects
    assert child.description == "the same rig, its carriage noisier" != base.description
    sidecar = '[sidecar]\nformat = "flexarm-recording/1"\nrig = "variant"\n'
    (tmp_path / "variant" / "rig.toml").write_text(CHILD + sidecar)
    assert load_rig(str(tmp_path / "variant")).sidecar == {"format": "flexarm-recording/1", "rig": "variant"}


@pytest.mark.parametrize("extends, match", [
    ('"nosuchrig"', r"variant\.toml: extends: unknown rig 'nosuchrig'"),
    ('"variant.toml"', r"variant\.toml: extends 'variant\.toml', which extends it again \(a cycle\)"),
    ('"loop.toml"', r"extends 'variant\.toml', which extends it again \(a cycle\)"),
    ("3", r"variant\.toml: extends must name a rig or a rig file, got 3"),
])
def test_a_bad_base_is_one_line_naming_the_file(tmp_path, monkeypatch, extends, match):
    monkeypatch.setenv("WATFLEX_RIGS", "")
    (tmp_path / "variant.toml").write_text(f"extends = {extends}\n")
    (tmp_path / "loop.toml").write_text('extends = "variant.toml"\n')
    with pytest.raises(ConfigError, match=match):
        load_rig(str(tmp_path / "variant.toml"))


def test_the_labs_files_are_read_as_the_lab_logged_them():
    """rigs/quanser_2dsfl_lab_lqg.toml reads a lab file's matrix columns (X1_meas: hub 1, link 1 in rad; X1_ref) and its
    time, passing over its text variables (the controller's name); the H-infinity rig extends the LQG's, so it reads
    the same layout. Both controllers are the lab's own state spaces, to the last digit of orr_controllers.mat."""
    saved = scipy.io.loadmat(LAB / "orr_controllers.mat", squeeze_me=True)
    for controller in ("lqg", "hinf"):
        rig = load_rig(f"quanser_2dsfl_lab_{controller}")
        run = scipy.io.loadmat(LAB / f"{controller}_step_10deg_run01.mat", squeeze_me=True)
        rec = read_recording(LAB / f"{controller}_step_10deg_run01.mat", sidecar=rig.sidecar)
        assert isinstance(run["controller"], str) and rec.rig == f"quanser_2dsfl_lab_{controller}"
        assert np.array_equal(rec.time, run["time"]) and math.isclose(rec.time[1], 0.002)
        assert np.array_equal(rec.channels["hub1"], run["theta11"])
        assert np.array_equal(rec.channels["link1"], run["theta12"])
        assert np.array_equal(rec.channels["hub1_reference"], run["X1_ref"][:, 0])
        stage_1 = rig.controller["parts"][0]
        for name in "ABCD":
            assert np.array_equal(np.atleast_2d(stage_1[name]), np.atleast_2d(saved[f"{controller}_ss"][name].item()))
        assert stage_1["limits"] == [saved[f"{controller}_ss"]["umax"].item()]
        assert stage_1["period_s"] == saved["Ts_ctrl"]
        assert rig.mat_channels == load_rig("quanser_2dsfl_lab_lqg").mat_channels
        base = load_rig("quanser_2dsfl")
        assert rig.channels == base.channels and rig.datasheet == base.datasheet


def test_a_labs_file_saved_as_v73_reads_as_the_v5_file_does(tmp_path):
    """The same lab run saved by MATLAB's `save -v7.3` (HDF5; tests/test_recording.py save_v73 writes it as MATLAB
    does) reads through the lab's rig file to the same samples, its matrix columns picked from arrays HDF5 keeps
    transposed."""
    rig = load_rig("quanser_2dsfl_lab_lqg")
    saved = scipy.io.loadmat(LAB / "lqg_step_10deg_run01.mat")
    save_v73(tmp_path / "lqg_step_10deg_run01.mat", {k: str(v[0]) if v.dtype.kind == "U" else v
                                                      for k, v in saved.items() if not k.startswith("__")})
    v5 = read_recording(LAB / "lqg_step_10deg_run01.mat", sidecar=rig.sidecar)
    v73 = read_recording(tmp_path / "lqg_step_10deg_run01.mat", sidecar=rig.sidecar)
    assert np.array_equal(v73.time, v5.time) and set(v73.channels) == set(v5.channels) == {"hub1_reference", "hub1",
                                                                                             "link1"}
    assert all(np.array_equal(v73.channels[c], v5.channels[c]) for c in v5.channels)
