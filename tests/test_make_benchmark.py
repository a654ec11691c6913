"""tools/make_benchmark.py: reproducible, concealed, visible (0.5 s recordings, a few effects)."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from watflex_sim import diagnosis as diagnose, read_recording
from watflex_sim.effects import CATALOGUE
from watflex_sim.resim import resimulate
from watflex_sim.rigdesc import load_rig

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("make_benchmark", ROOT / "tools" / "make_benchmark.py")
mb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mb)
_spec = importlib.util.spec_from_file_location("score_benchmark", ROOT / "tools" / "score_benchmark.py")
sb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sb)

EFFECTS = ["coulomb_friction", "payload", "sensor_offset"]
ARGS = dict(seed=3, rigs=("laser_arm", "watflex"), effects=EFFECTS, per_effect=1, clean=1, duration=0.5,
            log=lambda line: None)


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    return out, mb.make_cases(out, **ARGS)


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_same_seed_same_bytes(bench, tmp_path):
    out, _ = bench
    mb.make_cases(tmp_path, **ARGS)
    assert _files(tmp_path) == _files(out)


def test_truth_schema(bench):
    out, truth = bench
    assert truth == json.loads((out / "truth.json").read_text())
    assert truth["format"] == "flexarm-benchmark/1" and truth["seed"] == 3
    assert truth["generator"] == "tools/make_benchmark.py"
    assert len(truth["cases"]) == 2 * (len(EFFECTS) + 1)
    keys = ["id", "rig", "kind", "recordings", "effect", "where", "parameters", "units", "refit_parameters",
            "concealment", "duration_s"]
    for case in truth["cases"]:
        assert list(case) == keys
        rig = load_rig(case["rig"])
        assert len(case["recordings"]) == 3 and case["duration_s"] == 0.5
        for rel in case["recordings"]:
            assert rel.startswith(f"cases/{case['id']}/") and (out / rel).exists()
        for name, ratio in case["refit_parameters"].items():
            assert abs(ratio - 1) <= rig.parameters[name]["tolerance"]
        if case["effect"] is None:
            assert case["where"] is None and case["parameters"] == {} and case["refit_parameters"]
            continue
        assert case["where"] in rig.effects[case["effect"]]
        assert case["concealment"] in mb.CONCEALMENTS
        names = {p.name for p in CATALOGUE[case["effect"]][1]}
        assert set(case["parameters"]) <= names and set(case["units"]) == set(case["parameters"])
    assert not list((out / "cases").rglob("truth*"))


def _numbers(node):
    if isinstance(node, dict):
        return [x for v in node.values() for x in _numbers(v)]
    if isinstance(node, list):
        return [x for v in node for x in _numbers(v)]
    return [node] if isinstance(node, (int, float)) and not isinstance(node, bool) else []


def test_sidecars_conceal_the_truth(bench):
    out, truth = bench
    for case in truth["cases"]:
        for rel in case["recordings"]:
            text = (out / rel).with_suffix(".json").read_text()
            assert '"effects"' not in text and '"parameters"' not in text
            if case["effect"]:
                assert f'"{case["effect"]}"' not in text and case["id"] not in text  # "payload_kg" is fine
                numbers = set(_numbers(json.loads(text)))
                assert not [v for v in case["parameters"].values() if v not in (0.0, 1.0) and v in numbers]


CONTRACT = {"format", "rig", "experiment", "payload_kg", "controller", "mode", "notes", "locked_joints"}  # recordings.md


def test_a_sidecar_with_only_the_contracts_fields_is_re_simulated_the_same(bench):
    """Another implementation's recordings carry the sidecar of recordings.md section 1 only, not the `scenario`,
    `seed` and `control_period_s` our recorder adds: each benchmark recording, re-read with its sidecar cut to the
    contract's fields, gives the same scenario to re-simulate (so the same diagnosis; measured on seed 80's
    watflex-97a55996 and laser_arm-08b39646, whole diagnoses from cut sidecars: the same reports)."""
    from watflex_sim.resim import scenario_from_recording

    out, truth = bench
    for case in truth["cases"]:
        for rel in case["recordings"]:
            full = json.loads((out / rel).with_suffix(".json").read_text())
            cut = {k: v for k, v in full.items() if k in CONTRACT}
            assert set(full) - CONTRACT, "the benchmark's sidecars carry more than the contract: nothing tested"
            ours, theirs = read_recording(out / rel), read_recording(out / rel, sidecar=cut)
            assert scenario_from_recording(theirs) == scenario_from_recording(ours), rel


def _excess(rec, nominal, rig) -> tuple[float, float]:
    """Over the measured channels, the largest RMS(measured - nominal) and the largest |mean| of
    that difference, both / channel noise (noise alone: ~1 and ~1/sqrt(samples))."""
    rms = bias = 0.0
    for c, spec in rig.channels.items():
        if spec["kind"] == "measured" and spec.get("noise") and c in rec.channels:
            d = rec.channels[c] - nominal.channels[c]
            d = d[np.isfinite(d)]
            if d.size > 10 and np.std(nominal.channels[c][np.isfinite(nominal.channels[c])]) > 0:
                rms = max(rms, float(np.sqrt(np.mean(d**2))) / spec["noise"])
                bias = max(bias, abs(float(np.mean(d))) / spec["noise"])
    return rms, bias


def _visible(recs, rig) -> tuple[float, float]:
    """(RMS, bias) excess of the most changed recording against its nominal noise-free re-simulation."""
    both = [_excess(r, resimulate(r), rig) for r in recs]
    return max(b[0] for b in both), max(b[1] for b in both)


def _clear(rms: float, bias: float) -> bool:
    """Clearly beyond the noise: 3x its RMS, or a mean shift of half of it (~10 sigma of the mean
    over 500 samples; a sensor offset on a channel the loop ignores can be no larger than
    ~1.75x noise within the catalogue's bounds, laser motor_current)."""
    return rms > 3.0 or bias > 0.5


def test_effects_are_visible_above_noise(bench):
    """Each effect case differs from the nominal noise-free re-simulation of its sidecar by clearly
    more than the rig noise (clean cases differ too: parameters within tolerance, for the refit)."""
    out, truth = bench
    for case in truth["cases"]:
        if case["effect"]:
            rig = load_rig(case["rig"])
            recs = [read_recording(out / rel) for rel in case["recordings"]]
            excess = _visible(recs, rig)
            assert _clear(*excess), (case, excess)


REENABLED = [("laser_arm", "backlash", "hub"), ("watflex", "backlash", "elbow"),
             ("laser_arm", "sensor_gain", "motor_current"), ("laser_arm", "sensor_offset", "motor_current"),
             ("laser_arm", "delay", "tip_sensor"), ("laser_arm", "joint_compliance", "hub"),
             ("watflex", "joint_compliance", "elbow")]


@pytest.mark.parametrize("rig,effect,where", REENABLED)
def test_weak_end_is_visible(rig, effect, where):
    """The weakest magnitude of RANGES shows above the noise, for the effects and places that
    simulator fixes made possible (backlash a hard stop, sensor effects on monitored channels and
    delays from the first reading, a stiffer clamp)."""
    assert where in mb.places(rig, effect)
    weak = {name: span[0] for name, (kind, *span) in mb._ranges(rig, effect, where).items()}
    runs = mb.experiments(rig, 0.5, np.random.default_rng(1))
    recs = [rec for _, rec in mb.simulate_case(runs, [dict(effect=effect, where=where, **weak)], {})]
    excess = _visible(recs, load_rig(rig))
    assert _clear(*excess), excess


def test_places():
    """Watflex: only places the single-link experiments excite (rigs.md §2: link 1 rigid, its
    bridges not mounted); laser arm: every allowed one."""
    every = {w for e in CATALOGUE for w in mb.places("watflex", e)}
    assert {"elbow", "link2", "strain_2A", "elbow_angle", "elbow_torque_cmd", "command", "end_effector_bearing"} <= every
    assert not [w for w in every if w.startswith(("shoulder", "link1", "strain_1"))] and "elbow_bearing" not in every
    for effect, where in load_rig("laser_arm").effects.items():
        if mb.why_skipped("laser_arm", effect) is None:
            assert mb.places("laser_arm", effect) == where
    assert mb.why_skipped("laser_arm", "backlash") is None and mb.why_skipped("watflex", "backlash") is None


def test_ranges_within_catalogue_bounds():
    """Every RANGES value (both signs of "±", both ratios of "×") within its catalogue bounds; the
    data-scaled ones are checked on the data (test_truth_within_diagnosis_bounds)."""
    for rig, table in mb.RANGES.items():
        for key, ranges in table.items():
            effect, _, where = key.partition(":")
            assert effect in load_rig(rig).effects and (not where or where in load_rig(rig).effects[effect])
            params = {p.name: p for p in CATALOGUE[effect][1]}
            for name, (kind, *span) in ranges.items():
                p = params[name]
                if p.scale:
                    continue
                values = span + ([-v for v in span] if kind == "±" else []) + ([1 / v for v in span] if kind == "×" else [])
                assert all(p.low <= v <= p.high for v in values), (rig, key, name, values, p)


def test_truth_within_diagnosis_bounds(bench):
    """Each true parameter lies within the catalogue bounds in the diagnosis' units (scaled ones
    times diagnose.scale_of of the case's recordings)."""
    out, truth = bench
    for case in truth["cases"]:
        if not case["effect"]:
            continue
        data = diagnose.prepare([read_recording(out / rel) for rel in case["recordings"]], case["recordings"])
        for p in CATALOGUE[case["effect"]][1]:
            if p.name in case["parameters"]:
                scale = diagnose.scale_of(data, p, case["where"])
                assert p.low * scale <= case["parameters"][p.name] <= p.high * scale, (case, p, scale)


def test_existing_benchmark_is_refused(bench):
    out, _ = bench
    with pytest.raises(ValueError, match="already holds"):
        mb.make_cases(out, **ARGS)


@pytest.mark.parametrize("args", [["--rigs", "emps"], ["--effects", "gremlins"], ["--duration", "0"],
                                  ["--per-effect", "-1"], [], ["--range", "stribeck_friction.v_s=0.3:0.1"],
                                  ["--range", "stribeck_friction.v_s=0.1:9"], ["--range", "payload.speed=1:2"],
                                  ["--rigs", "laser_arm", "--range", "table_tilt.angle=0.001:0.002"]])
def test_cli_bad_arguments(args, tmp_path):
    argv = args + (["--out", str(tmp_path / "b")] if args else [])
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "make_benchmark.py"), *argv],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "b").exists()


