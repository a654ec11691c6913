"""tools/make_benchmark.py: reproducible, concealed, visible (0.5 s recordings, a few effects)."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from watflex_sim import read_recording
from watflex_sim.effects import CATALOGUE
from watflex_sim.resim import resimulate
from watflex_sim.rigdesc import load_rig

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("make_benchmark", ROOT / "tools" / "make_benchmark.py")
mb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mb)

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
    keys = ["id", "rig", "recordings", "effect", "where", "parameters", "units", "refit_parameters",
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


def _excess(rec, nominal, rig) -> float:
    """Largest RMS(measured - nominal) / channel noise over the measured channels (noise alone ~1)."""
    out = 0.0
    for c, spec in rig.channels.items():
        if spec["kind"] == "measured" and spec.get("noise") and c in rec.channels:
            d = rec.channels[c] - nominal.channels[c]
            d = d[np.isfinite(d)]
            if d.size > 10 and np.std(nominal.channels[c][np.isfinite(nominal.channels[c])]) > 0:
                out = max(out, float(np.sqrt(np.mean(d**2))) / spec["noise"])
    return out


def test_effects_are_visible_above_noise(bench):
    """Each effect case differs from the nominal noise-free re-simulation of its sidecar by clearly
    more than the rig noise (clean cases differ too: parameters within tolerance, for the refit)."""
    out, truth = bench
    for case in truth["cases"]:
        if case["effect"]:
            rig = load_rig(case["rig"])
            recs = [read_recording(out / rel) for rel in case["recordings"]]
            excess = max(_excess(r, resimulate(r), rig) for r in recs)
            assert excess > 3.0, (case, excess)


def test_existing_benchmark_is_refused(bench):
    out, _ = bench
    with pytest.raises(ValueError, match="already holds"):
        mb.make_cases(out, **ARGS)


@pytest.mark.parametrize("args", [["--rigs", "emps"], ["--effects", "gremlins"], ["--duration", "0"],
                                  ["--per-effect", "-1"], []])
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
