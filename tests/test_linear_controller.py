"""A linear law as data (controllers/linear.py) and controllers side by side (controllers/parallel.py).

Checked against a lab's own controllers on the Quanser 2DSFL (tests/data/quanser_2dsfl/lab/, SOURCE.md there): its
LQG and H-infinity, each exported both as the law it designed (a Kalman predictor and gain; a state space on the
integral of the tip error) and folded into one discrete state space; the second, run by `linear`, must give the first's
commands on the lab's own recorded inputs. And against scipy's discretisation and the project's PID.
"""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from scipy import signal

from watflex_sim.controllers import PID, Linear
from watflex_sim.engine import make_controller
from watflex_sim.model import ConfigError
from watflex_sim.rigdesc import load_rig

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "tests" / "data" / "quanser_2dsfl" / "lab"
INPUTS = ["hub1", "link1", "", "", "hub1_reference", "", "", ""]  # the Simulink Mux (SOURCE.md)
_spec = importlib.util.spec_from_file_location("quanser_lab_runs", ROOT / "tools" / "quanser_lab_runs.py")
lab_runs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lab_runs)


def _saved(name: str) -> dict:
    law = scipy.io.loadmat(LAB / "orr_controllers.mat", squeeze_me=True)[name]
    return {f: np.asarray(law[f].item(), dtype=float) for f in law.dtype.names}


def _run(law, rows: list[dict]) -> np.ndarray:
    law.reset()
    return np.array([list(law(0.0, row).values()) for row in rows])


def _lab_rows(step: str) -> tuple[list[dict], np.ndarray, np.ndarray]:
    seg = scipy.io.loadmat(LAB / step, squeeze_me=True)
    measured, reference = seg["X1_meas"], seg["X1_ref"][:, 0]
    rows = [{"hub1": m[0], "link1": m[1], "hub1_reference": r} for m, r in zip(measured, reference)]
    return rows, measured, reference


def test_the_labs_lqg_as_a_state_space_is_its_kalman_predictor_and_gain():
    """orr_ctrl_lqg.m: u = -K (xh - [r, 0, 0, 0]), xh <- Ad xh + Bd u + L (y - C_POS xh), every 10 ms (5 samples at
    500 Hz, held between); `linear` on `lqg_ss` gives the same current to 1e-12 A over the lab's 10 deg step (rms
    0.21 A), unclipped (the .m file feeds its predictor the clipped u, the state-space block does not)."""
    lqg, folded = _saved("lqg"), _saved("lqg_ss")
    rows, measured, reference = _lab_rows("lqg_step_10deg_run01.mat")
    law = Linear(["current1_cmd"], INPUTS, A=folded["A"], B=folded["B"], C=folded["C"], D=folded["D"], period_s=0.01,
                 period=0.002)
    xh, u, theirs = np.zeros(4), 0.0, []
    for k in range(len(rows)):
        if k % 5 == 0:
            u = -lqg["K"] @ (xh - np.array([reference[k], 0, 0, 0]))
            xh = lqg["Ad"] @ xh + lqg["Bd"] * u + lqg["L"] @ (measured[k, :2] - lqg["C_POS"] @ xh)
        theirs.append(u)
    ours = _run(law, rows)[:, 0]
    assert np.sqrt(np.mean(np.square(theirs))) > 0.2
    assert np.max(np.abs(ours - theirs)) < 1e-12


def test_the_labs_hinf_as_a_state_space_is_its_design_with_the_integral():
    """orr_ctrl_hinf.m: u = C xc + D [y_hub, y_defl, xi], xc <- A xc + B [...], xi <- xi + Ts (r - y_hub - y_defl);
    `linear` on `hinf_ss` (xi its 7th state) gives the same to 1e-12 A over the lab's 10 deg step (rms 0.14 A)."""
    hinf, folded = _saved("hinf"), _saved("hinf_ss")
    rows, measured, reference = _lab_rows("hinf_step_10deg_run01.mat")
    law = Linear(["current1_cmd"], INPUTS, A=folded["A"], B=folded["B"], C=folded["C"], D=folded["D"], period_s=0.01,
                 period=0.002)
    xc, xi, u, theirs = np.zeros(6), 0.0, 0.0, []
    for k in range(len(rows)):
        if k % 5 == 0:
            meas = np.array([measured[k, 0], measured[k, 1], xi])
            u = hinf["C"] @ xc + hinf["D"] @ meas
            xc, xi = hinf["A"] @ xc + hinf["B"] @ meas, xi + 0.01 * (reference[k] - measured[k, 0] - measured[k, 1])
        theirs.append(u)
    ours = _run(law, rows)[:, 0]
    assert np.sqrt(np.mean(np.square(theirs))) > 0.1
    assert np.max(np.abs(ours - theirs)) < 1e-12