def test_diverging_case_is_redrawn_then_skipped(tmp_path, monkeypatch, capsys):
    calls = []

    def diverge(scenario):
        calls.append(scenario["effects"][0])
        raise mb.SimulationError("simulation diverged (test)")

    monkeypatch.setattr(mb, "simulate", diverge)
    truth = mb.make_cases(tmp_path, **dict(ARGS, rigs=("watflex",), effects=["payload"], clean=0))
    assert truth["cases"] == [] and truth["skipped"][-1]["effect"] == "payload"
    assert len(calls) == mb.MAX_DRAWS and len({c["mass"] for c in calls}) == mb.MAX_DRAWS
    assert "diverged" in capsys.readouterr().err


def test_another_implementation_records_what_its_sidecars_do_not_tell(bench, tmp_path):
    """--segments / --step-divisor: the same cases (same draws, same sidecars byte for byte) recorded by a
    finer discretisation of the datasheet (30 segments, half the step), which the diagnosis is not told:
    the clean laser case's tip-sensor recording differs from ours by more than a tenth of its noise."""
    out, truth = bench
    other = mb.make_cases(tmp_path, **{**ARGS, "effects": [], "rigs": ("laser_arm",)}, segments=30, step_divisor=2)
    assert other["recorder"] == {"segments": 30, "step_divisor": 2} and truth["recorder"] == {"segments": 0, "step_divisor": 1}
    (case,) = other["cases"]
    assert case == next(c for c in truth["cases"] if c["id"] == case["id"])
    for rel in case["recordings"]:
        assert (tmp_path / rel).with_suffix(".json").read_bytes() == (out / rel).with_suffix(".json").read_bytes()
        ours, theirs = read_recording(out / rel), read_recording(tmp_path / rel)
        noise = load_rig("laser_arm").channels["tip_sensor"]["noise"]
        assert np.max(np.abs(ours.channels["tip_sensor"] - theirs.channels["tip_sensor"])) > 0.1 * noise


