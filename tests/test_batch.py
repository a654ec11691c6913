"""Sweeps (`watflex-sim batch`): sampling, rows and metrics, failed runs as rows, bad files, no lost
work when a worker is killed, the sweep interrupted or killed, and Ray equal to the process pool."""
import importlib.util
import json
import math
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from watflex_sim import load_scenario, simulate
from watflex_sim.batch import Sweep, assign, parse_spec, points, run_metrics, run_sweep
from watflex_sim.cli import EXIT_BAD_INPUT, main
from watflex_sim.metrics import step_metrics
from watflex_sim.model import ConfigError
from watflex_sim.params import LASER_ARM

LASER = 'scenario = "laser_arm_step"\n[fixed]\nnoise = false\n'


def sweep_file(tmp_path, text: str, name: str = "sweep.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def rows(out) -> list[dict]:
    return pq.read_table(out / "results.parquet").to_pylist()


def same(a: dict, b: dict) -> bool:
    """Rows equal but for where and how fast they ran (NaN equal to NaN)."""
    keys = set(a) - {"wall_time_s", "worker"}
    return keys == set(b) - {"wall_time_s", "worker"} and all(
        a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k])) for k in keys)


# ----------------------------------------------------------------------------- sampling


def test_grid_is_every_combination_last_key_fastest():
    specs = {"payload_kg": parse_spec("payload_kg", [0.0, 0.7], "grid"),
             "controller.kp": parse_spec("controller.kp", {"low": 0.1, "high": 0.2, "n": 3}, "grid"),
             "seed": parse_spec("seed", {"low": 1, "high": 2}, "grid")}
    sweep = Sweep({}, specs)
    got = list(points(sweep))
    assert len(got) == 12
    assert got[0] == {"payload_kg": 0.0, "controller.kp": 0.1, "seed": 1}
    assert got[1] == {"payload_kg": 0.0, "controller.kp": 0.1, "seed": 2}
    assert [p["controller.kp"] for p in got[:6:2]] == pytest.approx([0.1, 0.15, 0.2])


def test_lhs_puts_one_sample_in_every_stratum_and_seed_reproduces():
    specs = {"a": parse_spec("a", {"low": 0.0, "high": 1.0}, "lhs"),
             "b": parse_spec("b", {"low": 1e-3, "high": 1e3, "log": True}, "lhs"),
             "c": parse_spec("c", {"mean": 5.0, "std": 0.5}, "lhs")}
    draw = list(points(Sweep({}, specs, "lhs", 50, seed=3)))
    assert draw == list(points(Sweep({}, specs, "lhs", 50, seed=3)))
    assert draw != list(points(Sweep({}, specs, "lhs", 50, seed=4)))
    assert sorted(int(p["a"] * 50) for p in draw) == list(range(50))  # Latin hypercube: one per stratum
    assert sorted(int((math.log10(p["b"]) + 3) / 6 * 50) for p in draw) == list(range(50))
    assert np.mean([p["c"] for p in draw]) == pytest.approx(5.0, abs=0.05)  # stratified normal


def test_random_integers_cover_both_ends_and_lists_are_drawn_from():
    specs = {"seed": parse_spec("seed", {"low": 0, "high": 3}, "random"),
             "payload_kg": parse_spec("payload_kg", [0.0, 0.7, 1.15], "random")}
    draw = list(points(Sweep({}, specs, "random", 200, seed=0)))
    assert {p["seed"] for p in draw} == {0, 1, 2, 3} and all(isinstance(p["seed"], int) for p in draw)
    assert {p["payload_kg"] for p in draw} == {0.0, 0.7, 1.15}