def test_a_continuous_transfer_function_is_discretised_as_scipy_does():
    """A lead compensator (0.5 s + 2) / (0.05 s + 1) in s, Tustin at 2 ms: scipy's cont2discrete and dlsim on the same
    random input agree to 1e-12; one run at 10 ms inside a 2 ms loop holds each command 5 samples."""
    rng = np.random.default_rng(7)
    e = rng.normal(size=300)
    law = Linear(["u"], ["e"], num=[0.5, 2.0], den=[0.05, 1.0], domain="s", period=0.002)
    b, a, _ = signal.cont2discrete(([0.5, 2.0], [0.05, 1.0]), 0.002, method="bilinear")
    _, expected = signal.dlsim((b.ravel(), a, 0.002), e)
    assert np.max(np.abs(_run(law, [{"e": x} for x in e])[:, 0] - expected[:, 0])) < 1e-12
    slow = Linear(["u"], ["e"], num=[0.5, 2.0], den=[0.05, 1.0], domain="s", period_s=0.01, period=0.002)
    b, a, _ = signal.cont2discrete(([0.5, 2.0], [0.05, 1.0]), 0.01, method="bilinear")
    _, expected = signal.dlsim((b.ravel(), a, 0.01), e[::5])
    held = _run(slow, [{"e": x} for x in e])[:, 0]
    assert np.max(np.abs(held - np.repeat(expected[:, 0], 5))) < 1e-12


def test_a_pd_as_a_transfer_function_is_the_pid_law():
    """u = kp e + kd (e_k - e_{k-1}) / T with e = r - q (controllers/pid.py, rate_method "difference") is
    ((kp + kd/T) z - kd/T) / z on e, and on two inputs (r with +, q with -) the same: to 1e-9 N m over 200 samples
    that start at rest (the PID's rate starts at 0, the transfer function's state at 0)."""
    kp, kd, T = 40.0, 1.5, 0.001
    rng = np.random.default_rng(3)
    q = np.concatenate([[0.0], np.cumsum(rng.normal(scale=1e-3, size=199))])
    r = np.where(np.arange(200) >= 50, 0.1, 0.0)
    rows = [{"elbow_angle": a, "elbow_reference": b} for a, b in zip(q, r)]
    pid = PID(command="elbow_torque_cmd", position="elbow_angle", reference="elbow_reference", kp=kp, kd=kd,
              rate_method="difference", period=T)
    pd = [(kp + kd / T), -kd / T]
    law = Linear(["elbow_torque_cmd"], ["elbow_reference", "elbow_angle"], num=[[kp], [-x for x in pd]],
                 den=[[1.0], [1.0, 0.0]], period=T)
    # the PID differentiates the position only (no derivative kick): the reference term is kp alone
    assert np.max(np.abs(_run(law, rows)[:, 0] - _run(pid, rows)[:, 0])) < 1e-9


def test_a_linear_state_can_be_read_and_set():
    """controllers.base.StatefulController: x0..x{n-1}; a law set to another's state goes on as that one does."""
    folded = _saved("lqg_ss")
    rows, _, _ = _lab_rows("lqg_step_5deg_run01.mat")
    law = Linear(["current1_cmd"], INPUTS, A=folded["A"], B=folded["B"], C=folded["C"], D=folded["D"], period_s=0.01,
                 period=0.002)
    law.reset()
    for row in rows[:500]:
        law(0.0, row)
    assert list(law.state()) == ["x0", "x1", "x2", "x3"] and any(abs(v) > 1e-3 for v in law.state().values())
    twin = Linear(["current1_cmd"], INPUTS, A=folded["A"], B=folded["B"], C=folded["C"], D=folded["D"],
                  period_s=0.01, period=0.002)
    twin.reset()
    twin.set_state(law.state())
    assert [twin(0.0, row) for row in rows[500:600]] == [law(0.0, row) for row in rows[500:600]]
    with pytest.raises(ValueError, match="linear state has x0..x3, got x9"):
        law.set_state({"x9": 1.0})


