"""An accelerometer on a link as data (quantity = "acceleration"; model.mount_accelerometers, rigs.GenericRig).

Checked against kinematics: what it reads is the second time derivative of its point's position, across the
link, less gravity (specific force); and the two drivers read it alike. The rig: the Quanser 2DSFL with an
accelerometer at the tip of link 1 and one halfway along link 2 (a rig file written to a temporary folder).
"""
from pathlib import Path

import mujoco
import numpy as np
import pytest

from watflex_sim.engine import simulate
from watflex_sim.lockstep import simulate_batch
from watflex_sim.model import ConfigError, load_model
from watflex_sim.rigdesc import load_rig
from watflex_sim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
ACCELEROMETERS = ('link1_acc = { unit = "m/s^2", kind = "measured", link = "link1", quantity = "acceleration", '
                  'length = 0.202 }\n'
                  'link2_acc = { unit = "m/s^2", kind = "measured", link = "link2", quantity = "acceleration", '
                  'length = 0.20185, x = 0.1 }\n')


def _rig_file(folder: Path, channels: str = ACCELEROMETERS) -> Path:
    text = (ROOT / "rigs" / "quanser_2dsfl.toml").read_text().replace('name = "quanser_2dsfl"', 'name = "quanser_acc"')
    path = folder / "quanser_acc.toml"
    path.write_text(text.replace("[channels]\n", "[channels]\n" + channels, 1))
    return path


def test_an_accelerometer_reads_its_points_acceleration_across_the_link_less_gravity(tmp_path):
    """Both hubs driven by sines for 1 s on a table tilted 0.01 rad across link 1: each physics step's reading equals
    (p(t+h) - 2 p(t) + p(t-h)) / h^2 - g, across the link at its point, to 0.5 % of the largest reading (measured
    0.08 %: the second difference of a point moved by semi-implicit Euler is its acceleration to first order)."""
    model = load_model(load_rig(str(_rig_file(tmp_path))), tilt_rad=0.01, tilt_azimuth_rad=np.pi / 2)
    data = mujoco.MjData(model)
    h = model.opt.timestep
    for name in ("link1_acc", "link2_acc"):
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"accelerometer_{name}")
        sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"accelerometer_{name}")
        mujoco.mj_resetData(model, data)
        where, across, read = [], [], []
        for k in range(round(1.0 / h)):
            data.ctrl[:] = [0.3 * np.sin(2 * np.pi * 1.5 * k * h), -0.2 * np.sin(2 * np.pi * 2.5 * k * h)]
            mujoco.mj_forward(model, data)
            where.append(data.site_xpos[site].copy())
            across.append(data.site_xmat[site].reshape(3, 3)[:, 1].copy())
            mujoco.mj_step(model, data)
            read.append(data.sensordata[model.sensor_adr[sensor] + 1])  # computed at the step's start
        where, across, read = np.array(where), np.array(across), np.array(read)
        second = (where[2:] - 2 * where[1:-1] + where[:-2]) / h**2 - model.opt.gravity
        expected = np.einsum("ij,ij->i", second, across[1:-1])
        assert np.max(np.abs(read[1:-1] - expected)) < 0.005 * np.max(np.abs(expected))
        assert np.max(np.abs(expected)) > 0.05  # m/s^2: it moved, and gravity's part (0.098) is in it


def test_a_run_records_the_accelerometers_alike_in_both_drivers(tmp_path, monkeypatch):
    """The lab's LQG step on the rig with accelerometers: channels recorded (link 1's tip swings, rms > 0.1 m/s^2),
    the lockstep driver's recording identical to the single run's, with the control half per member (a `parallel`
    law) and on arrays (state feedback)."""
    monkeypatch.setenv("WATFLEX_RIGS", str(_rig_file(tmp_path)))
    scenario = {**load_scenario("quanser_lab_lqg_step"), "rig": "quanser_acc", "duration_s": 1.5}
    feedback = {**scenario, "effects": [], "parameters": {}, "controller": {
        "type": "state_feedback", "commands": ["current1_cmd", "current2_cmd"],
        "states": ["hub1", "link1", "hub2", "link2"],
        "references": {"hub1": "hub1_reference"}, "gains": [[15.81, -42.93, 0, 0], [0, 0, 15.81, -40.33]]}}
    for case, size in ((scenario, 2), (feedback, 8)):
        alone = simulate(case).recording
        assert np.sqrt(np.mean(alone.channels["link1_acc"] ** 2)) > 0.1
        together = simulate_batch([{**case, "seed": i} for i in range(size)], nthread=2, always=True)[0].recording
        assert all(np.array_equal(alone.channels[c], together.channels[c], equal_nan=True) for c in alone.channels)


@pytest.mark.parametrize("channel, message", [
    ('a = { unit = "m/s^2", kind = "measured", quantity = "acceleration", length = 0.2 }',
     "or a link .deflection, strain, acceleration"),
    ('a = { unit = "m/s^2", kind = "measured", link = "link1", quantity = "acceleration" }', "needs the link's length"),
])
def test_an_accelerometer_without_its_place_fails_in_one_line(tmp_path, channel, message):
    with pytest.raises(ConfigError, match=message):
        load_rig(str(_rig_file(tmp_path, channel + "\n")))