def test_a_pair_case_carries_both_effects_and_the_recordings_show_both(tmp_path):
    """--pairs: a case with two different effects at once. truth.json names the first as `effect` and the
    second in `others`; re-simulated (noise off) with both effects the recordings are matched to within
    their noise on every channel, with the first effect alone some channel is off by more than twice that
    (the second effect is really in them)."""
    truth = mb.make_cases(tmp_path, **dict(ARGS, rigs=("laser_arm",), per_effect=0, clean=0), pairs=1)
    (case,) = truth["cases"]
    assert case["kind"] == "pair" and case["concealment"] == "two effects" and len(case["others"]) == 1
    second = case["others"][0]
    assert {case["effect"], second["effect"]} <= set(EFFECTS) and case["effect"] != second["effect"]
    both = [dict(effect=e["effect"], where=e["where"], **e["parameters"]) for e in (case, second)]
    worst = {"both": 0.0, "first": 0.0}  # the largest RMS misfit over channels, in units of the channel's noise
    for rel in case["recordings"]:
        rec = read_recording(tmp_path / rel)
        for label, effects in (("both", both), ("first", both[:1])):
            sim = resimulate(rec, effects)
            for c, x in rec.channels.items():
                noise = load_rig("laser_arm").channels[c].get("noise", 0.0)
                if noise:
                    rms = float(np.sqrt(np.nanmean((sim.channels[c] - x) ** 2)))
                    worst[label] = max(worst[label], rms / noise)
    assert worst["both"] < 1.5 and worst["first"] > 2 * worst["both"], worst