def test_assign_reaches_into_tables_and_lists_and_refuses_unknown_keys():
    scenario = load_scenario("laser_arm_step")
    assign(scenario, "controller.kp", 0.2)
    assign(scenario, "reference.time_s", 0.2)  # the one reference table
    assign(scenario, "effects", [{"effect": "coulomb_friction", "where": "hub", "torque_positive": 0.1}])
    assign(scenario, "effects.0.torque_positive", 1.5)
    assign(scenario, "parameters.beam_EI", 1.02)  # an open table: created
    assert scenario["controller"]["kp"] == 0.2 and scenario["reference"][0]["time_s"] == 0.2
    assert scenario["effects"] == [{"effect": "coulomb_friction", "where": "hub", "torque_positive": 1.5}]
    for key in ("controller.kpp", "payload", "effects.1.torque_positive", "payload_kg.x"):
        with pytest.raises(ConfigError, match="unknown scenario parameter|is a value"):
            assign(scenario, key, 1.0)


# ----------------------------------------------------------------------------- a sweep


def test_sweep_rows_metrics_failed_runs_and_outputs(tmp_path, capsys):
    path = sweep_file(tmp_path, LASER + "[parameters]\npayload_kg = [0.7]\ntimestep = [0.0001, 0.001]\n"
                      "locked_joints = [{}, {wrist = 0.0}]\n")  # a joint the laser arm has not: fails at set-up
    out = tmp_path / "out"
    assert main(["batch", str(path), "--out", str(out), "--workers", "2", "--keep-recordings"]) == 0
    assert "4 runs done (3 failed), 0 already done" in capsys.readouterr().out
    ok, bad, diverged, _ = rows(out)
    assert [r["status"] for r in (ok, diverged, bad)] == ["ok", "diverged", "error"]
    assert "simulation diverged" in diverged["error"] and "cannot lock 'wrist'" in bad["error"]
    assert math.isnan(diverged["rise_time_s"]) and ok["wall_time_s"] > 0
    # the row's metrics are those of the same run simulated directly (examples/payload_sweep.py)
    rec = simulate(load_scenario("laser_arm_step", ["noise=false", "payload_kg=0.7"])).recording
    tip = LASER_ARM.beam.length * rec.channels["reference"] - rec.channels["tip_sensor"] / LASER_ARM.sensor_gain
    want = step_metrics(rec.time, tip, 0.1, 0.0, LASER_ARM.beam.length * rec.channels["reference"][-1])
    assert {k: ok[k] for k in want} == pytest.approx(want)
    assert ok["rise_time_s"] == pytest.approx(0.061) and ok["settling_time_s"] == pytest.approx(0.208)
    # CSV = parquet; the finished run's recording kept; summary plot written; no temporary files left
    assert pacsv.read_csv(out / "results.csv").to_pylist()[0]["run_id"] == ok["run_id"]
    assert sorted(p.name for p in (out / "recordings").iterdir()) == [f"{ok['run_id']}.csv", f"{ok['run_id']}.json"]
    assert sorted(p.name for p in out.iterdir()) == ["recordings", "results.csv", "results.parquet", "runs.jsonl", "summary.png"]


def test_effect_parameter_sweep_reaches_the_simulation(tmp_path):
    path = sweep_file(tmp_path, LASER + 'duration_s = 0.4\neffects = [{effect = "coulomb_friction", where = "hub", '
                      'torque_positive = 0.0}]\n[parameters]\n"effects.0.torque_positive" = [0.0, 2.5]\n')
    result = run_sweep(path, tmp_path / "out", workers=1, keep_recordings=True, plots=False)
    free, stuck = result.rows
    meta = json.loads((tmp_path / "out" / "recordings" / f"{stuck['run_id']}.json").read_text())
    assert meta["scenario"]["effects"][0]["torque_positive"] == 2.5
    assert stuck["tracking_rms"] > 1.2 * free["tracking_rms"]  # friction holds the hub back


