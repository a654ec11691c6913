"""A rig is a folder a user owns (issue 15, item 1): rig.toml + its MJCF model anywhere on disk,
found by --rig PATH or WATFLEX_RIGS, with no line of code naming it; bad rig files are one line, exit 2."""
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from watflex_sim import load_scenario, simulate
from watflex_sim.cli import EXIT_BAD_INPUT, main
from watflex_sim.model import ROOT, ConfigError
from watflex_sim.recording import read_recording
from watflex_sim.rigdesc import known_rigs, load_rig

SCENARIO = """rig = "myrig"
experiment = "myrig_moves"
duration_s = 2.0
reference = {{ channel = "qg", kind = "triangle", amplitude = 0.02, slope = 0.04, periods = 1 }}
effects = [{effects}]
[controller]
type = "cascade_p"
kp = 160.18
kv = 243.45
"""
FRICTION = '{ effect = "coulomb_friction", where = "carriage", torque_positive = 20.0, torque_negative = 20.0 }'


def make_rig(folder: Path, edit=lambda text: text) -> Path:
    """A copy of the bundled EMPS rig renamed `myrig`, its model beside it as myrig.xml."""
    folder.mkdir(parents=True)
    text = (ROOT / "rigs" / "emps.toml").read_text()
    text = text.replace('name = "emps"', 'name = "myrig"').replace('model = "emps"', 'model = "myrig.xml"')
    text = text.replace('rig = "emps"', 'rig = "myrig"')
    (folder / "rig.toml").write_text(edit(text))
    shutil.copy(ROOT / "models" / "emps.xml", folder / "myrig.xml")
    return folder


@pytest.fixture()
def rigdir(tmp_path, monkeypatch):
    monkeypatch.setenv("WATFLEX_RIGS", "")  # --rig PATH writes it; restored after the test
    return make_rig(tmp_path / "lab" / "myrig")


def test_folder_rig_runs_and_is_diagnosed_from_the_command_line(rigdir, tmp_path, capsys):
    """Simulated with --rig PATH, the folder rig gives the bundled EMPS rig's recording to the CSV's 10
    digits (same model, sensors, controller, seed); its sidecar says "myrig", and the diagnosis of it
    with --rig PATH (two worker processes) finds the Coulomb friction put in (20 N) within 10 %."""
    scenario = tmp_path / "moves.toml"
    scenario.write_text(SCENARIO.format(effects=FRICTION))
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--rig", str(rigdir), "--out", str(out), "--no-rrd", "--no-plot"]) == 0
    rec = read_recording(out / "moves.csv")
    assert rec.rig == "myrig" and set(rec.channels) == {"qg", "qm", "vir", "pulses_N"}
    same = simulate(load_scenario(str(scenario), ['rig="emps"'])).recording
    for channel in ("qm", "vir"):
        np.testing.assert_allclose(rec.channels[channel], same.channels[channel], rtol=1e-9, atol=1e-15)  # CSV: .10g

    report = tmp_path / "report"
    assert main(["diagnose", str(out / "moves.csv"), "--rig", str(rigdir / "rig.toml"), "--report", str(report),
                 "--workers", "2", "--max-effects", "1", "--no-rrd"]) == 0
    found = json.loads((report / "report.json").read_text())
    assert [f["effect"] for f in found["findings"]] == ["coulomb_friction"]
    p = found["findings"][0]["parameters"]
    assert 0.5 * (p["torque_positive"] + p["torque_negative"]) == pytest.approx(20.0, rel=0.1)
    assert found["held_out"]["after"]["nrmse"] < found["held_out"]["before"]["nrmse"]


def test_rig_library_from_watflex_rigs(tmp_path, monkeypatch, capsys):
    """WATFLEX_RIGS names folders of rigs; a rig is found by its `name`, whatever its folder is called;
    other TOML files there (a scenario) are not rigs."""
    make_rig(tmp_path / "library" / "myrig-v2")
    (tmp_path / "library" / "moves.toml").write_text(SCENARIO.format(effects=""))
    monkeypatch.setenv("WATFLEX_RIGS", os.pathsep.join([str(tmp_path / "nothing-here"), str(tmp_path / "library")]))
    rig = load_rig("myrig")
    assert rig.name == "myrig" and rig.model_path == tmp_path / "library" / "myrig-v2" / "myrig.xml"
    assert {"myrig", "emps", "laser_arm", "watflex"} <= set(known_rigs()) and "moves" not in known_rigs()
    assert main(["list", "--rigs"]) == 0
    assert f"myrig  {tmp_path / 'library' / 'myrig-v2' / 'rig.toml'}" in capsys.readouterr().out.splitlines()
    assert load_rig("emps").source == str((ROOT / "rigs" / "emps.toml").resolve())  # bundled rigs still there