def test_the_scorer_names_a_command_delay_where_the_report_does(bench):
    """score_benchmark.true_place(): a delay the truth puts on "command" is on the command channels the
    recordings carry, as the report names it (explain.physical_place): the laser arm's voltage_cmd,
    Watflex's shoulder_torque_cmd+elbow_torque_cmd (seed 46 scored two right delays as wrong places);
    any other place is the truth's own."""
    out, truth = bench
    case = next(c for c in truth["cases"] if c["rig"] == "laser_arm" and c["effect"])
    recs = [read_recording(out / p) for p in case["recordings"]]
    assert sb.true_place({**case, "effect": "delay", "where": "command"}, recs) == "voltage_cmd"
    assert sb.true_place(case, recs) == case["where"]
    case = next(c for c in truth["cases"] if c["rig"] == "watflex" and c["effect"])
    recs = [read_recording(out / p) for p in case["recordings"]]
    assert sb.true_place({**case, "effect": "delay", "where": "command"}, recs) == "shoulder_torque_cmd+elbow_torque_cmd"


def test_the_scorer_records_a_proposed_experiment_as_the_rig_recorded_the_case(bench):
    """score_benchmark.rig_records(): the experiment a report proposes, run on the case's truth, is recorded as
    the case's own files were: with the rig's noise (the tip sensor's second-difference noise within 30 % of the
    datasheet's 0.01 m: a noise-free file was the one the diagnosis could not match to its noise), the same
    bytes each time, and by the benchmark's recorder (30 segments at half the step differ from ours). A pair case's
    second effect is the rig's too (a 20 ms command delay changes the file; at 0 s, the neutral value, it does not)."""
    from watflex_sim.diagnosis.noise import measured_noise
    from watflex_sim.resim import scenario_from_recording

    out, truth = bench
    case = next(c for c in truth["cases"] if c["rig"] == "laser_arm" and c["effect"])
    scenario = scenario_from_recording(read_recording(out / case["recordings"][0]))
    ours = sb.rig_records(case, scenario).channels["tip_sensor"]
    again = sb.rig_records(case, scenario).channels["tip_sensor"]
    theirs = sb.rig_records(case, scenario, {"segments": 30, "step_divisor": 2}).channels["tip_sensor"]
    noise = load_rig("laser_arm").channels["tip_sensor"]["noise"]
    assert measured_noise(ours) == pytest.approx(noise, rel=0.3)
    assert np.array_equal(ours, again) and not np.array_equal(ours, theirs)

    def paired(seconds):
        other = {"effect": "delay", "where": "command", "parameters": {"seconds": seconds}}
        return sb.rig_records({**case, "kind": "pair", "others": [other]}, scenario).channels["tip_sensor"]
    assert np.array_equal(paired(0.0), ours) and not np.array_equal(paired(0.02), ours)