def test_watflex_metrics_strain_and_tip_error_against_rigid_kinematics():
    scenario = load_scenario("watflex_elbow_step", ["noise=false", "duration_s=1.5"])
    m = run_metrics(simulate(scenario).recording, scenario)
    assert m["response"] == "elbow_angle (rad)" and m["peak_strain_V"] > 0.1 and m["tip_error_rms_m"] > 0.01
    # at rest the straight arm's camera reading is the rigid kinematics of the reference
    scenario = load_scenario("watflex_elbow_step", ["noise=false", "duration_s=0.3", "reference.amplitude=0.0"])
    m = run_metrics(simulate(scenario).recording, scenario)
    assert m["tip_error_rms_m"] < 1e-6 and m["peak_strain_V"] < 1e-3


@pytest.mark.parametrize("text, message", [
    ("[parameters]\npayload = [0.0, 1.0]\n", "unknown scenario parameter 'payload'"),
    ('[parameters]\n"controller.kpp" = [0.1]\n', "unknown scenario parameter 'controller.kpp'"),
    ('[parameters]\n"effects.0.torque_positive" = [1.0]\n', "effects has 0 entries"),
    ("[parameters]\npayload_kg = []\n", "empty range"),
    ("[parameters]\npayload_kg = {low = 1.0, high = 0.5, n = 3}\n", "empty range"),
    ('[parameters]\npayload_kg = ["heavy"]\n', "must be a number"),
    ('[parameters]\npayload_kg = {low = "a", high = 2}\n', "must be numbers"),
    ("[parameters]\nseed = [0.5]\n", "seed must be an integer"),
    ("[parameters]\npayload_kg = [0.7, -1.0]\n", "payload_kg must be a finite number in [0, 5] kg"),
    ("[parameters]\ntimestep = [0.0001, 0.0009]\n", "not a whole multiple"),
    ('method = "random"\nsamples = 50\n[parameters]\npayload_kg = {mean = 0.1, std = 0.5}\n', "run "),
    ('method = "sobol"\n[parameters]\npayload_kg = [0.0]\n', "method must be one of"),
    ('method = "lhs"\n[parameters]\npayload_kg = {low = 0.0, high = 1.0}\n', "needs samples"),
    ("samples = 3\n[parameters]\npayload_kg = [0.0]\n", "'samples' is for method random or lhs"),
    ("sampels = 3\n[parameters]\npayload_kg = [0.0]\n", "unknown sweep key(s) sampels"),
    ("[parameters]\npayload_kg = {low = 0.0, high = 1.0}\n", "needs n"),
    ('[fixed]\n"controller.type" = "magic"\n[parameters]\npayload_kg = [0.0]\n', "unknown controller type"),
])
def test_bad_sweep_file_is_one_line_exit_2_before_anything_runs(tmp_path, capsys, text, message):
    path = sweep_file(tmp_path, 'scenario = "laser_arm_step"\n' + text)
    assert main(["batch", str(path), "--out", str(tmp_path / "out")]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and err.startswith("watflex-sim: error: ")
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- no lost work

N_RUNS = 30
SLOW = LASER + "duration_s = 0.3\n[parameters]\npayload_kg = {low = 0.0, high = 1.6, n = 10}\n" \
               '"controller.kp" = [0.1, 0.127, 0.15]\n'


def start_sweep(tmp_path):
    path = sweep_file(tmp_path, SLOW)
    cmd = [sys.executable, "-m", "watflex_sim.cli", "batch", str(path), "--out", str(tmp_path / "out"), "--workers", "2"]
    # Ctrl-C acts as in a terminal even when the tests run as a background job (which ignores SIGINT)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    return cmd, proc


def journal_rows(tmp_path, at_least: int, proc, timeout: float = 60.0) -> list[dict]:
    """Wait until the sweep has journalled `at_least` rows; return them."""
    path, end = tmp_path / "out" / "runs.jsonl", time.monotonic() + timeout
    while time.monotonic() < end:
        lines = path.read_text().splitlines() if path.exists() else []
        if len(lines) >= at_least:
            return [json.loads(x) for x in lines[:at_least]]
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.01)
    raise AssertionError("sweep made no progress")


