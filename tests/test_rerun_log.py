"""Round-trip test of watflex_sim.rerun_log: write an .rrd headless, read the sample counts back."""

import numpy as np
import pytest

pytest.importorskip("rerun")

from watflex_sim.rerun_log import channel_group, log_run, read_rrd_channels  # noqa: E402


def _synthetic(n=2000, n_frames=20):
    t = np.arange(n) * 1e-3
    strain = 1e-4 * np.sin(2 * np.pi * 3 * t)
    strain[100:350] = np.nan  # 250 missing samples
    strain[-1] = np.nan  # 1 more
    channels = {
        "hub_angle": 0.5 * np.sin(2 * np.pi * t),
        "strain_link1": strain,
        "motor_cmd": np.clip(3 * np.cos(t), -5, 5),
        "motor_current": 0.1 * t,
    }
    units = {"hub_angle": "rad", "strain_link1": "", "motor_cmd": "V", "motor_current": "A"}
    frame_time = np.linspace(0.0, t[-1], n_frames)
    s = np.linspace(0.0, 1.0, 11)
    frames = np.stack(
        [np.stack([s * np.cos(a), s * np.sin(a), np.zeros_like(s)], axis=1) for a in 0.5 * np.sin(frame_time)]
    )
    return t, channels, units, frames, frame_time


def test_groups():
    assert channel_group("hub_angle") == "angles"
    assert channel_group("tip_angle") == "angles"
    assert channel_group("reference") == "angles"
    assert channel_group("hub_reference") == "angles"
    assert channel_group("strain_2") == "strains"
    assert channel_group("motor_cmd") == "commands"
    assert channel_group("motor_current") == "sensors"


def test_roundtrip(tmp_path):
    t, channels, units, frames, frame_time = _synthetic()
    path = tmp_path / "x.rrd"
    log_run(t, channels, units, rrd_path=path, frames=frames, frame_time=frame_time, recording_name="test run")
    assert path.exists() and path.stat().st_size > 0
    counts = read_rrd_channels(path)
    assert counts == {"hub_angle": 2000, "strain_link1": 2000 - 251, "motor_cmd": 2000, "motor_current": 2000}


def test_two_runs_in_one_process(tmp_path):
    t, channels, units, _, _ = _synthetic(n=500)
    log_run(t, {"hub_angle": channels["hub_angle"]}, units, rrd_path=tmp_path / "a.rrd")
    log_run(t[:100], {"motor_cmd": channels["motor_cmd"][:100]}, units, rrd_path=tmp_path / "b.rrd")
    assert read_rrd_channels(tmp_path / "a.rrd") == {"hub_angle": 500}
    assert read_rrd_channels(tmp_path / "b.rrd") == {"motor_cmd": 100}


def test_no_sink_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    t, channels, units, frames, frame_time = _synthetic(n=100, n_frames=3)
    assert log_run(t, channels, units, frames=frames, frame_time=frame_time) is None
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="display check is Linux-only")
def test_spawn_without_display_raises(monkeypatch):
    for var in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(var, raising=False)
    t, channels, units, _, _ = _synthetic(n=10)
    with pytest.raises(RuntimeError, match="Rerun viewer"):
        log_run(t, channels, units, spawn=True)