def test_the_two_joint_setup_moves_both_joints_and_places_effects_on_the_shoulder(tmp_path):
    """`--watflex-setup two_joint`: every allowed place is a place (the shoulder, link 1 and its bridges
    included, which the single-link set-up never excites), the recordings are the observer control of
    both joints (thesis 5.2.5) with both joints moving by 0.3-0.5 / 0.6-1.0 rad (the drawn steps' spans,
    less 30 % for a 1.2 s recording's unfinished rise) and the link-1 bridges recorded; clean_rest's
    last file moves neither joint (within 0.01 rad); the single-link set-up's keys are not touched."""
    assert mb.places("watflex", "coulomb_friction", "two_joint") == ["shoulder", "elbow"]
    assert "strain_1A" in mb.places("watflex", "sensor_gain", "two_joint")
    truth = mb.make_cases(tmp_path, **dict(ARGS, rigs=("watflex",), effects=["coulomb_friction"], clean=0,
                                           duration=1.2), hard=1, setup="two_joint")
    assert truth["watflex_setup"] == "two_joint"
    cases = {c["kind"]: c for c in truth["cases"]}
    effect = cases["effect"]
    recs = {Path(p).stem: read_recording(tmp_path / p) for p in effect["recordings"]}
    assert sorted(recs) == ["two_joint_a", "two_joint_b", "two_joint_c"]
    for rec in recs.values():
        assert rec.meta["scenario"]["experiment"] == "watflex_observer_two_joint" and "strain_1A" in rec.channels
        assert np.ptp(rec.channels["shoulder_angle"]) > 0.7 * 0.3 and np.ptp(rec.channels["elbow_angle"]) > 0.7 * 0.6
    rest = read_recording(tmp_path / next(p for p in cases["clean_rest"]["recordings"] if "at_rest" in p))
    assert np.ptp(rest.channels["shoulder_angle"]) < 0.01 and np.ptp(rest.channels["elbow_angle"]) < 0.01
    assert mb._key("watflex", "two_joint", "clean/0") != mb._key("watflex", "single_link", "clean/0") == "watflex/clean/0"


