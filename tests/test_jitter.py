"""Sample-period jitter as data (issue 15 item 3): a rig's `control_jitter_s` delays each command
by a whole number of physics steps drawn uniformly on 0..jitter/timestep per tick from the seed."""
import mujoco
import numpy as np
import pytest

from watflex_sim.engine import ControlLoop, simulate
from watflex_sim.model import ConfigError, ROOT
from watflex_sim.rigdesc import load_rig
from watflex_sim.scenario import load_scenario

SCENARIO = """rig = "jittery"
experiment = "jittery_moves"
duration_s = {duration}
reference = {{ channel = "qg", kind = "triangle", amplitude = 0.02, slope = 0.04, periods = 1 }}
[controller]
type = "cascade_p"
kp = 160.18
kv = 243.45
"""  # rigs/emps.toml's gains


def make_rig(tmp_path, monkeypatch, jitter: str | None, period: str = "0.002"):
    """The bundled EMPS rig (0.5 ms physics step) as `jittery`, at a 2 ms sample period, with the
    given control_jitter_s line (None: no such key); returns the path of a scenario file."""
    folder = tmp_path / f"rig{jitter}"
    folder.mkdir()
    text = (ROOT / "rigs" / "emps.toml").read_text().replace('name = "emps"', 'name = "jittery"')
    text = text.replace('model = "emps"', f'model = "{ROOT / "models" / "emps.xml"}"').replace('rig = "emps"', 'rig = "jittery"')
    head = f"control_period_s = {period}\n" + (f"control_jitter_s = {jitter}\n" if jitter is not None else "")
    (folder / "rig.toml").write_text(text.replace("[channels]", head + "\n[channels]", 1))
    monkeypatch.setenv("WATFLEX_RIGS", str(folder))
    return folder


def scenario(tmp_path, over=(), duration=1.0):
    path = tmp_path / "moves.toml"
    path.write_text(SCENARIO.format(duration=duration))
    return load_scenario(str(path), list(over))


def test_no_jitter_is_the_recording_without_the_key(tmp_path, monkeypatch):
    """control_jitter_s = 0 runs the code path of a rig without it: every channel bit for bit."""
    make_rig(tmp_path, monkeypatch, None)
    plain = simulate(scenario(tmp_path)).recording
    make_rig(tmp_path, monkeypatch, "0.0")
    zero = simulate(scenario(tmp_path)).recording
    for c in plain.channels:
        np.testing.assert_array_equal(plain.channels[c], zero.channels[c])


def test_the_command_arrives_as_late_as_declared_and_the_seed_repeats_it(tmp_path, monkeypatch):
    """Jitter 1.5 ms on 0.5 ms steps: delays of 0, 0.5, 1, 1.5 ms equally likely, mean 0.75 ms
    (jitter / 2); measured from the plant input the physics steps see over 1000 ticks (2 s),
    the mean is within 10 % of it and every delay occurs. Same seed, same recording."""
    make_rig(tmp_path, monkeypatch, "0.0015")
    s = scenario(tmp_path, duration=2.0)
    steps, original = [], mujoco.mj_step

    def logged(model, data, nstep=1):
        steps.append((nstep, data.ctrl.copy()))
        original(model, data, nstep=nstep)

    delays = []
    with ControlLoop(s) as loop:
        monkeypatch.setattr(mujoco, "mj_step", logged)
        for k in range(loop.n_ticks):
            steps.clear()
            loop.tick(k)
            final = loop.data.ctrl.copy()
            delays.append(sum(n for n, ctrl in steps if not np.array_equal(ctrl, final)) * loop.model.opt.timestep)
        monkeypatch.setattr(mujoco, "mj_step", original)
    delays = np.array(delays)
    assert len(delays) == 1000 and loop.model.opt.timestep == 0.0005
    assert np.mean(delays) == pytest.approx(0.0015 / 2, rel=0.10)
    assert set(np.round(delays * 1e4).astype(int)) == {0, 5, 10, 15}  # 0.1 ms units
    a, b = simulate(s).recording, simulate(s).recording
    other = simulate(scenario(tmp_path, ["seed=7"], duration=2.0)).recording
    np.testing.assert_array_equal(a.channels["qm"], b.channels["qm"])
    assert not np.array_equal(a.channels["qm"], other.channels["qm"])
    assert a.meta["control_jitter_s"] == 0.0015


@pytest.mark.parametrize("jitter", ["-0.001", "0.002", "true"])
def test_jitter_must_be_below_the_period_and_not_negative(tmp_path, monkeypatch, jitter):
    make_rig(tmp_path, monkeypatch, jitter)
    with pytest.raises(ConfigError, match="rig.toml: control_jitter_s must be .* below control_period_s"):
        load_rig("jittery")


def test_jitter_must_be_whole_physics_steps(tmp_path, monkeypatch):
    make_rig(tmp_path, monkeypatch, "0.0007")
    with pytest.raises(ConfigError, match="rig.toml: control_jitter_s 0.0007 s is not a whole number of physics steps"):
        ControlLoop(scenario(tmp_path))