@pytest.mark.parametrize("table, message", [
    ({"commands": ["current1_cmd"], "inputs": ["hub1"], "A": [[1, 0], [0, 1]], "B": [1, 2, 3], "C": [[1, 0]], "D": [0]},
     "B must be 2 x 1"),
    ({"commands": ["current1_cmd"], "inputs": ["hub1"], "A": [1, 2, 3], "B": [1], "C": [1], "D": [0]},
     "A must be square"),
    ({"commands": ["current1_cmd"], "inputs": ["hub1"], "num": [1, 2, 3], "den": [1, 1]}, "improper"),
    ({"commands": ["current1_cmd"], "inputs": ["hub1"], "D": [2.0], "period_s": 0.003}, "whole number of control"),
    ({"commands": ["current1_cmd"], "inputs": ["hub1"], "D": [2.0], "domain": "w"}, "domain must be one of z, s"),
    ({"commands": ["current1_cmd"], "inputs": ["hub1"]}, "needs A, B, C, D"),
])
def test_a_bad_linear_law_fails_in_one_line(table, message):
    scenario = {"controller": {"type": "linear", **table}, "direction": "positive", "command": []}
    with pytest.raises(ConfigError, match=message):
        make_controller(scenario, load_rig("quanser_2dsfl"), 0.002)


def test_parallel_parts_drive_their_own_commands_at_their_own_rates():
    """The lab's run as data (tools/quanser_lab_runs.py): stage 1's LQG at 10 ms beside stage 2's state feedback at
    2 ms: stage 1's command changes every 5th sample only, stage 2's every sample; states named by part; two parts on
    one command refused."""
    _, sidecar = lab_runs.stair(LAB, "lqg")
    rig = load_rig("quanser_2dsfl")
    scenario = {"controller": sidecar["controller"], "direction": "positive", "command": []}
    law = make_controller(scenario, rig, 0.002)
    law.reset()
    rng = np.random.default_rng(1)
    out = np.array([list(law(0.0, {c: rng.normal(scale=0.01) for c in rig.channels}).values()) for _ in range(50)])
    changes = np.abs(np.diff(out, axis=0)) > 0
    assert not changes[:, 0][np.arange(49) % 5 != 4].any() and changes[:, 1].all()
    assert set(law.state()) == {f"0:x{i}" for i in range(4)}
    twice = {"type": "parallel", "parts": [sidecar["controller"]["parts"][1]] * 2}
    with pytest.raises(ConfigError, match="parts 0 and 1 both drive current2_cmd"):
        make_controller({**scenario, "controller": twice}, rig, 0.002)


def test_a_rig_files_parallel_parts_are_checked_like_any_controller(tmp_path):
    """rigdesc checks each part's channel names as it checks a controller table's: one line naming the part."""
    text = (ROOT / "rigs" / "quanser_2dsfl.toml").read_text().replace('name = "quanser_2dsfl"', 'name = "parts"')
    start, end = text.index("[controller]"), text.index("[sidecar]")
    text = text[:start] + (
        '[controller]\ntype = "parallel"\n'
        'parts = [{ type = "linear", commands = ["current1_cmd"], inputs = ["hub1", "link9"], D = [[1.0, 2.0]] },\n'
        '         { type = "pid", command = "current2_cmd", position = "hub2", kp = 1.0 }]\n\n') + text[end:]
    (tmp_path / "parts.toml").write_text(text)
    with pytest.raises(ConfigError, match=r"controller\.parts\[0\]\.inputs: unknown channel 'link9'"):
        load_rig(str(tmp_path / "parts.toml"))


def test_a_model_diagnosed_on_quansers_runs_predicts_the_labs_lqg_runs(tmp_path):
    """tools/quanser_lab_runs.py joins the lab's ten files a controller into one recording. Held-out controller,
    held-out runs: `watflex-sim diagnose` on Quanser's fsf and psf runs (the two .mat sets of
    tests/data/quanser_2dsfl, --workers 1, 2026-12-06) found link 2 at x0.354 and a 59.3 N m/rad compliance at drive 1
    (refit: drive damping x0.755 / x0.75, link stiffness x0.992 / x1.067). That model, never fitted to the lab's
    runs, re-simulates the lab's LQG stair: hub 1 NRMSE 0.104 -> 0.039, link 1 4.93 -> 0.41 (the nominal loop
    limit-cycles at +-4 deg where the rig's link rings 0.4 deg rms; docs/rigs.md)."""
    from watflex_sim.metrics import nrmse
    from watflex_sim.recording import read_recording
    from watflex_sim.resim import resimulate

    effects = [{"effect": "link_stiffness_change", "where": "link2", "ratio": 0.3544},
               {"effect": "joint_compliance", "where": "drive1", "stiffness": 59.26}]
    parameters = {"drive1_damping": 0.7547, "drive2_damping": 0.75, "link1_stiffness": 0.9917,
                  "link2_stiffness": 1.0672}
    rec = read_recording(lab_runs.write(*lab_runs.stair(LAB, "lqg"), tmp_path / "lqg_stair"))
    assert rec.time.size == 20000 and np.allclose(np.diff(rec.time), 0.002)  # ten 4 s files at 500 Hz, from rest
    assert rec.channels["hub1"][0] == 0.0 and math.isclose(rec.channels["hub1_reference"][-1], 0.0)
    nominal, diagnosed = resimulate(rec), resimulate(rec, effects, parameters)
    score = {name: {c: nrmse(rec.channels[c], sim.channels[c]) for c in ("hub1", "link1")}
             for name, sim in (("nominal", nominal), ("diagnosed", diagnosed))}
    assert score["nominal"]["link1"] > 3.0 and score["diagnosed"]["link1"] < 0.5
    assert score["diagnosed"]["hub1"] < 0.5 * score["nominal"]["hub1"]