def test_the_scorer_resumes_a_run_stopped_early(bench, tmp_path, monkeypatch):
    """score_benchmark --resume: the cases already in score.json keep their rows and are not diagnosed again;
    the others are scored and added (one row per case at the end)."""
    import shutil

    out, truth = bench
    copy = tmp_path / "bench"
    copy.mkdir()
    shutil.copy(out / "truth.json", copy / "truth.json")
    ids = sorted((c["id"] for c in truth["cases"]), key=lambda i: i.rsplit("-", 1)[-1])
    scored = []

    def row(root, case, *args):
        scored.append(case["id"])
        return {"id": case["id"], "rig": case["rig"], "kind": "clean", "truth": "none", "where": None, "concealment": "",
                "verdict": "nothing_missing", "proposed": False, "covered": [], "ours": "none", "ours_where": None,
                "ours_all": [], "held_before": 1.0, "held_after": 1.0, "seconds": 1.0, "error": None, "truth_all": None}

    monkeypatch.setattr(sb, "score_case", row)
    monkeypatch.setattr(sb, "machine_step_us", lambda: 3.0)
    (copy / "score.json").write_text(json.dumps([{**row(copy, {"id": ids[0], "rig": "x"}), "seconds": 7.0}]))
    scored.clear()
    assert sb.main([str(copy), "--resume", "--no-baselines"]) == 0
    rows = json.loads((copy / "score.json").read_text())
    assert scored == ids[1:] and [r["id"] for r in rows] == ids and rows[0]["seconds"] == 7.0


def test_a_range_beyond_the_benchmarks_is_drawn_from_and_kept_in_the_truth(tmp_path):
    """--range (make_cases `ranges`): a Stribeck velocity drawn from 0.2-0.4 rad/s, beyond the benchmark's own
    0.005-0.03 on the laser arm, on that run only (RANGES as before afterwards), and truth.json says so."""
    before = json.dumps(mb.RANGES, sort_keys=True)
    truth = mb.make_cases(tmp_path, **dict(ARGS, rigs=("laser_arm",), effects=["stribeck_friction"], clean=0),
                          ranges={"stribeck_friction.v_s": (0.2, 0.4)})
    (case,) = truth["cases"]
    assert 0.2 <= case["parameters"]["v_s"] <= 0.4
    assert truth["ranges"] == {"stribeck_friction.v_s": [0.2, 0.4]}
    assert json.dumps(mb.RANGES, sort_keys=True) == before


