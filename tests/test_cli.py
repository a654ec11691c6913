"""The command line as a user meets it: outputs of `run`, one-line errors with exit 2, nothing half-written."""
import json

import numpy as np
import pytest

from watflex_sim.cli import EXIT_BAD_INPUT, EXIT_DIVERGED, main
from watflex_sim.recording import read_recording
from watflex_sim.rerun_log import read_rrd_channels
from watflex_sim.scenario import available


def test_run_writes_recording_plot_and_rrd(tmp_path, capsys):
    assert main(["run", "laser_arm_step", "--out", str(tmp_path), "--set", "payload_kg=1.15",
                 "--set", "direction=negative", "--set", "controller.kp=0.1"]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["laser_arm_step.csv", "laser_arm_step.json", "laser_arm_step.png", "laser_arm_step.rrd"]
    rec = read_recording(tmp_path / "laser_arm_step.csv")
    # rigs.md §1: 1.0 s recorded at the 1 ms control period
    assert rec.time.size == 1000 and np.allclose(np.diff(rec.time), 1e-3)
    assert set(rec.channels) == {"reference", "hub_angle", "tip_sensor", "voltage_cmd", "motor_current"}
    assert rec.meta["payload_kg"] == 1.15 and rec.meta["controller"] == {"type": "pd_tip", "kp": 0.1, "kd": 0.0}
    assert rec.channels["reference"][-1] == pytest.approx(-0.0025 / 1.18)  # rigs.md: theta_c = -0.0025/L
    # the .rrd holds every channel with every sample
    assert read_rrd_channels(tmp_path / "laser_arm_step.rrd") == {c: 1000 for c in rec.channels}


def test_watflex_run_has_camera_at_25_hz(tmp_path):
    assert main(["run", "watflex_elbow_step", "--out", str(tmp_path), "--no-rrd", "--no-plot",
                 "--set", "duration_s=1.0"]) == 0
    rec = read_recording(tmp_path / "watflex_elbow_step.csv")
    # rigs.md §3: camera at 25 Hz -> 25 samples in 1 s, the rest missing
    assert np.isfinite(rec.channels["tip_x"]).sum() == 25
    # rigs.md §2: shoulder held at 0 in the elbow experiment
    assert np.all(rec.channels["shoulder_angle"] == 0.0)
    assert json.loads((tmp_path / "watflex_elbow_step.json").read_text())["locked_joints"] == {"shoulder": 0.0}


@pytest.mark.parametrize(
    "args, message",
    [
        (["run", "nope", "--out", "{out}"], "no scenario 'nope'"),
        (["run", "laser_arm_step", "--out", "{out}", "--set", "bogus=1"], "unknown scenario parameter 'bogus'"),
        (["run", "laser_arm_step", "--out", "{out}", "--set", "payload_kg=heavy"], "must be a number"),
        (["run", "laser_arm_step", "--out", "{out}", "--set", "payload_kg=-1"], "payload_kg must be a finite number in [0, 5] kg"),
        (["run", "laser_arm_step", "--out", "{out}", "--set", "timestep=0.0003"], "not a whole multiple"),
        (["run", "laser_arm_step", "--out", "{out}", "--set", "direction=up"], "direction must be"),
        (["run", "laser_arm_step", "--out", "{out}", "--set", "controller.type=magic"], "unknown controller type"),
        (["run", "watflex_elbow_step", "--out", "{out}", "--set", "locked_joints={wrist=0.0}"], "cannot lock 'wrist'"),
        (["plot", "{out}/missing.csv"], "missing.csv"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert main([a.replace("{out}", str(out)) for a in args]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists() or not any(out.iterdir())


def test_diverging_run_is_reported_not_written(tmp_path, capsys):
    # The stiff laser-arm beam is unstable at 1 ms (README "Time step"): the run must stop cleanly.
    assert main(["run", "laser_arm_step", "--out", str(tmp_path), "--set", "timestep=0.001"]) == EXIT_DIVERGED
    err = capsys.readouterr().err
    assert "diverged (detected at t =" in err and err.count("\n") == 1
    assert not any(tmp_path.iterdir())


def test_view_without_display_exits_2(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "laser_arm_step"]) == EXIT_BAD_INPUT
    assert "no display" in capsys.readouterr().err


def test_list_names_every_scenario(capsys):
    assert main(["list"]) == 0
    assert capsys.readouterr().out.split() == available()
    assert {"laser_arm_step", "watflex_elbow_staircase", "watflex_elbow_step", "watflex_elbow_triangle"} <= set(available())


def test_plot_compares_a_recording_with_the_nominal_and_a_patched_model(tmp_path, capsys):
    """`plot --simulate` re-simulates a recording on the nominal model, `--patch` also on a diagnosis' model (one
    found on other recordings): NRMSE per channel printed, both overlaid. A noise-free run of our own model is
    re-simulated to NRMSE < 1e-3 (the same physics); with 0.5 kg more at the tip, the patched model is further off."""
    assert main(["run", "laser_arm_step", "--out", str(tmp_path), "--no-rrd", "--no-plot", "--set", "noise=false"]) == 0
    patch = tmp_path / "patch.json"
    patch.write_text(json.dumps({"effects": [{"effect": "payload", "where": "tip", "mass": 0.5}], "parameters": {}}))
    capsys.readouterr()
    assert main(["plot", str(tmp_path / "laser_arm_step.csv"), "--patch", str(patch)]) == 0
    lines = capsys.readouterr().out.splitlines()
    means = {line.split()[0]: float(line.rsplit("mean ", 1)[1]) for line in lines if "model: NRMSE" in line}
    assert set(means) == {"nominal", "patched"} and means["nominal"] < 1e-3 < 0.05 < means["patched"]
    assert (tmp_path / "laser_arm_step.png").is_file()
    patch.write_text("{}")
    assert main(["plot", str(tmp_path / "laser_arm_step.csv"), "--patch", str(patch)]) == EXIT_BAD_INPUT
    assert "not a diagnosis patch.json" in capsys.readouterr().err