def resume(cmd, capsys) -> tuple[int, str, str]:
    """The same command again, in this process (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = main(cmd[3:] + ["--no-plot"])
    out, err = capsys.readouterr()
    return code, out, err


def text(rows_: list[dict]) -> str:
    return json.dumps(rows_, sort_keys=True)  # NaN as NaN: equal rows give equal text


def test_killed_worker_loses_nothing_and_resume_skips_everything(tmp_path, capsys):
    cmd, proc = start_sweep(tmp_path)
    first = journal_rows(tmp_path, 1, proc)[0]
    os.kill(int(first["worker"].rsplit(":", 1)[1]), signal.SIGKILL)  # that worker is running its next run
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "died (exit code -9)" in err and "retrying it" in err
    done = rows(tmp_path / "out")
    assert len(done) == N_RUNS and {r["status"] for r in done} == {"ok"}
    code, out, err = resume(cmd, capsys)
    assert code == 0 and f"0 runs done (0 failed), {N_RUNS} already done" in out
    assert text(rows(tmp_path / "out")) == text(done)


def test_interrupted_sweep_keeps_finished_rows_and_resumes(tmp_path, capsys):
    cmd, proc = start_sweep(tmp_path)
    journal_rows(tmp_path, 3, proc)
    proc.send_signal(signal.SIGINT)  # Ctrl-C
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "run the same command again to resume" in err
    kept = rows(tmp_path / "out")
    assert 3 <= len(kept) < N_RUNS and {r["status"] for r in kept} == {"ok"}
    code, out, err = resume(cmd, capsys)
    assert code == 0, err
    assert f"{N_RUNS - len(kept)} runs done (0 failed), {len(kept)} already done" in out
    done = {r["run_id"]: r for r in rows(tmp_path / "out")}
    assert len(done) == N_RUNS and text([done[r["run_id"]] for r in kept]) == text(kept)  # not re-run: same wall time


def test_killed_sweep_resumes_from_its_journal_even_with_a_torn_line(tmp_path, capsys):
    cmd, proc = start_sweep(tmp_path)
    kept = journal_rows(tmp_path, 3, proc)
    proc.kill()  # no chance to write anything more
    proc.communicate(timeout=60)
    with open(tmp_path / "out" / "runs.jsonl", "a") as f:
        f.write('{"run_id": "half a li')  # as a write cut by the kill would leave it
    code, out, err = resume(cmd, capsys)
    ran, skipped = map(int, re.search(r"(\d+) runs done \(0 failed\), (\d+) already done", out).groups())
    assert code == 0 and ran + skipped == N_RUNS and skipped >= len(kept), err
    done = {r["run_id"]: r for r in rows(tmp_path / "out")}
    assert len(done) == N_RUNS and {r["status"] for r in done.values()} == {"ok"}
    assert text([done[r["run_id"]] for r in kept]) == text(kept)


@pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                    reason="Ray is an optional extra (pip install '.[cluster]'); not installed here")
def test_ray_gives_the_process_pool_results_row_for_row(tmp_path):
    path = sweep_file(tmp_path, 'scenario = "laser_arm_step"\n[fixed]\nduration_s = 0.3\n[parameters]\n'
                      'payload_kg = [0.0, 1.15]\n"controller.kp" = [0.1, 0.2]\nseed = [1]\n')
    pool = run_sweep(path, tmp_path / "pool", workers=2, plots=False)
    ray = run_sweep(path, tmp_path / "ray", workers=2, ray_address="local", plots=False)
    assert ray.ran == pool.ran == 4 and ray.failed == 0
    assert all(same(a, b) for a, b in zip(rows(tmp_path / "pool"), rows(tmp_path / "ray"), strict=True))


def test_ray_missing_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed
    path = sweep_file(tmp_path, LASER + "[parameters]\npayload_kg = [0.0]\n")
    assert main(["batch", str(path), "--out", str(tmp_path / "out"), "--ray", "auto"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "pip install 'watflex-sim[cluster]'" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()