def test_relog_writes_a_recording_as_another_lab_logs_it(tmp_path):
    """tools/relog.py: a 0.4 s laser recording at 1 ms (400 samples) re-logged every 2nd sample from 100 s, 10 %
    of measured cells empty, the motor current dropped, a minimal sidecar: 200 samples 2 ms apart from 100 s, read
    back as a recording with its references whole, ~10 % (binomial, +-5 sd) of measured cells empty, no current column
    and none of the simulator's sidecar keys; the same seed gives the same bytes. With stamps jittered by up to 0.2 ms and
    written in ms (the sidecar says so), the reader gives times within 0.2 ms of the ticks and the values unmoved. With
    --filtered-noise 2 the tip sensor carries 2 x its declared 0.01 V more (within 25 %: 400 samples of noise correlated
    over ~2), correlated from sample to sample as a 100 Hz first-order low-pass at 1 kHz (0.53, within 0.15); the
    encoder, quantised, is left as it was. With --glitches 3 three cells of each measured channel move, each by
    --glitch-size 30 x its declared noise; a negative count is refused. --hold writes a column's empty cells as its
    last value above them (none before its first) and leaves the others' empty; --hold or --drop of a column the
    recordings lack is refused before anything is written."""
    from watflex_sim import load_scenario, simulate, write_recording

    spec = importlib.util.spec_from_file_location("relog", ROOT / "tools" / "relog.py")
    relog = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(relog)
    rec = simulate(load_scenario("laser_arm_step", ["duration_s=0.4"])).recording
    write_recording(rec, tmp_path / "src", "step")
    assert relog.main([str(tmp_path / "src"), str(tmp_path / "a"), "--empty", "0.1", "--drop", "motor_current"]) == 0
    out = read_recording(tmp_path / "a" / "step.csv")
    assert out.time.size == 200 and out.time[0] == 100.0 and np.allclose(np.diff(out.time), 2e-3, atol=1e-9)
    assert "motor_current" not in out.channels and np.isfinite(out.channels["reference"]).all()
    cells = np.array([out.channels[c] for c in ("hub_angle", "voltage_cmd")])
    assert abs(np.isnan(cells).mean() - 0.1) < 5 * np.sqrt(0.1 * 0.9 / cells.size)
    assert not {"scenario", "seed", "control_period_s"} & set(out.meta)
    relog.main([str(tmp_path / "src"), str(tmp_path / "b"), "--empty", "0.1", "--drop", "motor_current"])
    assert (tmp_path / "a" / "step.csv").read_bytes() == (tmp_path / "b" / "step.csv").read_bytes()
    assert relog.main([str(tmp_path / "nothing"), str(tmp_path / "c")]) == 2
    assert relog.main([str(tmp_path / "src"), str(tmp_path / "d"), "--every", "1", "--jitter-s", "2e-4",
                       "--time-unit", "ms"]) == 0  # stamps off by up to 0.2 ms, written in ms
    out = read_recording(tmp_path / "d" / "step.csv")
    off = out.time - (100.0 + rec.time)
    assert out.time.size == 400 and np.abs(off).max() <= 2e-4 + 1e-9 and np.abs(off).max() > 1e-4
    written_all = read_recording(tmp_path / "src" / "step.csv").channels
    written, moved = written_all["hub_angle"], out.channels["hub_angle"]
    assert np.array_equal(moved[np.isfinite(moved)], written[np.isfinite(moved)])  # the values not moved
    assert relog.main([str(tmp_path / "src"), str(tmp_path / "e"), "--every", "1", "--empty", "0",
                       "--filtered-noise", "2", "--filter-hz", "100"]) == 0  # 2 x the declared noise, low-passed
    out = read_recording(tmp_path / "e" / "step.csv")
    added = out.channels["tip_sensor"] - written_all["tip_sensor"]
    assert np.std(added) == pytest.approx(2 * 0.01, rel=0.25)  # rigs/laser_arm.toml: tip_sensor noise 0.01 V
    assert np.corrcoef(added[1:], added[:-1])[0, 1] == pytest.approx(np.exp(-2 * np.pi * 100 * 1e-3), abs=0.15)
    assert np.array_equal(out.channels["hub_angle"], written_all["hub_angle"])  # an encoder: quantised, left
    assert relog.main([str(tmp_path / "src"), str(tmp_path / "f"), "--every", "1", "--empty", "0", "--glitches", "3",
                       "--glitch-size", "30"]) == 0  # three samples a measured channel moved by 30 x its noise
    out = read_recording(tmp_path / "f" / "step.csv")
    for channel, noise in (("tip_sensor", 0.01), ("motor_current", 0.004), ("hub_angle", 2e-5)):  # rigs/laser_arm.toml
        moved = np.abs(out.channels[channel] - written_all[channel])
        assert np.count_nonzero(moved) == 3 and np.allclose(moved[moved > 0], 30 * noise, rtol=1e-6)
    assert relog.main([str(tmp_path / "src"), str(tmp_path / "g"), "--glitches", "-1"]) == 2
    rows = [["0", "", "5"], ["1", "2", ""], ["2", "", ""], ["3", "4", "6"], ["4", "", ""]]
    relog.hold_last_values(["time", "tip_x", "tip_y"], rows, frozenset({"tip_x"}))  # --hold tip_x
    assert [r[1] for r in rows] == ["", "2", "2", "4", "4"] and [r[2] for r in rows] == ["5", "", "", "6", ""]
    for option in ("--hold", "--drop"):  # a column the recordings do not have: refused, nothing written
        assert relog.main([str(tmp_path / "src"), str(tmp_path / "h"), option, "tip_sensor,tip_x"]) == 2
        assert not (tmp_path / "h").exists()