def test_a_run_cut_from_a_longer_one_starts_its_linear_law_as_it_held_there():
    """Each of the lab's files is a cut of one long run, the arm at rest at the last step, the LQG's Kalman estimate
    long settled there. Started at rest away from the nominal pose, a `linear` law takes the state it holds at those
    readings (x = A x + B u, to 1e-12), not its reset's zero, whose estimate of 0 deg at -20 deg kicked the hub:
    re-simulating the -20 -> 20 deg file alone, hub 1 in its first 0.3 s is within 0.52 deg of the recording
    (4.04 deg from a zero state; the nine files' median NRMSE 0.151 -> 0.069)."""
    from watflex_sim.recording import read_recording
    from watflex_sim.resim import resimulate

    # the 20 deg step, from rest at -20 deg (STEPS_DEG), read as the lab logged it (rigs/quanser_2dsfl_lab_lqg.toml)
    rec = read_recording(LAB / "lqg_step_20deg_run01.mat", sidecar=load_rig("quanser_2dsfl_lab_lqg").sidecar)
    folded = _saved("lqg_ss")
    law = Linear(["current1_cmd"], INPUTS, A=folded["A"], B=folded["B"], C=folded["C"], D=folded["D"], period_s=0.01,
                 period=0.002)
    first = {"hub1": rec.channels["hub1"][0], "link1": rec.channels["link1"][0], "hub1_reference": -20 * math.pi / 180}
    law.settle(first)
    u = np.array([first["hub1"], first["link1"], 0, 0, first["hub1_reference"], 0, 0, 0])
    assert np.max(np.abs(folded["A"] @ law.x + folded["B"] @ u - law.x)) < 1e-12
    sim = resimulate(rec)
    early = rec.time < 0.3
    assert np.degrees(np.max(np.abs(rec.channels["hub1"][early] - sim.channels["hub1"][early]))) < 1.0


def test_the_shipped_lqg_scenario_steps_hub_1_as_the_labs_rig_does():
    """scenarios/quanser_lab_lqg_step.toml (the LQG as data, the model diagnosed on Quanser's runs): from 1.5 s after
    the step on, hub 1 within 0.3 deg of 10 deg and link 1 within 0.5 deg (measured 0.17 and 0.39 deg; the lab's rig,
    1.5 s after its -5 -> 10 deg step: link 1 within 0.23 deg, hub 1 at 9.49 deg, stuck short). The same loop on the
    nominal model limit-cycles: link 1's swing grows from the first second to the third."""
    from watflex_sim.engine import simulate
    from watflex_sim.scenario import load_scenario

    scenario = load_scenario("quanser_lab_lqg_step")
    rec = simulate(scenario).recording
    late = rec.time >= 2.0
    assert np.degrees(np.max(np.abs(rec.channels["hub1"][late] - 10 * math.pi / 180))) < 0.3
    assert np.degrees(np.max(np.abs(rec.channels["link1"][late]))) < 0.5
    nominal = simulate({**scenario, "effects": [], "parameters": {}}).recording
    swing = [np.ptp(nominal.channels["link1"][(nominal.time >= a) & (nominal.time < a + 0.5)]) for a in (1.0, 2.5)]
    assert swing[1] > 1.2 * swing[0] > 0.02


def test_a_friction_is_sized_by_the_effort_the_model_commands_where_no_command_is_recorded(tmp_path):
    """The lab logged no current: a friction's catalogue bounds, in units of the peak actuator torque, take it from the
    nominal model run on the recording's experiment: the LQG's 0.6 A clip through drive 1's 8.925 N m/A = 5.355 N m
    (before, 1 N m by default, and the fits of the lab's runs sat on that bound: Coulomb 0.904 [0.52, 1] N m)."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis.motion import simulated_effort
    from watflex_sim.recording import read_recording

    rec = read_recording(lab_runs.write(*lab_runs.stair(LAB, "lqg"), tmp_path / "lqg_stair"))
    data = SimpleNamespace(recordings=[rec], rig=load_rig("quanser_2dsfl"), effort_memo=None)
    assert "current1_cmd" not in rec.channels
    assert simulated_effort(data) == pytest.approx(0.6 * 8.925, rel=1e-6)
