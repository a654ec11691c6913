"""Tests for watflex_sim.recording: the recording contract of recordings.md section 1."""
import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import given, settings
from hypothesis import strategies as st

from watflex_sim.recording import (
    CHANNELS, FORMAT, Recording, RecordingError, read_recording, validate, write_recording)

FUZZ = settings(max_examples=100, deadline=None, derandomize=True)

META = {"format": FORMAT, "rig": "laser_arm", "experiment": "laser_arm_step",
        "payload_kg": 0.7, "controller": {"type": "pd_tip", "kp": 0.127, "kd": 0.0},
        "mode": "closed_loop", "notes": "free text", "extra_key": [1, 2, {"a": None}]}

GOOD_CSV = "time,hub_angle,tip_sensor\n0,0.1,1\n0.001,0.2,\n0.002,0.3,3\n"


def exact(x):
    """Round to a value that survives the .10g text format unchanged."""
    return float(format(x, ".10g"))


def sample_recording(n=50, rig="laser_arm"):
    time = np.array([exact(0.001 * i) for i in range(n)])
    hub = np.array([exact(np.sin(3.1 * t) + 1e-7) for t in time])
    tip = np.array([exact(-7.25 * np.cos(t) * 1e3) for t in time])
    tip[[0, n // 2, n - 1]] = np.nan
    return Recording(time, {"tip_sensor": tip, "hub_angle": hub}, dict(META, rig=rig))


def put(directory, csv_text=GOOD_CSV, sidecar=META, name="r", suffix=".csv"):
    """Write a data file (text or bytes) and a sidecar (dict, text, or None) into directory."""
    path = Path(directory) / f"{name}{suffix}"
    if isinstance(csv_text, bytes):
        path.write_bytes(csv_text)
    elif csv_text is not None:
        path.write_text(csv_text)
    if isinstance(sidecar, bytes):
        path.with_suffix(".json").write_bytes(sidecar)
    elif sidecar is not None:
        text = sidecar if isinstance(sidecar, str) else json.dumps(sidecar)
        path.with_suffix(".json").write_text(text)
    return path


def assert_valid(rec):
    """What any successfully read recording must satisfy."""
    assert isinstance(rec, Recording)
    assert rec.time.ndim == 1 and rec.time.dtype == np.float64 and len(rec.time) >= 2
    assert np.all(np.isfinite(rec.time)) and np.all(np.diff(rec.time) > 0)
    assert rec.channels and set(rec.channels) <= set(CHANNELS[rec.rig])
    for x in rec.channels.values():
        assert x.shape == rec.time.shape and x.dtype == np.float64
        assert not np.all(np.isnan(x)) and not np.any(np.isinf(x))
    assert rec.meta["format"] == FORMAT


def read_or_error(path, **kw):
    """Read; a RecordingError is fine (one line), anything else fails the test."""
    try:
        rec = read_recording(path, **kw)
    except RecordingError as err:
        assert "\n" not in str(err) and "\r" not in str(err)
        return None
    assert_valid(rec)
    return rec


# --- vocabulary ----------------------------------------------------------------------------

def test_channels_match_the_vocabulary_table():
    assert {rig: CHANNELS[rig] for rig in ("laser_arm", "watflex")} == {
        "laser_arm": {"reference": "rad", "hub_angle": "rad", "tip_sensor": "V",
                      "voltage_cmd": "V", "motor_current": "A"},
        "watflex": {"shoulder_reference": "rad", "elbow_reference": "rad",
                    "shoulder_angle": "rad", "elbow_angle": "rad",
                    "shoulder_torque_cmd": "N m", "elbow_torque_cmd": "N m",
                    "strain_1A": "V", "strain_1B": "V", "strain_1C": "V", "strain_2A": "V",
                    "strain_2B": "V", "tip_x": "m", "tip_y": "m"}}
    assert FORMAT == "flexarm-recording/1"


def test_rig_and_units():
    rec = sample_recording()
    assert rec.rig == "laser_arm"
    assert rec.units() == {"tip_sensor": "V", "hub_angle": "rad"}


# --- writing and reading ---------------------------------------------------------------------

def test_round_trip_is_exact_and_keeps_nan(tmp_path):
    rec = sample_recording()
    path = write_recording(rec, tmp_path, "step")
    assert path == tmp_path / "step.csv" and (tmp_path / "step.json").is_file()
    back = read_recording(path)
    assert_valid(back)
    np.testing.assert_array_equal(back.time, rec.time)
    assert list(back.channels) == ["tip_sensor", "hub_angle"]
    for name, x in rec.channels.items():
        np.testing.assert_array_equal(back.channels[name], x)  # NaN == NaN here
    assert np.isnan(back.channels["tip_sensor"][[0, 25, 49]]).all()
    assert back.meta == rec.meta


def test_watflex_round_trip_with_all_channels(tmp_path):
    rng = np.random.default_rng(0)
    time = np.array([exact(t) for t in np.cumsum(rng.uniform(1e-4, 2e-3, 30))])
    chans = {n: np.array([exact(v) for v in rng.normal(size=30)]) for n in CHANNELS["watflex"]}
    rec = Recording(time, chans, {"format": FORMAT, "rig": "watflex"})
    back = read_recording(write_recording(rec, tmp_path, "w"))
    np.testing.assert_array_equal(back.time, time)
    assert list(back.channels) == list(CHANNELS["watflex"])
    for name in chans:
        np.testing.assert_array_equal(back.channels[name], chans[name])


def test_write_sets_format_and_does_not_touch_callers_meta(tmp_path):
    rec = sample_recording()
    del rec.meta["format"]
    write_recording(rec, tmp_path, "r")
    assert "format" not in rec.meta
    text = (tmp_path / "r.json").read_text()
    assert text == json.dumps(dict(rec.meta, format=FORMAT), indent=2, sort_keys=True) + "\n"
    assert read_recording(tmp_path / "r.csv").meta["format"] == FORMAT


def test_csv_text_is_deterministic_and_byte_identical(tmp_path):
    rec = Recording(np.array([0.0, 0.001, 0.002]),
                    {"hub_angle": np.array([0.1, np.nan, -2.5e-12])}, {"rig": "laser_arm"})
    a = write_recording(rec, tmp_path / "a", "r").read_bytes()
    b = write_recording(rec, tmp_path / "b", "r").read_bytes()
    c = write_recording(sample_recording(), tmp_path / "c", "r").read_bytes()
    d = write_recording(sample_recording(), tmp_path / "c", "r").read_bytes()  # overwrite
    assert a == b == b"time,hub_angle\n0,0.1\n0.001,\n0.002,-2.5e-12\n"
    assert c == d
    assert sorted(os.listdir(tmp_path / "c")) == ["r.csv", "r.json"]


def test_write_creates_missing_directory(tmp_path):
    path = write_recording(sample_recording(), tmp_path / "x" / "y", "r")
    assert path.is_file()


def test_sidecar_argument_replaces_the_json_file(tmp_path):
    path = put(tmp_path, sidecar=None)
    rec = read_recording(path, sidecar=META)
    assert rec.meta == META and rec.meta is not META
    assert np.isnan(rec.channels["tip_sensor"][1])


def test_reader_tolerates_bom_crlf_spaces_blank_lines_and_nan_text(tmp_path):
    text = "\ufefftime, hub_angle ,tip_sensor\r\n0, 0.5 ,NaN\r\n\r\n1e-3,\"0.25\",2\r\n"
    rec = read_recording(put(tmp_path, text))
    np.testing.assert_array_equal(rec.time, [0.0, 0.001])
    np.testing.assert_array_equal(rec.channels["hub_angle"], [0.5, 0.25])
    np.testing.assert_array_equal(rec.channels["tip_sensor"], [np.nan, 2.0])


def test_reads_a_10s_1khz_12_channel_file_quickly(tmp_path):
    import time as clock
    n = 10_000
    t = np.array([exact(0.001 * i) for i in range(n)])
    names = list(CHANNELS["watflex"])[:12]
    chans = {name: np.round(np.sin(t * (k + 1)), 9) for k, name in enumerate(names)}
    path = write_recording(Recording(t, chans, {"rig": "watflex"}), tmp_path, "big")
    start = clock.perf_counter()
    rec = read_recording(path)
    assert clock.perf_counter() - start < 1.0
    assert len(rec.time) == n and len(rec.channels) == 12


def test_reads_mat_files_with_row_and_column_vectors(tmp_path):
    time = np.arange(5) * 1e-3
    hub = np.array([0.0, 0.1, np.nan, 0.3, 0.4])
    scipy.io.savemat(tmp_path / "m.mat", {"time": time.reshape(-1, 1), "hub_angle": hub,
                                          "motor_current": np.arange(5, dtype=np.int16),
                                          "controller": "lqr", "notes": ["run 1", "hot"]})  # text: passed over
    put(tmp_path, None, META, name="m")
    rec = read_recording(tmp_path / "m.mat")
    assert_valid(rec)
    assert set(rec.channels) == {"hub_angle", "motor_current"}
    np.testing.assert_array_equal(rec.time, time)
    np.testing.assert_array_equal(rec.channels["hub_angle"], hub)
    np.testing.assert_array_equal(rec.channels["motor_current"], [0, 1, 2, 3, 4])
    assert rec.meta == META


def save_v73(path, variables: dict) -> None:
    """A MATLAB v7.3 file as MATLAB writes one (`save -v7.3`): a 512-byte user block holding the MAT header, then
    HDF5 with each array transposed (MATLAB's column-major order) and its MATLAB_class; text as 16-bit codes; a
    struct as a group. Written with h5py, as hdf5storage does (no MATLAB here)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            if isinstance(value, dict):
                group = f.create_group(name)
                group.attrs["MATLAB_class"] = np.bytes_("struct")
                for field, v in value.items():
                    group.create_dataset(field, data=np.atleast_2d(v).T).attrs["MATLAB_class"] = np.bytes_("double")
                continue
            text = isinstance(value, str)
            array = np.array([[ord(c) for c in value]], dtype=np.uint16) if text else np.atleast_2d(value)
            cls = "char" if text else {"f": "double", "c": "double"}.get(array.dtype.kind, str(array.dtype))
            f.create_dataset(name, data=array.T).attrs["MATLAB_class"] = np.bytes_(cls)
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(116) + bytes(8) + b"\x00\x02IM")


def test_reads_mat_v73_files_as_their_v5_twins(tmp_path):
    """A v7.3 file (HDF5) gives what the same variables saved as v5 give: column and row vectors, an int16 channel, a
    scalar for the sidecar ("mat:NAME"), text and a struct passed over; a complex channel refused by name."""
    time = np.arange(5) * 1e-3
    variables = {"time": time.reshape(-1, 1), "hub_angle": np.array([0.0, 0.1, np.nan, 0.3, 0.4]),
                 "motor_current": np.arange(5, dtype=np.int16), "controller": "pd_tip", "setup": {"kp": 0.127}}
    scipy.io.savemat(tmp_path / "v5.mat", variables)
    save_v73(tmp_path / "v73.mat", variables)
    assert (tmp_path / "v73.mat").read_bytes()[512:516] == b"\x89HDF"
    put(tmp_path, None, META, name="v5")
    put(tmp_path, None, META, name="v73")
    v5, v73 = read_recording(tmp_path / "v5.mat"), read_recording(tmp_path / "v73.mat")
    assert_valid(v73)
    np.testing.assert_array_equal(v73.time, v5.time)
    assert set(v73.channels) == set(v5.channels) == {"hub_angle", "motor_current"}
    for channel in v5.channels:
        np.testing.assert_array_equal(v73.channels[channel], v5.channels[channel])
    save_v73(tmp_path / "v73.mat", {**variables, "hub_angle": variables["hub_angle"] * 1j})
    with pytest.raises(RecordingError, match=r"v73\.mat: MATLAB variable 'hub_angle' is not a plain real numeric"):
        read_recording(tmp_path / "v73.mat")


@pytest.mark.parametrize("variables, match", [
    ({"hub_angle": np.ones(3)}, r"no 'time' variable"),
    ({"time": np.arange(3.0), "hub_angle": np.ones(3), "tout": np.ones(3)},
     r"unknown channel for rig 'laser_arm': 'tout'$"),
    ({"time": np.arange(3.0), "hub_angle": np.ones((3, 2))}, r"'hub_angle' is not a vector"),
    ({"time": np.arange(3.0), "hub_angle": "abc"}, r"'hub_angle' is not a plain real numeric"),
    ({"time": np.arange(3.0), "hub_angle": np.ones(3) * 1j}, r"'hub_angle' is not a plain real"),
    ({"time": np.arange(3.0), "hub_angle": {"a": 1.0}}, r"'hub_angle' is not a plain real"),
    ({"time": np.arange(3.0), "hub_angle": np.ones(4)}, r"'hub_angle' has 4 samples, time has 3"),
    ({"time": [0.0, 2.0, 1.0], "hub_angle": np.ones(3)},
     r"time is not strictly increasing at sample 2 \(1 s after 2 s\)"),
])
def test_mat_errors(tmp_path, variables, match):
    scipy.io.savemat(tmp_path / "m.mat", variables)
    put(tmp_path, None, META, name="m")
    with pytest.raises(RecordingError, match=match) as err:
        read_recording(tmp_path / "m.mat")
    assert "\n" not in str(err.value) and str(err.value).startswith(str(tmp_path / "m.mat"))


@pytest.mark.parametrize("raw, match", [
    (b"MATLAB 5.0 garbage" * 20, r"not a MATLAB v5, v7 or v7.3 file"),
    (b"MATLAB 7.3 MAT-file".ljust(124) + b"\x00\x02IM" + b"\x89HDF\r\n" * 10,
     r"not a MATLAB v5, v7 or v7.3 file \(v4 is not supported\)"),
    (b"MATLAB 7.3 MAT-file".ljust(124) + b"\x00\x02IM" + bytes(384) + b"\x89HDF\r\n\x1a\n" + b"garbage" * 20,
     r"cannot read MATLAB v7.3 file: "),
    (b"MATLAB 5.0 MAT-file".ljust(124) + b"\x00\x01IM" + b"\x0e\x00\x00\x00\xff\x00\x00\x00",
     r"truncated MATLAB file"),
])
def test_corrupt_mat_file(tmp_path, raw, match):
    with pytest.raises(RecordingError, match=r"m\.mat: " + match):
        read_recording(put(tmp_path, raw, META, name="m", suffix=".mat"))


def test_mat_data_of_an_invalid_type_is_refused_not_a_crash(tmp_path):
    # scipy.io.loadmat segfaults on this (data element type 0 in a double array).
    raw = bytearray(valid_mat_bytes())
    at = raw.rindex(b"hub_angle") + 16  # the tag of hub_angle's data element
    assert raw[at:at + 4] == b"\x09\x00\x00\x00"  # miDOUBLE
    raw[at:at + 4] = bytes(4)
    with pytest.raises(RecordingError, match=r"variable 'hub_angle' is not a plain real numeric"):
        read_recording(put(tmp_path, bytes(raw), META, name="m", suffix=".mat"))


# --- one test per reading error ---------------------------------------------------------------

@pytest.mark.parametrize("csv_text, sidecar, match", [
    pytest.param(GOOD_CSV, "{not json", r"r\.json: sidecar is not valid JSON", id="bad-json"),
    pytest.param(GOOD_CSV, "[1, 2]", r"r\.json: sidecar is not a JSON object", id="not-object"),
    pytest.param(GOOD_CSV, b'{"rig": "\xff"}', r"r\.json: sidecar is not UTF-8", id="json-bytes"),
    pytest.param(GOOD_CSV, {"rig": "laser_arm"}, r"r\.json: sidecar has no 'format'",
                 id="missing-format"),
    pytest.param(GOOD_CSV, dict(META, format="flexarm-recording/2"),
                 r"format 'flexarm-recording/2' is not 'flexarm-recording/1'", id="wrong-format"),
    pytest.param(GOOD_CSV, {"format": FORMAT}, r"sidecar has no 'rig'", id="missing-rig"),
    pytest.param(GOOD_CSV, dict(META, rig="scara"), r"unknown rig 'scara'", id="unknown-rig"),
    pytest.param(GOOD_CSV, dict(META, rig="watflex"),
                 r"unknown channels for rig 'watflex': 'hub_angle', 'tip_sensor'$",
                 id="channel-of-other-rig"),
    pytest.param("", META, r"r\.csv: empty file", id="empty-file"),
    pytest.param(b"time,hub_angle\n0,\xff\n", META, r"r\.csv: not UTF-8 text", id="not-utf8"),
    pytest.param("hub_angle,tip_sensor\n1,2\n3,4\n", META, r"no 'time' column", id="no-time"),
    pytest.param("time,hub_angle,foo,tip_sensor,bar\n0,1,2,3,4\n1,1,2,3,4\n", META,
                 r"unknown channels for rig 'laser_arm': 'foo', 'bar'$", id="unknown-channel"),
    pytest.param("time,hub_angle,hub_angle\n0,1,2\n1,1,2\n", META,
                 r"duplicate column 'hub_angle'", id="duplicate-column"),
    pytest.param("time,,hub_angle\n0,1,2\n1,1,2\n", META, r"empty column name.*column 2",
                 id="empty-column-name"),
    pytest.param("time,hub_angle\n0,1\n0.001,abc\n", META,
                 r"line 3, column 'hub_angle': 'abc' is not a number", id="non-numeric"),
    pytest.param("time,hub_angle\n0,1\n0.001,1_0\n", META,
                 r"line 3, column 'hub_angle': '1_0' is not a number", id="underscore"),
    pytest.param("time,hub_angle\n0,1\nx,1\n", META,
                 r"line 3, column 'time': 'x' is not a number", id="non-numeric-time"),
    pytest.param("time,hub_angle\n0,1\n0.001,1,2\n", META,
                 r"line 3 has 3 fields, header has 2", id="too-many-fields"),
    pytest.param("time,hub_angle\n0,1\n0.001\n0.002,3\n", META,
                 r"line 3 has 1 fields, header has 2", id="too-few-fields"),
    pytest.param("time,hub_angle\n0,1\n", META, r"fewer than 2 samples \(1\)", id="one-sample"),
    pytest.param("time,hub_angle\n", META, r"fewer than 2 samples \(0\)", id="header-only"),
    pytest.param("time,hub_angle\n0,1\n,2\n", META, r"time is not finite at line 3",
                 id="empty-time"),
    pytest.param("time,hub_angle\n0,1\ninf,2\n", META, r"time is not finite at line 3",
                 id="infinite-time"),
    pytest.param("time,hub_angle\n0,1\n0.002,2\n0.001,3\n", META,
                 r"time is not strictly increasing at line 4 \(0\.001 s after 0\.002 s\)",
                 id="time-decreasing"),
    pytest.param("time,hub_angle\n0,1\n0.001,2\n0.001,3\n", META,
                 r"time is not strictly increasing at line 4", id="time-repeated"),
    pytest.param("time,hub_angle,tip_sensor\n0,1,\n0.001,2,nan\n", META,
                 r"channel 'tip_sensor' has no samples", id="all-nan-channel"),
    pytest.param("time,hub_angle\n0,1\n0.001,-inf\n", META,
                 r"channel 'hub_angle' is infinite at line 3", id="infinite-value"),
    pytest.param("time\n0\n0.001\n", META, r"r\.csv: no channels", id="no-channels"),
    pytest.param('time,hub_angle\n0,"1\n', META, r"r\.csv: malformed CSV", id="open-quote"),
    pytest.param("time,hub_angle\n0,1\x00\n1,2\n", META, r"r\.csv: malformed CSV|not a number",
                 id="nul-byte"),
])
def test_read_errors(tmp_path, csv_text, sidecar, match):
    path = put(tmp_path, csv_text, sidecar)
    with pytest.raises(RecordingError, match=match) as err:
        read_recording(path)
    message = str(err.value)
    assert "\n" not in message and "\r" not in message
    assert str(tmp_path) in message
    assert "reference" not in message  # the vocabulary is never listed


def test_missing_file(tmp_path):
    with pytest.raises(RecordingError, match=r"nothere\.csv: file not found") as err:
        read_recording(tmp_path / "nothere.csv")
    assert "\n" not in str(err.value)


def test_unreadable_file(tmp_path):
    (tmp_path / "d.csv").mkdir()
    put(tmp_path, None, META, name="d")
    with pytest.raises(RecordingError, match=r"d\.csv: cannot read d\.csv: Is a directory") as err:
        read_recording(tmp_path / "d.csv")
    assert "\n" not in str(err.value)


def test_unreadable_sidecar_and_nul_in_path(tmp_path):
    path = put(tmp_path, GOOD_CSV, None)
    (tmp_path / "r.json").mkdir()
    with pytest.raises(RecordingError, match=r"r\.csv: cannot read r\.json"):
        read_recording(path)
    with pytest.raises(RecordingError, match=r"cannot read a\x00b\.csv"):
        read_recording(tmp_path / "a\0b.csv")


def test_not_a_recording_suffix(tmp_path):
    path = put(tmp_path, GOOD_CSV, META, suffix=".xlsx")
    with pytest.raises(RecordingError, match=r"r\.xlsx: not a recording \(\.csv, \.txt, \.tsv, \.dat text or \.mat\)"):
        read_recording(path)


def test_missing_sidecar(tmp_path):
    path = put(tmp_path, GOOD_CSV, None)
    with pytest.raises(RecordingError, match=r"r\.csv: sidecar r\.json not found") as err:
        read_recording(path)
    assert "\n" not in str(err.value)


def test_given_sidecar_is_checked_too(tmp_path):
    with pytest.raises(RecordingError, match=r"r\.csv: unknown rig 'scara'"):
        read_recording(put(tmp_path, sidecar=None), sidecar=dict(META, rig="scara"))
    with pytest.raises(RecordingError, match=r"r\.csv: sidecar is not a JSON object"):
        read_recording(put(tmp_path, sidecar=None), sidecar=["rig"])


def test_error_message_is_one_line_even_for_multiline_causes(tmp_path):
    path = put(tmp_path, "time,hub_angle\n0,1\n0.001,\"a\nb\"\n")
    with pytest.raises(RecordingError, match="is not a number") as err:
        read_recording(path)
    assert "\n" not in str(err.value)
    assert "\n" not in str(RecordingError("a\nb.csv", "x\r\ny\u2028z"))


# --- validate and atomic writing ---------------------------------------------------------------

@pytest.mark.parametrize("change, match", [
    (lambda r: r.channels.update(hub_angle=r.channels["hub_angle"][:-1]),
     r"'hub_angle' has 49 samples, time has 50"),
    (lambda r: r.channels.update(hub_angle=np.ones((50, 2))), r"'hub_angle' is not a vector"),
    (lambda r: r.channels.update(hub_angle=np.array(["a"] * 50)), r"not real numeric"),
    (lambda r: r.channels.update(foo=np.ones(50)), r"unknown channel for rig 'laser_arm': 'foo'$"),
    (lambda r: r.channels.clear(), r"no channels"),
    (lambda r: r.channels.update(hub_angle=np.full(50, np.nan)), r"'hub_angle' has no samples"),
    (lambda r: r.time.__setitem__(3, r.time[2]), r"not strictly increasing at sample 3"),
    (lambda r: r.time.__setitem__(0, np.nan), r"time is not finite at sample 0"),
    (lambda r: r.meta.update(rig="scara"), r"unknown rig 'scara'"),
    (lambda r: r.meta.update(format="other/1"), r"format 'other/1' is not"),
])
def test_validate_errors(change, match):
    rec = sample_recording()
    change(rec)
    with pytest.raises(RecordingError, match=r"^mine: .*" + match) as err:
        validate(rec, "mine")
    assert "\n" not in str(err.value)


def test_validate_returns_float_arrays():
    rec = Recording([0, 1, 2], {"hub_angle": [1, 2, 3]}, {"rig": "laser_arm"})
    out = validate(rec)
    assert out.time.dtype == np.float64 and out.channels["hub_angle"].dtype == np.float64


def test_failed_write_leaves_nothing_behind(tmp_path):
    (tmp_path / "keep.txt").write_text("x")
    bad = sample_recording()
    bad.time[5] = bad.time[4]
    with pytest.raises(RecordingError, match="not strictly increasing"):
        write_recording(bad, tmp_path, "r")
    with pytest.raises(RecordingError, match="not JSON-serialisable"):
        write_recording(Recording(bad.time[:3], {"hub_angle": np.ones(3)},
                                  {"rig": "laser_arm", "x": object()}), tmp_path, "r")
    with pytest.raises(RecordingError, match="bad recording name"):
        write_recording(sample_recording(), tmp_path, "../r")
    with pytest.raises(RecordingError):
        write_recording(bad, tmp_path / "new", "r")
    assert os.listdir(tmp_path) == ["keep.txt"]


@pytest.mark.parametrize("fail_at", ["fsync", "replace"])
def test_io_failure_midway_leaves_nothing_behind(tmp_path, monkeypatch, fail_at):
    calls = []
    real = getattr(os, fail_at)

    def flaky(*args):
        calls.append(args)
        if len(calls) == 2:  # the second file: the csv is done (and, for replace, in place)
            raise OSError("disk full")
        return real(*args)

    monkeypatch.setattr(os, fail_at, flaky)
    with pytest.raises(OSError, match="disk full"):
        write_recording(sample_recording(), tmp_path, "r")
    monkeypatch.undo()
    assert os.listdir(tmp_path) == []


# --- fuzzing: the reader returns a valid recording or raises RecordingError, nothing else ------

@FUZZ
@given(st.binary(max_size=400), st.sampled_from([".csv", ".mat"]))
def test_fuzz_random_bytes(data, suffix):
    with tempfile.TemporaryDirectory() as d:
        read_or_error(put(d, data, META, suffix=suffix))


def valid_mat_bytes(compress=False):
    """A small v5 MAT file, with a fixed header text (savemat writes the date there)."""
    buffer = io.BytesIO()
    scipy.io.savemat(buffer, {"time": np.arange(6) * 1e-3, "hub_angle": np.arange(6.0)},
                     do_compression=compress)
    return b"MATLAB 5.0 MAT-file".ljust(116) + buffer.getvalue()[116:]


@FUZZ
@given(st.data(), st.booleans())
def test_fuzz_corrupted_mat_file(data, compress):
    raw = valid_mat_bytes(compress)
    at = data.draw(st.integers(0, len(raw) - 1))
    patch = data.draw(st.binary(min_size=1, max_size=8))
    keep = data.draw(st.booleans())  # overwrite, or insert
    raw = raw[:at] + patch + raw[at + (0 if keep else len(patch)):]
    with tempfile.TemporaryDirectory() as d:
        read_or_error(put(d, raw, META, suffix=".mat"))


@FUZZ
@given(st.booleans(), st.lists(st.text(max_size=30), max_size=8))
def test_fuzz_random_text_lines(with_header, lines):
    text = "\n".join((["time,hub_angle,tip_sensor"] if with_header else []) + lines)
    with tempfile.TemporaryDirectory() as d:
        read_or_error(put(d, text, META))


@FUZZ
@given(st.text(max_size=200))
def test_fuzz_random_sidecar(sidecar_text):
    with tempfile.TemporaryDirectory() as d:
        read_or_error(put(d, GOOD_CSV, sidecar_text))


@FUZZ
@given(st.lists(st.sampled_from([0.0, 0.001, 0.002, 0.003, 0.5, -1.0, 1e300]),
                min_size=2, max_size=8).flatmap(lambda ts: st.permutations(ts)))
def test_fuzz_shuffled_and_duplicated_time(times):
    rows = "".join(f"{format(t, '.10g')},{k}\n" for k, t in enumerate(times))
    with tempfile.TemporaryDirectory() as d:
        rec = read_or_error(put(d, "time,hub_angle\n" + rows, META))
    if all(b > a for a, b in zip(times, times[1:])):
        assert rec is not None
        np.testing.assert_array_equal(rec.time, times)
    else:
        assert rec is None


@FUZZ
@given(st.data())
def test_fuzz_garbage_cell_in_a_valid_file(data):
    rec = sample_recording(n=6)
    with tempfile.TemporaryDirectory() as d:
        path = write_recording(rec, d, "r")
        rows = [line.split(",") for line in path.read_text().splitlines()]
        k = data.draw(st.integers(0, len(rows) - 1))
        j = data.draw(st.integers(0, len(rows[k]) - 1))
        rows[k][j] = data.draw(st.one_of(
            st.text(max_size=12), st.sampled_from(["", "nan", "inf", "-0", "1e999", '"', ",,"])))
        path.write_text("\n".join(",".join(r) for r in rows) + "\n")
        read_or_error(path)


@FUZZ
@given(st.data())
def test_fuzz_garbage_inserted_anywhere(data):
    rec = sample_recording(n=6)
    with tempfile.TemporaryDirectory() as d:
        path = write_recording(rec, d, "r")
        raw = path.read_bytes()
        at = data.draw(st.integers(0, len(raw)))
        garbage = data.draw(st.binary(min_size=1, max_size=8))
        path.write_bytes(raw[:at] + garbage + raw[at:])
        read_or_error(path)