def test_unknown_rig_name_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("WATFLEX_RIGS", "")
    scenario = tmp_path / "moves.toml"
    scenario.write_text(SCENARIO.format(effects=""))
    assert main(["run", str(scenario), "--out", str(tmp_path / "o")]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown rig 'myrig'" in err[0] and "WATFLEX_RIGS" in err[0]


BAD = {  # what is wrong -> (edit of rig.toml, words the one-line error must hold)
    "unknown key": (lambda t: t.replace('sensors = "generic"', 'sensors = "generic"\nsensor = "typo"'), ["sensor"]),
    "missing model file": (lambda t: t.replace('"myrig.xml"', '"gone.xml"'), ["model", "gone.xml"]),
    "wrong unit kind": (lambda t: t.replace('qm = { unit = "m"', 'qm = { unit = "rad"'), ["qm", "'rad'", "carriage"]),
    "unknown unit": (lambda t: t.replace('vir = { unit = "V"', 'vir = { unit = "volts"'), ["vir", "volts"]),
    "unknown channel in a controller": (lambda t: t.replace('position = "qm"', 'position = "qx"', 1),
                                        ["controller.position", "qx"]),
    "unknown joint": (lambda t: t.replace('joint = "carriage", noise', 'joint = "cart", noise'), ["qm", "cart"]),
    "bad TOML": (lambda t: t + "\n[channels\n", ["cannot read"]),
    "unknown channel in columns": (lambda t: t + '\n[columns]\n"q (mm)" = { channel = "q", scale = 1e-3 }\n',
                                   ["columns", "'q (mm)'", "'q'"]),
}


@pytest.mark.parametrize("what", BAD)
def test_bad_rig_file_is_one_line_naming_file_and_key(what, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("WATFLEX_RIGS", "")
    edit, words = BAD[what]
    folder = make_rig(tmp_path / "myrig", edit)
    scenario = tmp_path / "moves.toml"
    scenario.write_text(SCENARIO.format(effects=""))
    assert main(["run", str(scenario), "--rig", str(folder), "--out", str(tmp_path / "o")]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(folder / "rig.toml") in err[0], err
    assert all(w in err[0] for w in words), err
    assert not (tmp_path / "o").exists()


def test_a_rig_loaded_by_path_resolves_by_name_in_a_fresh_process(rigdir):
    """use_rig(PATH) (what --rig PATH does) reaches processes that share no memory with this one
    (spawned or forkserver workers): the name resolves to the same file there."""
    import subprocess
    import sys

    from watflex_sim.rigdesc import use_rig

    source = use_rig(str(rigdir)).source
    child = subprocess.run([sys.executable, "-c", "from watflex_sim.rigdesc import load_rig; print(load_rig('myrig').source)"],
                           capture_output=True, text=True, timeout=120)
    assert child.returncode == 0, child.stderr
    assert child.stdout.strip() == source == str(rigdir / "rig.toml")


def test_the_simulation_path_receives_the_rig(rigdir, monkeypatch):
    """A rig is loaded once into one object (issue 15, item 1): given it, the engine, the lockstep
    driver and re-simulation set up and run without resolving any rig by name (a lookup here fails)."""
    import watflex_sim.rigdesc as rigdesc
    from watflex_sim.resim import resimulate, resimulate_many

    rig = rigdesc.use_rig(str(rigdir))  # as --rig PATH: the scenario's "myrig" resolves to it
    path = rigdir.parent / "moves.toml"
    path.write_text(SCENARIO.format(effects=FRICTION))
    scenario = load_scenario(path)
    scenario["duration_s"] = 0.2
    rec = simulate(scenario, rig=rig).recording
    with pytest.raises(ConfigError, match="scenario of rig 'myrig' given the rig 'emps'"):
        simulate(scenario, rig=load_rig("emps"))

    def no_lookup(*args):
        raise AssertionError(f"rig looked up by name: {args}")

    monkeypatch.setattr(rigdesc, "_load", no_lookup)
    monkeypatch.setattr(rigdesc, "rig_file", no_lookup)
    again = simulate(scenario, rig=rig).recording
    assert all(np.array_equal(again.channels[c], rec.channels[c]) for c in rec.channels)
    assert set(resimulate(rec, rig=rig).channels) == set(rec.channels)
    sims = resimulate_many([(rec, [], {}, None, None), (rec, [], {}, 0.1, 3)], nthread=1, rig=rig)
    assert [set(s.channels) for s in sims] == [set(rec.channels)] * 2


COLUMNS = '''
[columns]                 # the lab's own export: names, mm, ms
"Time [ms]" = { channel = "time", scale = 0.001 }
"q_ref (mm)" = { channel = "qg", scale = 0.001 }
"q_m (mm)" = { channel = "qm", scale = 0.001 }
"u (V)" = "vir"
"T (C)" = ""              # a column the recording does not use
t_ms = { channel = "time", scale = 0.001 }
q_ref_mm = { channel = "qg", scale = 0.001 }
q_m_mm = { channel = "qm", scale = 0.001 }
u_V = "vir"
'''


def test_a_lab_text_export_is_read_through_the_rig_columns(tmp_path, monkeypatch):
    """Recordings as users have them (issue 15, item 6): tab- or space-separated text with the lab's
    column names, mm and ms, mapped by the rig's [columns]; read, they equal the contract CSV they
    were written from (to the 10 digits written); a bad cell names the line and the file's column."""
    from watflex_sim.recording import RecordingError

    monkeypatch.setenv("WATFLEX_RIGS", "")
    folder = make_rig(tmp_path / "myrig", lambda t: t + COLUMNS)
    (tmp_path / "moves.toml").write_text(SCENARIO.format(effects=""))
    main(["run", str(tmp_path / "moves.toml"), "--rig", str(folder), "--out", str(tmp_path / "sim"), "--no-rrd"])
    csv_path = next((tmp_path / "sim").glob("*.csv"))
    rec = read_recording(csv_path)
    rows = np.column_stack([rec.time * 1e3, rec.channels["qg"] * 1e3, rec.channels["qm"] * 1e3, rec.channels["vir"],
                            np.full(rec.time.size, 21.5)])
    exports = {
        "tabs.tsv": "# exported by the lab PC\n" + "\t".join(["Time [ms]", "q_ref (mm)", "q_m (mm)", "u (V)", "T (C)"]) + "\n"
                    + "".join("\t".join(format(x, ".10g") for x in row) + "\n" for row in rows),
        "spaces.txt": "% t in ms\n" + "   t_ms   q_ref_mm   q_m_mm   u_V\n"
                      + "".join("  ".join(format(x, ".10g") for x in row[:4]) + "\n" for row in rows),
    }
    for name, text in exports.items():
        path = tmp_path / name
        path.write_text(text)
        path.with_suffix(".json").write_text(csv_path.with_suffix(".json").read_text())
        got = read_recording(path)
        assert set(got.channels) == {"qg", "qm", "vir"}, name
        assert np.allclose(got.time, rec.time, rtol=1e-9, atol=1e-12), name
        for c in got.channels:
            assert np.allclose(got.channels[c], rec.channels[c], rtol=1e-9, atol=1e-15), (name, c)
    bad = tmp_path / "bad.tsv"
    bad.write_text(exports["tabs.tsv"].replace("\n" + "\t".join(format(x, ".10g") for x in rows[3]),
                                               "\n" + "\t".join(format(x, ".10g") for x in rows[3][:2]) + "\tn/a\t0\t0", 1))
    bad.with_suffix(".json").write_text(csv_path.with_suffix(".json").read_text())
    with pytest.raises(RecordingError, match=r"bad\.tsv: line 6, column 'q_m \(mm\)': 'n/a' is not a number$"):
        read_recording(bad)


def test_a_scenario_without_a_controller_runs_the_rigs_own(rigdir):
    """A scenario that names no [controller] runs the rig file's [controller] (its law, its gains);
    the recording's sidecar names it, so the diagnosis re-runs the same law."""
    from watflex_sim.rigdesc import use_rig

    rig = use_rig(str(rigdir))
    path = rigdir.parent / "moves.toml"
    path.write_text(SCENARIO.format(effects="").split("[controller]")[0])
    scenario = load_scenario(path)
    assert scenario["controller"] == rig.controller and rig.controller["type"] == "cascade_p"
    assert simulate(dict(scenario, duration_s=0.05)).recording.meta["controller"] == rig.controller


def test_the_rotary_flexible_link_example_runs_from_its_folder(monkeypatch, tmp_path):
    """examples/rotary_flexible_link (docs/rigs.md): a datasheet rig with a voltage drive, state
    feedback on the link angle and a lab-format [columns] table loads and runs: the +-5 V amplifier
    limits the command (the square wave's edges saturate it) and the hub follows the 0.5 rad steps."""
    from watflex_sim.rigdesc import use_rig

    monkeypatch.setenv("WATFLEX_RIGS", "")
    folder = Path(__file__).resolve().parent.parent / "examples" / "rotary_flexible_link"
    rig = use_rig(str(folder))
    assert rig.effort_per_unit("voltage") == pytest.approx(0.62 * 70 * 7.68e-3 / 2.6, rel=1e-5)
    rec = simulate(load_scenario(folder / "square_with_friction.toml", ["duration_s=2.0", "noise=false"])).recording
    assert np.abs(rec.channels["voltage"]).max() == pytest.approx(5.0)
    assert rec.channels["hub"][int(1.9 / 0.002)] == pytest.approx(0.5, abs=0.05)
