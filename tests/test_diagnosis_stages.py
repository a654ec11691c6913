"""The diagnosis' stages alone (issue 14), on inputs whose answer is known in closed form."""
import math
import types
from unittest.mock import patch

import numpy as np
import pytest

from watflex_sim import load_scenario, simulate
from watflex_sim.diagnosis import Model, Slot, intervals, prepare
from watflex_sim.diagnosis.data import NO_NOISE_FLOOR, split_blocks
from watflex_sim.diagnosis.noise import measured_noise
from watflex_sim.diagnosis.explain import direction, finding, indistinct, physical_place, units_at
from watflex_sim.diagnosis.fitting import huber_threshold, residual_variance
from watflex_sim.diagnosis.validate import explained_share
from watflex_sim.diagnosis.tolerance import fold_within_tolerance
from watflex_sim.model import load_model
from watflex_sim.rigdesc import load_rig
from watflex_sim.recording import Recording


@pytest.fixture(scope="module")
def laser_recordings():
    recs = []
    for i, direction_ in enumerate(("positive", "negative")):
        scenario = load_scenario("laser_arm_step", [f"direction={direction_}", "duration_s=0.4", f"seed={i}"])
        recs.append(simulate(scenario).recording)
    return recs


def test_prepare_is_the_same_whatever_the_file_order(laser_recordings):
    """Canonical order (by name, then content): the split, channels and noise do not depend on
    the order the files were given in."""
    a = prepare(laser_recordings, ["b.csv", "a.csv"])
    b = prepare(laser_recordings[::-1], ["a.csv", "b.csv"])
    assert a.names == b.names == ["a.csv", "b.csv"]
    assert all(np.array_equal(x, y) for x, y in zip(a.train, b.train))
    assert a.noise == b.noise and a.channels == b.channels


def test_every_recording_is_both_fitted_and_validated(laser_recordings):
    """Blocks in every recording (not a held-out file): about half of each recording's samples
    train, the other half validate; a periodic experiment whose period
    is two blocks (pulses every 0.2 s with 0.1 s blocks: the EMPS PULSES run against strictly
    alternate blocks) has pulses in both halves."""
    data = prepare(laser_recordings, ["a", "b"])
    for mask in data.train:
        assert 0.4 < mask.mean() < 0.6
    t = np.arange(0, 6.0, 1e-3)
    mask, block = split_blocks(t)
    assert block == pytest.approx(0.1, rel=1e-3)
    pulses = (t % 0.2) < 0.01
    assert 0.3 < (pulses & mask).sum() / pulses.sum() < 0.7


def test_recordings_of_one_length_are_split_each_its_own_way(laser_recordings):
    """Each recording's split is salted with its content: recordings of one length split alike would put a
    step's onset, at the same time in each, in one half in all of them (seed 58: a 2 ms laser sensor delay
    seen at the onsets only, 0.08-0.15 s, was fitted on every onset, validated on none, and rejected). The
    two 0.4 s recordings (20 ms blocks) differ; the same recording always splits the same way; over eight
    salts, the 0.1-0.2 s of a 6 s recording (a laser step's transient) fits in some and validates in others."""
    data = prepare(laser_recordings, ["a.csv", "b.csv"])
    assert not np.array_equal(data.train[0], data.train[1])
    again = prepare(laser_recordings, ["a.csv", "b.csv"])
    assert all(np.array_equal(x, y) for x, y in zip(data.train, again.train))
    t = np.arange(0, 6.0, 1e-3)
    onset = (t >= 0.1) & (t < 0.2)
    fitted = [split_blocks(t, salt)[0][onset].mean() for salt in range(8)]
    assert min(fitted) < 0.5 < max(fitted)


def test_every_stretch_of_three_blocks_is_in_both_halves():
    """Blocks are split in pairs, one fitting and one validating, so no run of one half is longer than two
    blocks: a 0.3 s transient of a 6 s recording (0.1 s blocks) is always seen by both. With each block's
    half drawn alone, 9 blocks in a row validated on seed 65's watflex-6b7dd386 (0.5-1.4 s, a whole step
    transient), and the refit, fitted without it, was 1.40 x the noise there on a clean case (0.73 x paired)."""
    t = np.arange(0, 6.0, 1e-3)
    for salt in range(20):
        mask, block = split_blocks(t, salt)
        runs = np.diff(np.flatnonzero(np.diff(np.r_[-1, mask.astype(int), -1])))  # samples in each run of one half
        assert runs.max() <= 2 * block / 1e-3 + 1
        assert 0.45 < mask.mean() < 0.55


def test_noise_is_measured_from_the_data():
    """White noise of rms 0.01 on a slow sine: the second-difference estimate gives 0.01 within 5 %;
    a quantised ramp (step 1e-3) gives at least the uniform quantisation rms 1e-3/sqrt(12)."""
    rng = np.random.default_rng(0)
    t = np.arange(0, 5, 1e-3)
    assert measured_noise(np.sin(2 * np.pi * t) + 0.01 * rng.normal(size=t.size)) == pytest.approx(0.01, rel=0.05)
    assert measured_noise(np.round(0.1 * t / 1e-3) * 1e-3) >= 1e-3 / math.sqrt(12) * 0.999


def _low_passed_noise(n: int, a: float, seed: int) -> np.ndarray:
    """Unit-rms noise through a first-order low-pass: x[k] = a x[k-1] + sqrt(1 - a^2) e[k] (autocorrelation a^lag)."""
    from scipy.signal import lfilter

    e = np.random.default_rng(seed).standard_normal(n)
    return lfilter([math.sqrt(1 - a * a)], [1.0, -a], e)


def test_noise_a_sensors_filter_correlated_is_measured_on_the_residual():
    """noise.coloured_noise: unit-rms noise through a first-order low-pass at 100 Hz sampled at 1 kHz (a = 0.53):
    the lag-1 estimate reads sqrt(1 - 4a/3 + a^2/3) = 0.62 of it (its second differences' variance, within 5 %),
    coloured_noise its rms (within 5 %), also at 2 ms; white noise, a smooth 5 Hz misfit on it and steady lines from
    50 to 300 Hz (the frequencies whose second differences are alike at 4 and 8 ms, 83 and 167 Hz, among them) add
    nothing; nor does a low-pass at 40 Hz (a = 0.78), which has not levelled off by NOISE_LAG_S."""
    from watflex_sim.diagnosis.noise import coloured_noise

    t = np.arange(0.0, 6.0, 1e-3)  # s
    a = math.exp(-2 * math.pi * 100.0 * 1e-3)
    noise = _low_passed_noise(t.size, a, 0)
    assert measured_noise(noise) == pytest.approx(math.sqrt(1 - 4 * a / 3 + a * a / 3), rel=0.05)
    assert coloured_noise(noise, 1e-3) == pytest.approx(1.0, rel=0.05)
    assert coloured_noise(noise[::2], 2e-3) == pytest.approx(1.0, rel=0.05)
    white = np.random.default_rng(1).standard_normal(t.size)
    assert coloured_noise(white, 1e-3) == 0.0
    assert coloured_noise(0.01 * white + 0.1 * np.sin(2 * np.pi * 5.0 * t), 1e-3) == 0.0
    for hz in (50.0, 83.0, 100.0, 125.0, 167.0, 200.0, 300.0):
        assert coloured_noise(0.5 * white + np.sin(2 * np.pi * hz * t), 1e-3) == 0.0, hz
    assert coloured_noise(_low_passed_noise(t.size, math.exp(-2 * math.pi * 40.0 * 1e-3), 2), 1e-3) == 0.0


def test_the_noise_floor_of_a_measured_channel_is_raised_to_its_coloured_noise():
    """floors.add_coloured_noise: a 3 s laser step whose tip sensor and voltage command carry low-pass noise of 0.02 V
    rms (100 Hz, as above) besides the rig's: against the same step without it, the tip sensor's noise and sensor
    noise are raised to that (within 10 %: 3,000 samples' estimate), the command's are left (a command's noise is
    the closed-loop part's, add_closed_loop_noise) and so is the motor current, whose residual is nil."""
    from watflex_sim.diagnosis.floors import add_coloured_noise

    rec = simulate(load_scenario("laser_arm_step", ["duration_s=3", "seed=0"])).recording
    extra = 0.02 * _low_passed_noise(rec.time.size, math.exp(-2 * math.pi * 100.0 * 1e-3), 3)  # V
    noisy = Recording(rec.time, {**rec.channels, "tip_sensor": rec.channels["tip_sensor"] + extra,
                                 "voltage_cmd": rec.channels["voltage_cmd"] + extra}, rec.meta)
    data = prepare([noisy], ["step.csv"])
    before = [dict(n) for n in data.noise]
    raised = add_coloured_noise(data, [rec])
    assert raised and raised[0].startswith("step.csv: tip_sensor x")
    assert data.sensor_noise[0]["tip_sensor"] == pytest.approx(0.02, rel=0.1)
    assert data.sensor_noise[0]["tip_sensor"] > before[0]["tip_sensor"]
    assert data.noise[0]["tip_sensor"] == data.sensor_noise[0]["tip_sensor"]
    assert data.noise[0]["voltage_cmd"] == before[0]["voltage_cmd"]
    assert data.noise[0]["motor_current"] == before[0]["motor_current"]


def test_a_channel_whose_noise_the_data_do_not_resolve_gets_the_no_noise_floor(laser_recordings):
    """A command with no declared noise, holding still 60 % of the time and jittering there at its tenth
    significant digit (what a 2 ms re-sampling of a seed-97 two-joint case left on a torque command: 6e-9 N m,
    3e-10 of its spread): its noise is NO_NOISE_FLOOR x its spread, not its number format's; the same command with
    a white noise of 1e-3 V keeps that noise measured (within 10 %)."""
    rec = laser_recordings[0]
    t = rec.time - rec.time[0]
    held = np.where(t < 0.4 * t[-1], np.sin(20 * t), np.sin(20 * 0.4 * t[-1])) * (1 + 1e-10 * np.cos(7e3 * t))
    noisy = held + 1e-3 * np.random.default_rng(0).normal(size=t.size)
    for command, expected in ((held, NO_NOISE_FLOOR * np.std(held)), (noisy, 1e-3)):
        edited = Recording(rec.time, {**rec.channels, "voltage_cmd": command}, rec.meta)
        data = prepare([edited], ["a.csv"])
        assert data.noise[0]["voltage_cmd"] == pytest.approx(expected, rel=0.1)
    assert measured_noise(held) < 1e-9 * np.std(held)  # what the floor replaces


def test_time_stamps_a_logger_jittered_are_compared_at_the_loops_ticks(laser_recordings, monkeypatch):
    """data.on_ticks in prepare: a laser step logged at 1 ms with every stamp off by up to 0.3 ms (uniform, the values
    those of the ticks: a logger stamping when it writes) is compared at the ticks: its times are whole ms from the
    first (to 1e-9 s), the split's description says the stamps moved, and the nominal model's residual is the one of
    the file as made to 1e-9 of its spread; compared at the stamps, as before, it is off by more than 1 % of the
    spread rms (0.026: the noise leaves 0.030). A log on the ticks, one at 0.7 ms (not the loop's), a clock that
    drifts a period and more against the loop (0.99 ms: two stamps on one tick) and samples stamped exactly at times
    unrelated to the loop (spacings uniform on 2.6-3.4 ms: a variable-step simulator's output) are left as they are."""
    from watflex_sim.diagnosis import data as data_module
    from watflex_sim.resim import resimulate

    rec = laser_recordings[0]
    stamps = 100.0 + rec.time + np.random.default_rng(0).uniform(-3e-4, 3e-4, rec.time.size)
    jittered = Recording(stamps, rec.channels, rec.meta)
    made, moved = prepare([rec], ["a.csv"]), prepare([jittered], ["a.csv"])
    t = moved.recordings[0].time - moved.recordings[0].time[0]
    assert np.abs(t - 1e-3 * np.round(t / 1e-3)).max() < 1e-9 and "clock jitter" in moved.how
    assert "clock jitter" not in made.how and made.recordings[0] is rec
    residual = {}
    for name, data in (("made", made), ("moved", moved)):
        residual[name] = data_module.residual_vector(data, [resimulate(data.recordings[0])], "all", stride=1)
    assert np.abs(residual["moved"] - residual["made"]).max() < 1e-9
    monkeypatch.setattr(data_module, "on_ticks", lambda r, period: (r, 0.0))
    at_stamps = prepare([jittered], ["a.csv"])
    off = data_module.residual_vector(at_stamps, [resimulate(jittered)], "all", stride=1) - residual["made"]
    assert np.sqrt(np.mean(off**2)) > 0.01
    for spacing in (0.7e-3, 0.99e-3):
        other = Recording(np.arange(rec.time.size) * spacing, rec.channels, rec.meta)
        assert data_module.on_ticks(other, 1e-3) == (other, 0.0)
    anywhere = np.cumsum(np.random.default_rng(1).uniform(2.6e-3, 3.4e-3, rec.time.size))  # exact, off any grid
    assert data_module.on_ticks(Recording(anywhere, rec.channels, rec.meta), 1e-3)[1] == 0.0


def test_glitches_are_one_or_two_samples_off_the_line_their_neighbours_lie_on():
    """glitch.glitch_samples: on 200,000 samples of white noise (sd 1) none is a glitch (8 sd of a sample's offset
    from its neighbours' mean: ~1e-15 a sample); 40 single samples moved by 25 sd (2.5 x GLITCH), either way, and
    then 40 pairs of neighbours moved alike by 25 sd are all found and nothing else; what the rig's signals do at
    the loop's rate is none: a step of 100 sd, a corner (a cusp, 100 sd a sample either side), a 480 Hz oscillation
    of 50 sd sampled at 1 kHz (a beam mode near the sampling rate), an encoder's count flickering (noise: its step's
    rms), three samples moved by 100 sd (a pulse the rig's command gave)."""
    from watflex_sim.diagnosis.glitch import GLITCH, glitch_samples

    rng = np.random.default_rng(0)
    noise = rng.normal(size=200_000)
    assert not glitch_samples(noise, 1.0).any()
    where = np.arange(1000, 200_000, 5000)
    moved = noise.copy()
    moved[where] += 25.0 * np.where(np.arange(where.size) % 2, 1.0, -1.0)
    assert 25.0 >= 2.5 * GLITCH and np.array_equal(np.flatnonzero(glitch_samples(moved, 1.0)), where)
    moved = noise.copy()
    moved[where] += 25.0
    moved[where + 1] += 25.0
    assert np.array_equal(np.flatnonzero(glitch_samples(moved, 1.0)), np.sort(np.r_[where, where + 1]))
    k = np.arange(2000.0)
    step = noise[:2000] + 100.0 * (k >= 1000)
    cusp = noise[:2000] + 100.0 * np.abs(k - 1000)
    oscillation = noise[:2000] + 50.0 * np.sin(2 * np.pi * 480.0 * k * 1e-3)
    flicker = np.round(0.3 * np.sin(k / 50.0) + 0.5 * (k % 7 == 0))  # counts: 0, now and then 1
    pulse = noise[:2000] + 100.0 * ((k >= 1000) & (k < 1003))
    for values, sd in ((step, 1.0), (cusp, 1.0), (oscillation, 1.0), (flicker, 1 / math.sqrt(12)), (pulse, 1.0)):
        assert not glitch_samples(values, sd).any()


def test_a_loggers_glitches_are_left_out_and_the_rigs_own_spikes_kept(laser_recordings):
    """data.prepare leaves out a measured channel's glitches (glitch.without_glitches: empty cells, as a logger's
    missing samples) and says so in the split's description: three tip-sensor samples moved by 20 x its declared
    noise are NaN, and a motor-current glitch at the sample of one of them (a row written wrong); nothing else
    changes. A spike the command has at the same sample (a controller's kick) makes the motor current's spike the
    rig's: kept. A recording without one is the same object."""
    rec = laser_recordings[0]
    sd = load_rig("laser_arm").channels["tip_sensor"]["noise"]
    tip, current, command = (rec.channels[c].copy() for c in ("tip_sensor", "motor_current", "voltage_cmd"))
    tip[[150, 220, 330]] += 20.0 * sd
    current[[220, 250]] += 1.0
    command[250] += 5.0
    edited = Recording(rec.time, {**rec.channels, "tip_sensor": tip, "motor_current": current, "voltage_cmd": command},
                       rec.meta)
    data = prepare([edited], ["a.csv"])
    cleaned = data.recordings[0].channels
    assert np.array_equal(np.flatnonzero(np.isnan(cleaned["tip_sensor"])), [150, 220, 330])
    assert np.array_equal(np.flatnonzero(np.isnan(cleaned["motor_current"])), [220])
    assert cleaned["motor_current"][250] == current[250] and np.array_equal(cleaned["voltage_cmd"], command)
    assert "(a logger's glitches): a.csv (tip_sensor 3, motor_current 1)" in data.how
    assert data.glitches == ["a.csv (tip_sensor 3, motor_current 1)"]
    made = prepare([rec], ["a.csv"])
    assert made.recordings[0] is rec and "glitches" not in made.how


def test_a_slower_sensors_values_a_logger_held_are_compared_once():
    """data.prepare (glitch.without_held): a 1.5 s Watflex elbow step's 25 Hz camera written in every 1 ms row as its
    last frame (a logger holding it) is compared at its frames only: tip_x and tip_y finite exactly where the files as
    made have them (38 frames), the repeats counted in the split's description. An elbow encoder at a steady speed,
    one count every 7 ms (runs as even as a held sensor's, but on a grid as coarse as its noise), and the files as
    made are left as they are."""
    rec = simulate(load_scenario("watflex_elbow_step", ["duration_s=1.5"])).recording
    frames = np.isfinite(rec.channels["tip_x"])
    held = {c: rec.channels[c][np.maximum.accumulate(np.where(frames, np.arange(frames.size), 0))]
            for c in ("tip_x", "tip_y")}
    count = 2 * math.pi / (4 * 1024 * 80)  # rad: an encoder's count (rigs.md)
    steady = count * np.floor(np.arange(frames.size) / 7.0)
    edited = Recording(rec.time, {**rec.channels, **held, "elbow_angle": steady}, rec.meta)
    data = prepare([edited], ["a.csv"])
    cleaned = data.recordings[0].channels
    for c in ("tip_x", "tip_y"):
        assert np.array_equal(np.isfinite(cleaned[c]), frames) and np.array_equal(cleaned[c][frames], held[c][frames])
    assert frames.sum() == 38 and np.array_equal(cleaned["elbow_angle"], steady)
    repeats = frames.size - 38
    assert data.held == [f"a.csv (tip_x {repeats}, tip_y {repeats})"] and "a logger held" in data.how
    made = prepare([rec], ["a.csv"])
    assert made.held == [] and made.recordings[0] is rec


def test_a_camera_is_compared_at_every_frame_whatever_the_clock_reads(tmp_path):
    """resim._sampled: a 6 s Watflex elbow step (its camera at 25 Hz: 150 frames, NaN between) written to CSV and read
    back, and the same with its clock started at 100 s (a logger's clock), re-simulated with the noise off: the
    simulated camera has a value at each of the 150 frames, the same values either way. Interpolated at the recording's
    times, which are ~1e-14 s off the simulation's ticks, beside an empty tick, it had 134 as made and 6 from 100 s."""
    from watflex_sim import write_recording
    from watflex_sim.recording import read_recording
    from watflex_sim.resim import resimulate

    made = read_recording(write_recording(simulate(load_scenario("watflex_elbow_step")).recording, tmp_path, "a"))
    later = read_recording(write_recording(Recording(made.time + 100.0, made.channels, made.meta), tmp_path, "b"))
    sims = [resimulate(r) for r in (made, later)]
    frames = np.isfinite(made.channels["tip_x"])
    assert frames.sum() == 150 and np.array_equal(np.isfinite(later.channels["tip_x"]), frames)
    for sim in sims:
        assert np.array_equal(np.isfinite(sim.channels["tip_x"]), frames)
    assert np.array_equal(sims[0].channels["tip_x"][frames], sims[1].channels["tip_x"][frames])


def test_intervals_cover_a_linear_fit_as_often_as_they_say():
    """y = a t + white noise, fitted by least squares: the 95 % interval from the Jacobian covers
    the true a in 95 % +- 4 % of 400 seeds (binomial: 2 sd = 2.2 %)."""
    t = np.linspace(0, 1, 200)
    J = t[:, None]
    covered = 0
    for seed in range(400):
        y = 2.0 * t + 0.1 * np.random.default_rng(seed).normal(size=t.size)
        a = float(J[:, 0] @ y / (J[:, 0] @ J[:, 0]))
        r = a * t - y
        lo, hi = intervals([Slot(("param", "a"), -10, 10)], Model(parameters={"a": a}), J, r)[0]
        covered += lo <= 2.0 <= hi
    assert covered / 400 == pytest.approx(0.95, abs=0.04)


def test_noise_replicates_cover_what_white_noise_intervals_miss():
    """y = a t + e, with e what noise does in a closed loop: a drift it causes (a bias of the estimate)
    plus a random walk (serially correlated). The Jacobian's interval, built for white noise, covers the
    true a in under 20 % of 200 seeds; with 8 replicates of e (other seeds, as final_intervals simulates
    them) it covers in 90-99 % (95 % nominal; binomial 2 sd = 3 %, and 8 replicates estimate the scatter
    to ~25 %)."""
    t = np.linspace(0, 1, 200)
    J = t[:, None]

    def noise(rng):
        return 0.05 * np.sqrt(t) + 0.02 * np.cumsum(rng.normal(size=t.size)) / np.sqrt(t.size)

    white = replicated = 0
    for seed in range(200):
        y = 2.0 * t + noise(np.random.default_rng(seed))
        a = float(t @ y / (t @ t))
        slots, model, r = [Slot(("param", "a"), -10, 10)], Model(parameters={"a": a}), a * t - y
        lo, hi = intervals(slots, model, J, r)[0]
        white += lo <= 2.0 <= hi
        replicates = [noise(np.random.default_rng(10_000 + 8 * seed + k)) for k in range(8)]
        lo, hi = intervals(slots, model, J, r, replicates=replicates)[0]
        replicated += lo <= 2.0 <= hi
    assert white / 200 < 0.2
    assert 0.90 <= replicated / 200 <= 0.99


def test_an_interval_reaches_past_a_fit_that_stopped_short():
    """y = a t + white noise, the fit stopped 5 sd short of the least-squares estimate (a valley of a
    stick-slip cost): the interval reaches the Gauss-Newton step from there, so it still covers the
    true a in 95 % +- 4 % of 400 seeds (binomial 2 sd = 2.2 %); centred on the stalled value alone
    it would cover in under 1 % (5 sd off, 1.96 sd wide)."""
    t = np.linspace(0, 1, 200)
    J = t[:, None]
    sd = 0.1 / math.sqrt(t @ t)
    covered = 0
    for seed in range(400):
        y = 2.0 * t + 0.1 * np.random.default_rng(seed).normal(size=t.size)
        a = float(t @ y / (t @ t)) + 5 * sd
        lo, hi = intervals([Slot(("param", "a"), -10, 10)], Model(parameters={"a": a}), J, a * t - y)[0]
        covered += lo <= 2.0 <= hi
    assert covered / 400 == pytest.approx(0.95, abs=0.04)


def test_huber_threshold_ignores_exact_zeros():
    """A residual that is 0 on 60 % of its elements (missing camera samples, a quantised channel that
    re-simulates to the same count) and unit normal elsewhere: Huber's threshold is HUBER x the
    normal's sd (1.345, +-10 % for 4,000 draws' MAD), not the ~0 that the zeros' median gave, which
    stalled Levenberg-Marquardt on Watflex's quantised encoders and strain converters."""
    r = np.concatenate([np.zeros(6000), np.random.default_rng(0).normal(size=4000)])
    assert huber_threshold(r) == pytest.approx(1.345, rel=0.1)
    assert huber_threshold(np.zeros(10)) == math.inf


def test_a_nuisance_traded_off_widens_an_interval_by_its_prior():
    """y = (a + b) t + noise, a an effect's parameter (no prior), b a rig parameter with a tolerance
    prior of sd 0.05: the data fix only a + b, so a's 95 % half-width is 1.96 x sqrt(0.05^2 + the
    noise's share) - linear-Gaussian algebra - and not the noise-only width it has with b left out
    (issue 14: a friction side near 0 or a rig parameter at its bound, dropped, made intervals too narrow)."""
    t = np.linspace(0, 1, 200)
    y = 2.0 * t + 0.1 * np.random.default_rng(0).normal(size=t.size)
    a = float(t @ y / (t @ t))
    r = a * t - y
    slots = [Slot(("effect", 0, "a"), -10, 10), Slot(("param", "b"), 0.5, 1.5)]
    model = Model([{"effect": "x", "a": a}], {"b": 1.0})
    J = np.column_stack([t, t])
    alone = intervals(slots[:1], model, J[:, :1], r)[0]
    joint = intervals(slots, model, J, r, [math.inf, 0.05])[0]
    noise_sd = (alone[1] - alone[0]) / 2 / 1.96
    assert (joint[1] - joint[0]) / 2 == pytest.approx(1.96 * math.hypot(0.05, noise_sd), rel=0.02)
    assert (joint[1] - joint[0]) > 3 * (alone[1] - alone[0])


def test_an_interval_reaches_along_a_valley_to_the_datasheets_value():
    """y = (a + b) t + noise, the fit left the rig parameter b at its tolerance bound 1.05 (datasheet 1.0, prior
    sd 0.05 / sqrt 3) and a at 1.95, the truth a = 2.05 at b's other bound 0.95: the data fix only a + b, so the
    step to the posterior's mode moves b back to 1.0 and a up by 0.05, and the prior's 95 % half-width (1.96 x
    0.029) reaches 2.057 - past the truth with the prior's mean given, not without it (2.007; seed 48's payload
    1.6 % short with the hub's inertia at +3 %)."""
    from watflex_sim.diagnosis.uncertainty import tolerance_centre, tolerance_sd

    t = np.linspace(0, 1, 200)
    y = 3.0 * t + 0.01 * np.random.default_rng(0).normal(size=t.size)
    a = float(t @ y / (t @ t)) - 1.05
    slots = [Slot(("effect", 0, "a"), -10, 10), Slot(("param", "b"), 0.95, 1.05)]
    model = Model([{"effect": "x", "a": a}], {"b": 1.05})
    J, r = np.column_stack([t, t]), (a + 1.05) * t - y
    prior = [tolerance_sd(s) for s in slots]
    assert [tolerance_centre(s) for s in slots][1] == pytest.approx(1.0)
    without = intervals(slots, model, J, r, prior)[0]
    with_mean = intervals(slots, model, J, r, prior, prior_mean=[tolerance_centre(s) for s in slots])[0]
    assert without[1] < 2.05 < with_mean[1]
    assert with_mean[0] == pytest.approx(without[0], abs=1e-12)


def test_a_model_errors_reach_is_what_it_can_move_the_estimate_not_what_the_prior_leaves_loose():
    """y = (a + b) t + noise (sd 0.01), a an effect's parameter, b a rig parameter with a tolerance prior (sd 0.05);
    a model error e = 0.02 t, which the columns absorb whole: least squares with the prior moves a by exactly
    0.02 and b by nothing (the prior holds b; linear algebra), so the interval reaches 0.02 further, the bound
    |g_a| |P e| met with equality. The bound sd_a |P e| / s, in which a's sd is the prior's 0.05 the data cannot
    narrow, reached 40 x that (seed 56: a link stiffness x1.26, tied to link 2's EI, got its whole bounds
    [0.02, 153]). Without the prior both bounds are the same: sd_a |P e| / s."""
    t = np.linspace(0, 1, 200)
    y = 2.0 * t + 0.01 * np.random.default_rng(0).normal(size=t.size)
    a = float(t @ y / (t @ t)) - 1.0
    slots = [Slot(("effect", 0, "a"), -10, 10), Slot(("param", "b"), 0.5, 1.5)]
    model = Model([{"effect": "x", "a": a}], {"b": 1.0})
    J, r, error = np.column_stack([t, t]), (a + 1.0) * t - y, 0.02 * t
    prior = [math.inf, 0.05]
    half = lambda lo_hi: (lo_hi[1] - lo_hi[0]) / 2  # noqa: E731
    reach = half(intervals(slots, model, J, r, prior, model_error=error)[0]) - half(intervals(slots, model, J, r, prior)[0])
    assert reach == pytest.approx(0.02, rel=1e-6)
    s2 = residual_variance(r, 2)
    sd = math.sqrt(np.linalg.inv(J.T @ J / s2 + np.diag([0.0, 0.05**-2]))[0, 0])  # ~0.05: the prior's
    assert sd * np.linalg.norm(error) / math.sqrt(s2) > 30 * reach  # the former bound
    alone = [intervals(slots[:1], model, J[:, :1], r, model_error=e)[0] for e in (error, None)]
    sd_alone = math.sqrt(residual_variance(r, 1) / float(t @ t))
    assert half(alone[0]) - half(alone[1]) == pytest.approx(sd_alone * np.linalg.norm(error) / math.sqrt(residual_variance(r, 1)), rel=1e-6)


def test_direction_follows_the_final_parameters():
    """A level per direction that is ~0 one way is one-sided; equal levels are 'both' (issue 14's
    stale label: 'both' with torque_positive 1e-28)."""
    assert direction("coulomb_friction", {"torque_positive": 1e-28, "torque_negative": 0.3}) == "negative"
    assert direction("coulomb_friction", {"torque_positive": 0.5, "torque_negative": 0.48}) == "both"
    assert direction("backlash", {"width": 1e-3, "position": 0.9}) == "positive"


def test_places_and_units_are_the_rigs_own(laser_recordings):
    """A delay on 'command' acts on the command channel the recordings carry; a command limit is in
    the channel's unit (V); friction on a slide is in N (EMPS), on a hinge in N m."""
    data = prepare(laser_recordings, ["a", "b"])
    assert physical_place(data, "delay", "command") == "voltage_cmd"
    assert units_at(data, "current_saturation", "voltage_cmd") == {"limit": "V"}
    assert units_at(data, "coulomb_friction", "hub")["torque_positive"] == "N m"


def test_a_gain_within_tolerance_is_parameter_error_not_physics(laser_recordings):
    """sensor_gain 1.015 on the tip sensor (tolerance 2 %, rigs.md §4) goes into the refit parameters;
    0.5 (a halved gain) stays a finding; a negative ratio (a sign error) too."""
    data = prepare(laser_recordings, ["a", "b"])
    folded = fold_within_tolerance(data, Model([dict(effect="sensor_gain", where="tip_sensor", ratio=1.015)], {}))
    assert folded.effects == [] and folded.parameters["tip_sensor_gain"] == pytest.approx(1.015)
    for ratio in (0.5, -1.0):
        kept = fold_within_tolerance(data, Model([dict(effect="sensor_gain", where="tip_sensor", ratio=ratio)], {}))
        assert len(kept.effects) == 1


def test_explained_share():
    """Share of the residual above the noise removed: 25 x -> 2 x the noise removes 24/25 = 96 %... of 24."""
    assert explained_share(25.0, 2.0) == pytest.approx(23 / 24)
    assert explained_share(0.9, 0.9) == 1.0


def test_proposed_experiment_separates_two_explanations_and_runs(laser_recordings, tmp_path):
    """Two explanations that differ (0.3 N m Coulomb vs 0.3 N m Stribeck excess decaying at 0.01
    rad/s): the proposal is a menu experiment of these recordings whose predictions differ by more
    than the noise, written as a scenario file that `watflex-sim run` accepts."""
    from watflex_sim.cli import main
    from watflex_sim.diagnosis.experiment import propose_experiment, to_toml
    from watflex_sim.diagnosis.runner import hold

    data = prepare(laser_recordings, ["a", "b"])
    hold(data)
    chosen = Model([dict(effect="coulomb_friction", where="hub", torque_positive=0.3, torque_negative=0.3)])
    other = dict(effect="stribeck_friction", where="hub", instead_of="coulomb_friction",
                 model={"effects": [dict(effect="stribeck_friction", where="hub", breakaway_positive=0.3,
                                         breakaway_negative=0.3, v_s=0.01)], "parameters": {}})
    proposal = propose_experiment(data, chosen, [other])
    assert proposal["scenario_dict"] is not None and proposal["experiment"].split()[0] in ("a", "b")
    assert float(proposal["expected_difference"].split(": ")[1].split(" x")[0]) > 1.0
    assert proposal["drive"].startswith("voltage_cmd peaks at ") and "of its 24 V limit" in proposal["drive"]
    path = tmp_path / "discriminate.toml"
    path.write_text(to_toml(proposal["scenario_dict"], "proposed"))
    assert main(["run", str(path), "--out", str(tmp_path / "run"), "--no-plot", "--no-rrd"]) == 0


def test_a_proposal_says_how_hard_it_drives_the_rig():
    """drive_demand(): a command's peak against its limit and the share of samples at it (|v| >= 0.999 x the limit:
    2 of 5 here, 40 %), from the rig's channel table (the laser arm's voltage_cmd: 24 V, rigs.md); channels
    without a limit, and a command that never moves (a locked joint's), say nothing."""
    from watflex_sim.diagnosis.experiment import drive_demand
    from watflex_sim.rigdesc import load_rig

    channels = load_rig("laser_arm").channels
    text = drive_demand({"voltage_cmd": [0.0, 12.0, 24.0, -24.0, 6.0], "tip_sensor": [1.0] * 5}, channels)
    assert text == "voltage_cmd peaks at 24 V of its 24 V limit, at the limit 40 % of the run"
    assert drive_demand({"tip_sensor": [1.0] * 5}, channels) == drive_demand({"voltage_cmd": [0.0] * 5}, channels) == ""


def test_the_sweep_on_the_menu_spans_the_recorded_excursion_and_band(laser_recordings):
    """The menu's sweep of a 0.4 s step recording at 1 ms control: a sine chirp from the step's start, as far from
    it as the step went, logarithmic from 2 cycles over the recording (5.01 Hz) to 5 % of the control rate
    (50 Hz). Its cycles in closed form: f0 T (k - 1) / ln k with k = f1 / f0 (scipy.signal.chirp), 7.8 here."""
    from watflex_sim.diagnosis.experiment import VARIANTS, _variant
    from watflex_sim.diagnosis.runner import hold

    data = prepare(laser_recordings, ["a", "b"])
    hold(data)
    ref = data.recordings[0].channels["reference"]
    step = float(np.nanmax(np.abs(ref - ref[0])))
    signal, = _variant(data, 0, *VARIANTS["as a sweep"])["reference"]
    v, t = np.asarray(signal["values"]) - ref[0], np.asarray(signal["time_s"])
    assert v[0] == pytest.approx(0.0, abs=1e-12) and np.max(np.abs(v)) == pytest.approx(step, rel=0.01)
    f0, f1, span = 2.0 / t[-1], 50.0, t[-1]
    cycles = f0 * span * (f1 / f0 - 1) / math.log(f1 / f0)
    assert cycles == pytest.approx(7.8, abs=0.1)
    assert np.count_nonzero(np.diff(np.sign(v[1:])) != 0) == pytest.approx(2 * cycles, abs=1.0)


def test_one_channel_above_its_noise_is_not_within_noise(laser_recordings):
    """Issue 14's false all-clear: a motor-current error of 1.5 x its noise on one of four channels
    leaves the mean noise ratio near 1.1 (< 1.3) but must not pass as 'within noise'."""
    from watflex_sim.diagnosis.scores import fit_scores
    from watflex_sim.diagnosis.validate import within_noise

    data = prepare(laser_recordings, ["a", "b"])
    rng = np.random.default_rng(3)
    sims = []
    for rec, noise in zip(data.recordings, data.noise):
        channels = {c: v + noise[c] * rng.normal(size=v.size) if c in noise else v for c, v in rec.channels.items()}
        channels["motor_current"] = channels["motor_current"] + 1.1 * noise["motor_current"]
        sims.append(type(rec)(rec.time, channels, rec.meta))
    train, held = fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")
    assert train["worst_channel"] == "motor_current" and train["worst_ratio"] == pytest.approx(1.5, abs=0.1)
    assert train["noise_ratio"] < 1.3 and not within_noise(train, held)
    sims[0].channels["motor_current"] = data.recordings[0].channels["motor_current"] + 3.0 * data.noise[0]["motor_current"]
    sims[1].channels["motor_current"] = data.recordings[1].channels["motor_current"]
    # the median over recordings: of two, their mean (3 x and 0 x the noise -> 1.5 x)
    assert fit_scores(data, sims, "train")["worst_ratio"] == pytest.approx((3.0 + 0.0) / 2, abs=0.1)


def test_a_channel_whose_floor_is_our_discretisation_is_judged_by_its_upper_estimate(laser_recordings):
    """A channel judged on its own counts the discretisation part of its floor DISCRETISATION_COUNT = 2 times (as a
    window's local null does): with 0.8 of a noise n our discretisation, the floor alone is n sqrt(1 + 3 x 0.64) =
    1.709 n (closed form), so a motor-current misfit of 1.5 n sits at 0.88 x (within), one of 3 n at 1.76 x (not);
    the mean over channels still divides by n. A channel without a discretisation part is judged as before."""
    from watflex_sim.diagnosis.scores import fit_scores
    from watflex_sim.diagnosis.validate import within_noise

    data = prepare(laser_recordings, ["a", "b"])
    data.discretisation = [{"motor_current": 0.8 * noise["motor_current"]} for noise in data.noise]

    def scores(current_off: float, tip_off: float = 0.0):
        sims = []
        for rec, noise in zip(data.recordings, data.noise):
            channels = dict(rec.channels)
            channels["motor_current"] = rec.channels["motor_current"] + current_off * noise["motor_current"]
            channels["tip_sensor"] = rec.channels["tip_sensor"] + tip_off * noise["tip_sensor"]
            sims.append(type(rec)(rec.time, channels, rec.meta))
        return fit_scores(data, sims, "train"), fit_scores(data, sims, "held_out")

    upper = math.sqrt(1 + 3 * 0.8**2)
    train, held = scores(1.5)
    assert train["channel_ratios"]["motor_current"] == pytest.approx(1.5 / upper, rel=1e-6)
    assert train["noise_ratio"] == pytest.approx(1.5 / len(data.channels[0]), rel=1e-6)  # mean: 1.5 n on one channel
    assert within_noise(train, held)
    train, held = scores(3.0)
    assert train["worst_ratio"] == pytest.approx(3.0 / upper, rel=1e-6) and not within_noise(train, held)
    train, held = scores(0.0, tip_off=1.5)
    assert train["worst_channel"] == "tip_sensor" and train["worst_ratio"] == pytest.approx(1.5, rel=1e-6)
    assert not within_noise(train, held)


def test_a_residual_that_is_a_curve_of_its_channel_is_not_explained():
    """curved_channels (seed 58, laser_arm-51359564: a motor current reading +50 % at its peak, y = x (1 + 0.5
    (x / peak)^2), 'explained' by a gain x1.141 at 1.14 x the noise): in miniature, a current of steps and a sine, the
    cubic reading against the best gain leaves 1.17 x the noise (0.6 of it structured: 0.36 noise variances), and the
    curve must take over 90 % of the excess (to within 2 % of the noise itself) and call the verdict `unexplained`. A
    plain gain error (x1.14) leaves more (1.35 x the noise) but is a line, not a curve; a frequency 2 % off (a dynamic misfit,
    its residual 90 degrees from the value, 1.89 x the noise) is not a curve either: neither is flagged."""
    from watflex_sim.diagnosis.data import Data
    from watflex_sim.diagnosis.characteristic import CURVE_SHARE, CURVE_SIGNIFICANCE, CURVE_VARIANCE, curved_channels
    from watflex_sim.diagnosis.verdict import verdict_of
    from watflex_sim.recording import Recording

    t = np.arange(0.0, 6.0, 1e-3)  # s
    x = np.where(t < 3.0, np.sign(np.sin(2 * np.pi * t / 1.5)), np.sin(2 * np.pi * 0.7 * t)) * 2.0  # A
    curved = x * (1 + 0.5 * (x / 2.0) ** 2)
    gain = float(curved @ x / (x @ x))  # the gain a fit finds
    noise = float(np.sqrt(np.mean((curved - gain * x) ** 2))) / 0.6  # structured residual 0.6 of the noise: 1.17 x
    rng = np.random.default_rng(5)

    def check(measured: np.ndarray, simulated: np.ndarray) -> list[dict]:
        data = Data([Recording(t, {"motor_current": measured + noise * rng.normal(size=t.size)}, {})], ["a"], None,
                    [["motor_current"]], [{"motor_current": float(np.std(measured))}], [{"motor_current": noise}],
                    [split_blocks(t)[0]])
        return curved_channels(data, [Recording(t, {"motor_current": simulated}, {})])

    found = check(curved, gain * x)
    assert len(found) == 1 and found[0]["noise_ratio"] == pytest.approx(np.sqrt(1 + 0.6**2), abs=0.03)
    assert found[0]["share"] > 0.9 > CURVE_SHARE and found[0]["with_curve"] == pytest.approx(1.0, abs=0.02)
    assert found[0]["noise_ratio"] ** 2 - found[0]["with_curve"] ** 2 > CURVE_VARIANCE
    assert verdict_of(Model([{"effect": "sensor_gain", "where": "motor_current", "ratio": gain}]),
                      {"noise_ratio": 1.0, "worst_ratio": 1.2}, {"noise_ratio": 1.0, "worst_ratio": 1.2}, 1.0, found) == "unexplained"
    assert check(1.14 * x, x) == []
    wave = 2.0 * np.sin(2 * np.pi * 0.7 * t)
    assert check(2.0 * np.sin(2 * np.pi * 0.714 * t), wave) == []
    # a current of brief peaks (4 ms wide, one every 1.5 s, as a motor's at each step) read +30 % at the peak: 0.10 noise
    # variances, under CURVE_VARIANCE, but on white noise chance takes 2 / 6,000 of a variance: F = 0.10 x 6,000 / 2 ~
    # 300 (seed 59's laser current: 0.094-0.122, 290-390), bending 6 noise sd from the line at the peaks: flagged
    pulses = 2.0 * np.exp(-0.5 * (((t % 1.5) - 0.3) / 0.004) ** 2) * np.where((t // 1.5) % 2, -1, 1) + 0.2 * np.sin(0.6 * np.pi * t)
    bent = pulses * (1 + 0.3 * (pulses / 2.0) ** 2)
    noise = 0.08  # A
    found = check(bent, float(bent @ pulses / (pulses @ pulses)) * pulses)
    assert len(found) == 1 and found[0]["noise_ratio"] ** 2 - found[0]["with_curve"] ** 2 == pytest.approx(0.10, abs=0.02)
    assert found[0]["significance"] == pytest.approx(310, rel=0.2) and found[0]["bend"] == pytest.approx(6.0, abs=0.5)
    # +10 % at the peak: 1 % of the noise's variance, 32 x chance on 6,000 white samples and 61 % of the excess, but
    # bending 1.9 noise sd: not flagged, nor would it be at 20 x chance (seed 59's laser pair, a Stribeck friction
    # fitted as Coulomb's: its motor current 0.010 noise variances, 28.5 x chance, 67 %, bending 1.3-2.2 noise sd)
    slight = pulses * (1 + 0.1 * (pulses / 2.0) ** 2)
    data = Data([Recording(t, {"c": slight + noise * np.random.default_rng(6).normal(size=t.size)}, {})], ["a"], None,
                [["c"]], [{"c": 1.0}], [{"c": noise}], [split_blocks(t)[0]])
    sims = [Recording(t, {"c": float(slight @ pulses / (pulses @ pulses)) * pulses}, {})]
    assert curved_channels(data, sims) == []
    with patch("watflex_sim.diagnosis.characteristic.CURVE_SIGNIFICANCE", 20.0):
        assert curved_channels(data, sims) == []
        with patch("watflex_sim.diagnosis.characteristic.CURVE_BEND", 0.0):
            alone = curved_channels(data, sims)
    assert len(alone) == 1 and alone[0]["significance"] == pytest.approx(32, rel=0.25) and alone[0]["bend"] == pytest.approx(1.9, abs=0.2)
    # no curve, the model exact, white noise: the significance is chance's, ~ Exp(1) (mean 1); never near 20
    chance = []
    for seed in range(40):
        measured = wave + noise * np.random.default_rng(seed).normal(size=t.size)
        data = Data([Recording(t, {"c": measured}, {})], ["a"], None, [["c"]], [{"c": 1.0}], [{"c": noise}],
                    [split_blocks(t)[0]])
        with patch.multiple("watflex_sim.diagnosis.characteristic", CURVE_SHARE=-1.0, CURVE_VARIANCE=-1.0,
                            CURVE_SIGNIFICANCE=-1.0):
            chance.append(curved_channels(data, [Recording(t, {"c": wave}, {})])[0]["significance"])
    assert np.mean(chance) == pytest.approx(1.0, abs=0.35) and max(chance) < CURVE_SIGNIFICANCE / 2


def test_a_loop_that_sticks_elsewhere_at_each_hold_is_not_a_curve():
    """curved_channels asks a large curve to be significant too. An encoder in a staircase whose six holds
    each stick a little elsewhere (offsets -0.8 ... +2.0 x the noise, as seed 83's two-joint watflex-490a4521, the
    truth's delay found and the model within the noise, its shoulder encoder 0.81 noise variances, 51 % of the excess
    taken by a cubic, 3.7 x chance): the cubic of the six levels takes 0.77 noise variances, 51 % of the excess, but
    what it leaves is as smooth as what it took, ~4.5 x chance (a sensor's characteristic: 313 x and more)."""
    from scipy.signal import lfilter

    from watflex_sim.diagnosis.data import Data
    from watflex_sim.diagnosis.characteristic import CURVE_SHARE, CURVE_SIGNIFICANCE, CURVE_VARIANCE, curved_channels
    from watflex_sim.recording import Recording

    t = np.arange(0.0, 6.0, 1e-3)  # s
    noise = 1e-4  # rad
    hold = np.minimum((t // 1.0).astype(int), 5)
    settle = lambda v: lfilter([1 - np.exp(-1e-3 / 0.05)], [1, -np.exp(-1e-3 / 0.05)], v)  # noqa: E731 - 50 ms
    x = settle(np.linspace(0.0, 0.5, 6)[hold])  # rad: the staircase
    stuck = settle(np.array([-0.8, -0.2, 2.0, 0.8, -2.0, 0.0])[hold] * noise)
    measured = x + stuck + noise * np.random.default_rng(1).normal(size=t.size)
    data = Data([Recording(t, {"c": measured}, {})], ["a"], None, [["c"]], [{"c": 0.5}], [{"c": noise}], [split_blocks(t)[0]])
    assert curved_channels(data, [Recording(t, {"c": x}, {})]) == []
    with patch("watflex_sim.diagnosis.characteristic.CURVE_SIGNIFICANCE", -1.0):
        (found,) = curved_channels(data, [Recording(t, {"c": x}, {})])
    taken = found["noise_ratio"] ** 2 - found["with_curve"] ** 2
    assert taken == pytest.approx(0.77, abs=0.05) and taken > CURVE_VARIANCE and found["share"] > CURVE_SHARE
    assert found["significance"] == pytest.approx(4.5, abs=1.0) and found["significance"] < CURVE_SIGNIFICANCE


def test_a_curve_within_what_our_discretisation_leaves_is_not_a_characteristic():
    """curved_channels judges a channel as the verdict does (data.noise_alone: our discretisation error counted
    DISCRETISATION_COUNT times). Seed 125's two-joint watflex-e75c32f4 (clean, recorded by a finer simulator, the model
    at 0.81 x the noise): its elbow encoder's residual, 0.95 x the noise with the discretisation counted twice, was a
    curve of the angle (a step's misfit along the way, 205 x chance) by the floor counting it once and the case was
    called `unexplained`. In miniature: a critically damped 0.8 rad step, the measurement off along the way by
    1.6e-3 (u^3 - u) rad (u: the angle over its target; 0.23 mrad RMS), 0.05 mrad white noise, a floor of 0.187 mrad
    of which 0.18 is our discretisation: a curve at 1.06 x the floor when the floor's make-up is unknown, flagged;
    0.54 x the floor with the discretisation counted twice (0.363 mrad), not."""
    from watflex_sim.diagnosis.characteristic import curved_channels
    from watflex_sim.diagnosis.data import Data
    from watflex_sim.recording import Recording

    t = np.arange(0.0, 6.0, 1e-3)  # s
    x = 0.8 * np.where(t < 0.5, 0.0, 1 - np.exp(-(t - 0.5) / 0.4) * (1 + (t - 0.5) / 0.4))  # rad
    measured = x + 1.6e-3 * ((x / 0.8) ** 3 - x / 0.8) + 0.5e-4 * np.random.default_rng(2).normal(size=t.size)
    step = 1.8e-4  # rad: what a finer discretisation changes (floors.add_discretisation_error)
    floor = float(np.hypot(0.5e-4, step))

    def curved(discretisation: list[dict]) -> list[dict]:
        data = Data([Recording(t, {"c": measured}, {})], ["a"], None, [["c"]], [{"c": 0.5}], [{"c": floor}],
                    [split_blocks(t)[0]], discretisation=discretisation)
        return curved_channels(data, [Recording(t, {"c": x}, {})])

    (found,) = curved([])
    assert found["noise_ratio"] == pytest.approx(1.06, abs=0.03) and found["with_curve"] == pytest.approx(0.27, abs=0.02)
    assert curved([{"c": step}]) == []


def test_a_steady_line_the_simulation_lacks_is_not_explained():
    """disturbance.steady_lines: a strain bridge over three 6 s recordings of a staircase (0.05 V levels every 1.5 s,
    a 2.5 Hz ring after each step) that the model rings at 2.6 Hz (a misfit of ~2 noise sd, 2 mV noise): mains hum of
    one noise sd at 50 Hz, in another phase in each recording, is found under the larger misfit (the periodogram's
    peaks are asked highest over what the simulation has there), at 50.00 Hz, 2 mV within 10 %, in 3 of 3 recordings,
    and makes the verdict `unexplained` whatever the findings. Not flagged: the misfit alone (the simulation carries
    its own ring: 2.7 x the line), a ring at 8.3 Hz the model lacks (it decays within each hold: its weakest window
    0.35 of its strongest), a loop's limit cycle at 3.0 Hz that the model has at 3.1 Hz, a hum of 0.3 noise sd
    (its windows' amplitudes too noisy to call it steady: not claimed) and a hum in one recording of three. Where the
    search stopped at --max-effects, the reason says that too."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis.data import Data
    from watflex_sim.diagnosis.disturbance import steady_lines
    from watflex_sim.diagnosis.verdict import verdict_of, verdict_reason
    from watflex_sim.recording import Recording

    t = np.arange(0.0, 6.0, 1e-3)  # s
    noise = 2e-3  # V
    since = t % 1.5  # s since the last step
    level = np.array([0.0, 1.0, -1.0, 0.5])[(t // 1.5).astype(int)] * 0.05  # V
    ring = lambda f, zeta=0.05: 0.02 * np.exp(-2 * np.pi * f * zeta * since) * np.sin(2 * np.pi * f * since)  # noqa: E731
    model = level + ring(2.6)

    def lines(extra, simulated=model) -> list[dict]:
        recordings = [Recording(t, {"strain_2B": level + ring(2.5) + extra(k) + noise * np.random.default_rng(k).normal(size=t.size)}, {})
                      for k in range(3)]
        data = Data(recordings, ["a", "b", "c"], SimpleNamespace(units=lambda: {"strain_2B": "V"}), [["strain_2B"]] * 3,
                    [{"strain_2B": 0.05}] * 3, [{"strain_2B": noise}] * 3, [split_blocks(t)[0]] * 3)
        return steady_lines(data, [Recording(t, {"strain_2B": simulated}, {})] * 3)

    (hum,) = lines(lambda k: noise * np.sin(2 * np.pi * 50.0 * t + k))
    assert hum["frequency_hz"] == pytest.approx(50.0, abs=0.01) and hum["amplitude"] == pytest.approx(noise, rel=0.1)
    assert hum["recordings"] == "3 of 3" and hum["unit"] == "V"
    within = {"noise_ratio": 1.0, "worst_ratio": 1.1, "worst_channel": "strain_2B"}
    assert verdict_of(Model(), within, within, 0.0, [], [], [hum]) == "unexplained"
    assert verdict_of(Model(), within, within, 0.0, [], [], []) == "nothing_missing"
    assert "steady line at 50.00 Hz" in verdict_reason("unexplained", within, within, within, within, 0.0, [], disturbed=[hum])
    assert lines(lambda k: 0.0 * t) == []
    assert lines(lambda k: 0.01 * np.exp(-2 * np.pi * 8.3 * 0.02 * since) * np.sin(2 * np.pi * 8.3 * since)) == []
    assert lines(lambda k: 3 * noise * np.sin(2 * np.pi * 3.0 * t), model + 3 * noise * np.sin(2 * np.pi * 3.1 * t)) == []
    assert lines(lambda k: 0.3 * noise * np.sin(2 * np.pi * 50.0 * t + k)) == []
    # in one recording of three only (a resonance that one periodic experiment excites: EMPS' pulses run): not flagged
    assert lines(lambda k: noise * np.sin(2 * np.pi * 50.0 * t) * (k == 0)) == []
    stopped = verdict_reason("unexplained", within, within, within, within, 0.0, [], limit=1, disturbed=[hum])
    assert "steady line at 50.00 Hz" in stopped and "limit of 1 finding (--max-effects)" in stopped


def test_a_sensor_that_drifts_is_not_explained():
    """disturbance.steady_drifts, on the staircase of test_a_steady_line_the_simulation_lacks_is_not_explained (the
    model ringing at 2.6 Hz for 2.5): a strain bridge drifting 0 -> 20 mV over each 6 s recording (10 x its 2 mV noise;
    the Watflex probe of docs/diagnosis.md, read as a +12.2 mV sensor offset and `explained`) is found at 3.33 mV/s
    within 5 % in 3 of 3 recordings, an offset taken off first; named in the verdict's reason. Not flagged: the misfit
    alone, a model that settles 1 noise sd elsewhere after each step (a staircase of offsets, its halves' rates unlike),
    and a drift that accelerates (0 -> 20 mV as t^2: the first half's rate a third of the second's)."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis.data import Data
    from watflex_sim.diagnosis.disturbance import disturbances, steady_drifts
    from watflex_sim.diagnosis.verdict import verdict_reason
    from watflex_sim.recording import Recording

    t = np.arange(0.0, 6.0, 1e-3)  # s
    noise = 2e-3  # V
    since = t % 1.5  # s since the last step
    hold = (t // 1.5).astype(int)
    level = np.array([0.0, 1.0, -1.0, 0.5])[hold] * 0.05  # V
    ring = lambda f: 0.02 * np.exp(-2 * np.pi * f * 0.05 * since) * np.sin(2 * np.pi * f * since)  # noqa: E731

    def drifts(extra) -> list[dict]:
        recordings = [Recording(t, {"strain_2A": level + ring(2.5) + extra + noise * np.random.default_rng(k).normal(size=t.size)}, {})
                      for k in range(3)]
        data = Data(recordings, ["a", "b", "c"], SimpleNamespace(units=lambda: {"strain_2A": "V"}), [["strain_2A"]] * 3,
                    [{"strain_2A": 0.05}] * 3, [{"strain_2A": noise}] * 3, [split_blocks(t)[0]] * 3)
        sims = [Recording(t, {"strain_2A": level + ring(2.6)}, {})] * 3
        assert disturbances(data, sims) == [x for x in disturbances(data, sims) if x["kind"] == "drift"]  # no line
        return steady_drifts(data, sims)

    (drift,) = drifts(0.02 * t / 6.0)
    assert drift["rate"] == pytest.approx(0.02 / 6.0, rel=0.05) and drift["recordings"] == "3 of 3"
    within = {"noise_ratio": 1.0, "worst_ratio": 1.1, "worst_channel": "strain_2A"}
    reason = verdict_reason("unexplained", within, within, within, within, 0.0, [], disturbed=[drift])
    assert f"drifts steadily in time at {drift['rate']:.3g} V/s" in reason and "3 of 3 recordings" in reason
    assert drifts(0.0 * t) == []
    assert drifts(np.array([0.0, -1.0, 1.0, 0.5])[hold] * noise) == []
    assert drifts(0.02 * (t / 6.0) ** 2) == []


def test_effective_samples_of_white_noise_and_of_a_smooth_misfit():
    """White noise is worth its length (within 10 %); a 0.5 Hz sine sampled at 1 kHz for 6 s, a few per period."""
    from watflex_sim.diagnosis.characteristic import effective_samples

    t = np.arange(0.0, 6.0, 1e-3)  # s
    assert effective_samples(np.random.default_rng(2).normal(size=t.size)) == pytest.approx(t.size, rel=0.1)
    assert effective_samples(np.sin(2 * np.pi * 0.5 * t)) < 20


def test_compass_search_crosses_a_rough_cost():
    """A quadratic with a saw-tooth on top (stick-slip's rough cost, local minima every 0.01):
    from 0.5 the pattern search lands within 0.02 of the minimum at 0.83."""
    from watflex_sim.diagnosis.pattern import compass

    def residual(m):
        a = m.parameters["a"]
        return np.array([a - 0.83, 0.02 * math.sin(2 * math.pi * a / 0.01)])

    evaluate = lambda models: [residual(m) for m in models]  # noqa: E731
    slot = [Slot(("param", "a"), 0.0, 2.0)]
    start = Model(parameters={"a": 0.5})
    found = compass(evaluate, start, slot, [0.5], residual(start), sweeps=12)
    assert found.parameters["a"] == pytest.approx(0.83, abs=0.02)


def test_the_compass_stops_where_no_step_could_make_a_move():
    """Missing physics holds the cost up (a residual of 1000 no slot explains: cost 5e5, a move must gain
    COMPASS_GAIN of it, 500): a slot whose every step changes the cost by at most 0.5 x 100 x 0.58 = 29 is
    searched one sweep, not halved until its steps change the cost by less than the resolution (7 sweeps
    before, the step halved from 0.5 to 0.0078, where 0.5 x 100 x ((0.33 + 0.0078)^2 - 0.33^2) = 0.26).
    Near the noise the resolution decides as before (test_the_refit_compass_goes_on_until_...)."""
    from watflex_sim.diagnosis.pattern import compass
    from watflex_sim.diagnosis.pattern import CHI2_RESOLUTION

    calls = []

    def evaluate(models):
        calls.append(len(models))
        return [np.array([1000.0, 10.0 * (m.parameters["a"] - 0.83)]) for m in models]

    slot, start = [Slot(("param", "a"), 0.0, 2.0)], Model(parameters={"a": 0.5})
    found = compass(evaluate, start, slot, [0.5], evaluate([start])[0], 14, resolution=CHI2_RESOLUTION)
    assert found.parameters["a"] == 0.5 and calls == [1, 2]


def test_a_slot_at_its_bound_does_not_hold_the_compass():
    """A slot at its bound steps one way only, and its cost changes in proportion to the step: a step inward that
    loses loses less shorter, but never gains. Cost 10 (a + 0.5) with a at its bound 0: the step inward costs
    0.5 x 100 x (1.0^2 - 0.5^2) = 37.5 more; one sweep, where halving until that change fell below the resolution
    took 7 (seed 56's laser tip-sensor gain x1.081 case, all five rig parameters at their bounds: 186 -> 78
    simulations in its refit, the same refit)."""
    from watflex_sim.diagnosis.pattern import compass
    from watflex_sim.diagnosis.pattern import CHI2_RESOLUTION

    calls = []

    def evaluate(models):
        calls.append(len(models))
        return [np.array([10.0 * (m.parameters["a"] + 0.5)]) for m in models]

    slot, start = [Slot(("param", "a"), 0.0, 2.0)], Model(parameters={"a": 0.0})
    found = compass(evaluate, start, slot, [0.0], evaluate([start])[0], 14, resolution=CHI2_RESOLUTION)
    assert found.parameters["a"] == 0.0 and calls == [1, 1]


def test_the_compass_stops_at_the_first_move_that_is_enough():
    """refit_nominal's pattern search stops once the verdict's own test holds (`enough`; in the clean Watflex
    cases of seeds 55-56 training and validation were within the noise after its first one or two moves and
    it searched on to its 14 sweeps). Here 10 (a - 0.83) from 0.5: moves to 1.0 (step 0.5), then 0.75 (step
    0.25), which is enough (within 0.1 of 0.83): three sweeps, and the model returned is the one judged."""
    from watflex_sim.diagnosis.pattern import compass
    from watflex_sim.diagnosis.pattern import CHI2_RESOLUTION

    calls, judged = [], []

    def evaluate(models):
        calls.append(len(models))
        return [np.array([10.0 * (m.parameters["a"] - 0.83)]) for m in models]

    def enough(model):
        judged.append(model)
        return abs(model.parameters["a"] - 0.83) < 0.1

    slot, start = [Slot(("param", "a"), 0.0, 2.0)], Model(parameters={"a": 0.5})
    found = compass(evaluate, start, slot, [0.5], evaluate([start])[0], 14, resolution=CHI2_RESOLUTION, enough=enough)
    assert found is judged[-1] and [m.parameters["a"] for m in judged] == pytest.approx([1.0, 0.75])
    assert calls == [1, 2, 2, 2]  # the start, then sweeps at steps 0.5 (a move), 0.5 (none), 0.25 (a move, enough)
    unbounded = compass(evaluate, start, slot, [0.5], evaluate([start])[0], 14, resolution=CHI2_RESOLUTION)
    assert abs(unbounded.parameters["a"] - 0.83) < abs(found.parameters["a"] - 0.83)


def test_a_link_stiffness_is_probed_stiffer_as_well_as_softer(laser_recordings):
    """A stiffer link than the datasheet's (issue 14: ratio 3 read as a strain-gauge gain): the
    candidate's probes go to 0.9, 0.6 and 2.0 x the stiffness."""
    from watflex_sim.diagnosis.screening import make_candidate

    cand = make_candidate(prepare(laser_recordings, ["a", "b"]), "link_stiffness_change", "beam")
    assert sorted(round(v["ratio"], 3) for v in cand.probes().values()) == [0.6, 0.9, 2.0]


def test_a_friction_level_is_probed_small_as_well_as_large(laser_recordings):
    """Coulomb friction's levels are probed at 0.25, 1 and 4 x their start (0.1 x the peak effort), each
    level on its own: stick-slip's signature depends on the size (seed 48, a laser hub's 0.045 N m screened
    at 1 % from probes at 1 and 4 x and 18 % once probed at 0.25 x)."""
    from watflex_sim.diagnosis.screening import make_candidate

    cand = make_candidate(prepare(laser_recordings, ["a", "b"]), "coulomb_friction", "hub")
    start = cand.start["torque_positive"]
    probes = cand.probes()
    assert sorted(level for level, name in probes if name == "torque_positive") == [0.25, 1.0, 4.0]
    assert probes[(0.25, "torque_positive")] == {"torque_positive": pytest.approx(0.25 * start), "torque_negative": 0.0}


def _camera_and_strain(k_true=0.98):
    """Issue 14's clean Watflex cases in miniature: a camera channel whose noise is 28 % of its spread and
    a strain bridge whose noise is 1.1 % of its (2 mV on a decaying 2 Hz vibration), the vibration's
    frequency scaled by a rig parameter k (truth 0.98, tolerance 5 %); -> (data, simulate(model))."""
    from watflex_sim.diagnosis.data import Data
    from watflex_sim.recording import Recording

    t = np.arange(0, 6.0, 1e-3)
    noise = {"tip_x": 0.0017, "strain_2A": 0.002}

    def channels(k):
        return {"tip_x": 0.02 * np.sin(0.5 * t), "strain_2A": 0.5 * np.sin(2 * np.pi * 2.0 * k * t) * np.exp(-0.3 * t)}

    rng = np.random.default_rng(0)
    measured = {c: v + noise[c] * rng.normal(size=t.size) for c, v in channels(k_true).items()}
    data = Data([Recording(t, measured, {})], ["a"], None, [list(noise)],
                [{c: float(np.std(v)) for c, v in measured.items()}], [dict(noise)], [split_blocks(t)[0]])
    return data, lambda m: [Recording(t, channels(m.parameters.get("k", 1.0)), {})]


def test_the_refit_cost_sees_a_precise_channel_off_its_noise():
    """Issue 14 (clean Watflex cases called 'unexplained', strain_2A 1.52 x its noise): in spread units
    (NRMSE, what the refit minimised) a strain bridge at 1.5 x its noise costs 0.2 % more than the truth,
    because the camera's noise fills the cost (measured on case watflex-4cecc0b4 of seed 4: truth 6.1214,
    refit 6.1293, 0.13 %), below Levenberg-Marquardt's 0.1 % stopping gain and the compass's 0.1 % step;
    in noise units, what the verdict judges and the refit now minimises, it costs 40 % more."""
    from scipy.optimize import brentq

    from watflex_sim.diagnosis.data import residual_vector, unit_change
    from watflex_sim.diagnosis.scores import channel_ratios

    data, simulate_ = _camera_and_strain()
    strain = lambda k: [r["ratio"] for r in channel_ratios(data, simulate_(Model(parameters={"k": k})), "train")  # noqa: E731
                        if r["channel"] == "strain_2A"][0]
    k_off = brentq(lambda k: strain(k) - 1.5, 0.98, 0.99)
    excess = {}
    for unit in ("spread", "noise"):
        off, truth = (residual_vector(data, simulate_(Model(parameters={"k": k})), unit=unit) for k in (k_off, 0.98))
        excess[unit] = (off @ off - truth @ truth) / (off @ off)
    assert excess["spread"] < 0.005 and excess["noise"] > 0.3
    noise_units = residual_vector(data, simulate_(Model()), unit="noise")  # converted back for the screening
    assert np.allclose(noise_units * unit_change(data), residual_vector(data, simulate_(Model())))


def test_a_channel_further_off_than_its_noise_is_weighted_by_its_misfit():
    """The final refit's units (`unit_change` with the model's simulations): at k = 1.0 against a truth of
    0.98 the strain bridge is off by far more than its 2 mV noise and counts in units of its own RMS
    misfit; the camera, off by its noise alone, keeps its noise (0.0017 m, +-5 % for 6,000 draws'
    RMS). Noise weights alone, on EMPS (current 22 x its noise), put the friction bias 6.8 % from
    Janot's figure (test_diagnose.py)."""
    from watflex_sim.diagnosis.data import unit_change

    data, simulate_ = _camera_and_strain()
    sims = simulate_(Model(parameters={"k": 1.0}))
    units = unit_change(data, "all", stride=1, sims=sims) * np.repeat([data.scale[0][c] for c in data.channels[0]], 6000)
    misfit = float(np.sqrt(np.mean((sims[0].channels["strain_2A"] - data.recordings[0].channels["strain_2A"]) ** 2)))
    assert misfit > 10 * 0.002
    assert units[:6000] == pytest.approx(0.0017, rel=0.05) and units[6000:] == pytest.approx(misfit, rel=1e-9)


def test_the_refit_compass_goes_on_until_the_noise_resolves_no_step():
    """The refit's pattern search in noise units (pattern.COMPASS_SWEEPS, CHI2_RESOLUTION) from k 2 % off
    (the nominal model) reaches the truth to 2e-5, the strain bridge within 1.01 x its noise; 6 sweeps (the
    search before) halve the step to 0.4 % of the tolerance and leave it at 3.0 x (on watflex-4cecc0b4:
    link2_EI 0.97947 against 0.9791, strain_2A 1.32 x; now 0.9791, nothing_missing)."""
    from watflex_sim.diagnosis.data import residual_vector
    from watflex_sim.diagnosis.scores import channel_ratios
    from watflex_sim.diagnosis.pattern import compass
    from watflex_sim.diagnosis.pattern import CHI2_RESOLUTION, COMPASS_SWEEPS

    data, simulate_ = _camera_and_strain()
    evaluate = lambda models: [residual_vector(data, simulate_(m), unit="noise") for m in models]  # noqa: E731
    slot, start = [Slot(("param", "k"), 0.95, 1.05)], Model(parameters={"k": 1.0})
    strain = lambda m: [r["ratio"] for r in channel_ratios(data, simulate_(m), "train") if r["channel"] == "strain_2A"][0]  # noqa: E731
    before = compass(evaluate, start, slot, [1.0], evaluate([start])[0], 6)
    found = compass(evaluate, start, slot, [1.0], evaluate([start])[0], COMPASS_SWEEPS, resolution=CHI2_RESOLUTION)
    assert strain(before) > 2.0
    assert found.parameters["k"] == pytest.approx(0.98, abs=2e-5) and strain(found) < 1.01


def test_a_finding_is_told_from_no_effect_by_its_intervals():
    """explain.indistinct: a finding whose every 95 % interval includes the value at which its effect vanishes
    (the catalogue's neutral: a ratio of 1, no friction) is not told from no effect, and the pipeline drops it
    unless a rig parameter turns the same knob (then the interval carries that parameter's tolerance, and
    tolerance.reaches_tolerance judges it: below).
    Seed 46, watflex-e35447b1: physics outside the catalogue (a cubic strain bridge), 'unexplained', with a
    sensor gain x1.09 [0.968, 1.214] on strain_2B listed as a finding; now dropped, the same verdict, the residual
    at strain_2B. No right finding of the stored benchmark reports (seeds 41-46) has such intervals. Effects
    without a neutral value (a backlash, a compliance) are never indistinct by this test."""
    stiffness = {"effect": "link_stiffness_change", "where": "beam", "ratio": 0.959}
    assert indistinct(None, stiffness, {"ratio": (0.903, 1.018)})
    assert not indistinct(None, stiffness, {"ratio": (0.903, 0.998)})
    viscous = {"effect": "viscous_friction", "where": "hub", "coefficient": 0.01, "coefficient_negative": 0.4}
    assert not indistinct(None, viscous, {"coefficient": (-0.01, 0.03), "coefficient_negative": (0.3, 0.5)})
    assert indistinct(None, viscous, {"coefficient": (-0.01, 0.03), "coefficient_negative": (-0.1, 0.5)})
    assert not indistinct(None, {"effect": "backlash", "where": "hub", "width": 1e-4, "position": 0.0},
                          {"width": (1e-6, 2e-4), "position": (-1.0, 1.0)})
    assert not indistinct(None, stiffness, {})  # no interval: nothing to judge by


def test_a_finding_says_which_interval_reaches_no_effect():
    """explain.finding: a kept finding one of whose 95 % intervals includes the value at which that part of the effect
    vanishes says so, by name and value, in 'explanation' and in 'interval_reaches_neutral' (seed 113's one-way laser
    hub Coulomb friction, 0.0984 / 0 N m: its free side fitted at 0.027 [0, 0.031] N m; a dwell-time stiction's gain
    [0, 0.488]): a user reads that friction the other way, or the dwell's growth, may be absent. Sides whose interval
    is clear of it are not named."""
    one_way = {"effect": "viscous_friction", "where": "hub", "coefficient": 0.4, "coefficient_negative": 0.01}
    scores = dict.fromkeys(["train_before", "train_after", "held_before", "held_after", "ratio_before", "ratio_after",
                            "ablated", "held_without"], 1.0)
    data = types.SimpleNamespace(rig=load_rig("laser_arm"), recordings=[])
    out = finding(data, one_way, {"coefficient": (0.3, 0.5), "coefficient_negative": (-0.002, 0.03)}, scores, [])
    assert out["interval_reaches_neutral"] == ["coefficient_negative"]
    assert "interval reaches coefficient_negative = 0 N m s/rad: the data do not rule that out" in out["explanation"]
    both = finding(data, one_way, {"coefficient": (0.3, 0.5), "coefficient_negative": (0.005, 0.03)}, scores, [])
    assert both["interval_reaches_neutral"] == [] and "rule that out" not in both["explanation"]


def test_a_finding_validation_cannot_do_without_is_not_dropped_for_its_intervals():
    """validate.vague_findings: a finding whose intervals include 'no effect' is dropped only if validation without
    it is not far worse - it removes less than EXPLAINED_SHARE (80 %) of the excess over the noise that validation
    has without it. Seed 46 (watflex-e35447b1): a spurious sensor gain x1.09 [0.968, 1.214], validation 7.17 x the
    noise with it, 8.27 x without (16 %): dropped. Seed 53 (watflex-d245fa05): an elbow ripple at a wrong period,
    its amplitude's interval [-1.87, 6.03], validation 7.59 x with it and 66.12 x without (90 %): kept (it had been
    dropped and the case left `unexplained` with no finding). The rig data only matters for knob partners."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis.validate import vague_findings

    data = SimpleNamespace(rig=SimpleNamespace(parameters={}))
    gain = {"effect": "sensor_gain", "where": "strain_2B", "ratio": 1.0909}
    ripple = {"effect": "position_dependent_friction", "where": "elbow", "amplitude": 2.084, "period": 1.1305,
              "phase": 0.196, "spring": -2.70}
    model = Model([gain, ripple])
    ranges = {0: {"ratio": (0.968, 1.214)}, 1: {"amplitude": (-1.87, 6.03), "period": (0.58, 4.27),
                                                "phase": (0.079, 0.313), "spring": (-17.6, 50.0)}}
    held = {"noise_ratio": 7.17}
    assert vague_findings(data, model, ranges, [{"noise_ratio": 8.27}, {"noise_ratio": 66.12}], held) == [0]
    assert vague_findings(data, model, ranges, [{"noise_ratio": 8.27}, {"noise_ratio": 30.0}], held) == [0, 1]  # 79 %
    # least missed first (settle drops that one only: two findings that stand for each other are each vague beside
    # the other; the EMPS run's Coulomb and Stribeck frictions were dropped together)
    assert vague_findings(data, model, ranges, [{"noise_ratio": 8.27}, {"noise_ratio": 7.5}], held) == [1, 0]
    assert vague_findings(data, model, ranges, [{"noise_ratio": 40.0}, {"noise_ratio": 60.0}], held) == []
    # seed 60's clean watflex-ec898126: an elbow encoder offset of 1.5e-7 rad [-1.5e-4, 1.5e-4], validation 0.906 x
    # the noise with it and 0.92 x without (elbow_torque_cmd 1.380 x either way): nothing above the noise is
    # removed, so it is vague (it was kept: the mean, below 1, counted as 100 % removed)
    offset = Model([{"effect": "sensor_offset", "where": "elbow_angle", "offset": 1.5e-7}])

    def scores(mean, worst):
        return {"noise_ratio": mean, "worst_channel": "elbow_torque_cmd", "worst_ratio": worst,
                "channel_ratios": {"elbow_torque_cmd": worst}}
    assert vague_findings(data, offset, {0: {"offset": (-1.5e-4, 1.5e-4)}}, [scores(0.92, 1.381)], scores(0.906, 1.380)) == [0]
    assert vague_findings(data, offset, {0: {"offset": (-1.5e-4, 1.5e-4)}}, [scores(0.95, 3.0)], scores(0.906, 1.2)) == []
    # seed 77's two-joint watflex-2ae75650: a shoulder Coulomb friction of 0.03 N m [0, 0.14] beside the true strain
    # offset; validation 0.689 x with it, 1.15 x without (shoulder encoder 4.17 x), 0.687 x (tip_y 0.863 x) without it
    # once the rest and the rig's parameters are refit on training: vague. Refit only where the interval is vague and
    # validation without it as it stood kept it
    friction = Model([{"effect": "coulomb_friction", "where": "shoulder", "torque_positive": 0.0265, "torque_negative": 0.0309}])
    intervals = {0: {"torque_positive": (0.0, 0.144), "torque_negative": (0.0, 0.116)}}
    with_it = {"noise_ratio": 0.689, "worst_channel": "tip_y", "worst_ratio": 0.862, "channel_ratios": {"shoulder_angle": 0.9}}
    as_it_stood = {"noise_ratio": 1.15, "worst_channel": "shoulder_angle", "worst_ratio": 4.17, "channel_ratios": {}}
    refit = {"noise_ratio": 0.687, "worst_channel": "tip_y", "worst_ratio": 0.863, "channel_ratios": {}}
    asked = []
    assert vague_findings(data, friction, intervals, [as_it_stood], with_it) == []
    assert vague_findings(data, friction, intervals, [as_it_stood], with_it, lambda i: asked.append(i) or refit) == [0]
    assert asked == [0]
    assert vague_findings(data, friction, intervals, [as_it_stood], with_it, lambda i: None) == []  # the refit diverged
    assert vague_findings(data, model, ranges, [{"noise_ratio": 8.27}, {"noise_ratio": 66.12}], held,
                          lambda i: asked.append(i) or {"noise_ratio": 60.0}) == [0]  # the ripple: still far worse
    assert asked == [0, 1]


def test_a_knob_finding_whose_interval_reaches_back_within_tolerance_is_vague():
    """validate.vague_findings on an effect that turns a rig parameter's knob (a link's stiffness change and its EI,
    rigs.md section 4: EI +-5 %): it is told from parameter error by its ratio's interval leaving the tolerance band
    (tolerance.reaches_tolerance), not by the neutral 1, which such an interval reaches by design. Seed 87's
    laser_arm-791f7610 (a hub backlash; the truth's beam EI 0.9512, refit 0.951): a beam stiffness x0.953 [0.717,
    1.145], validation 0.383 x the noise with it, 0.88 x without (within the margin on every channel): was kept, now
    vague. A real change beyond the tolerance stays (seed 88's laser_arm-c63bcc3f: x0.3875 [0.294, 0.607]), and so
    does one far from the noise that validation needs: the Quanser 2DSFL's link 2 x0.343 [0.19, 4.0], 611.7 x the
    noise with it and 780.5 x without (22 %, against MIN_GAIN's 2 % for its one parameter); 1 % better would not be."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis.tolerance import reaches_tolerance
    from watflex_sim.diagnosis.validate import vague_findings

    data = SimpleNamespace(rig=SimpleNamespace(parameters={"beam_EI": {"knob": "chain_stiffness", "target": "beam",
                                                                        "tolerance": 0.05}}))
    beam = Model([{"effect": "link_stiffness_change", "where": "beam", "ratio": 0.9533}])

    def scores(mean, worst=None):
        return {"noise_ratio": mean, "worst_channel": "motor_current", "worst_ratio": worst or mean,
                "channel_ratios": {"motor_current": worst or mean}}
    assert reaches_tolerance(data, beam.effects[0], {"ratio": (0.717, 1.145)})
    assert reaches_tolerance(data, beam.effects[0], {"ratio": (0.5, 0.951)})
    assert not reaches_tolerance(data, beam.effects[0], {"ratio": (0.294, 0.607)})
    assert not reaches_tolerance(data, beam.effects[0], {"ratio": (1.06, 1.3)})
    assert not reaches_tolerance(data, {"effect": "link_stiffness_change", "where": "link2", "ratio": 1.0},
                                 {"ratio": (0.9, 1.1)})  # no rig parameter on that knob: explain.indistinct judges it
    assert vague_findings(data, beam, {0: {"ratio": (0.717, 1.145)}}, [scores(0.88, 1.1)], scores(0.383, 0.46)) == [0]
    assert vague_findings(data, beam, {0: {"ratio": (0.294, 0.607)}}, [scores(0.88, 1.1)], scores(0.383, 0.46)) == []
    assert vague_findings(data, beam, {0: {"ratio": (0.717, 1.145)}}, [scores(3.0)], scores(0.383, 0.46)) == []  # 92 %
    far = {0: {"ratio": (0.19, 4.0)}}
    assert vague_findings(data, beam, far, [scores(780.5)], scores(611.7)) == []
    assert vague_findings(data, beam, far, [scores(617.9)], scores(611.7)) == [0]  # 1 % better without it


def test_elimination_drops_a_finding_that_validation_does_not_need(monkeypatch):
    """eliminate(): a finding stays only if taking it out of the final model worsens validation by more
    than MIN_HELD_GAIN (1 %, what it had to gain to enter). Seed 5, watflex-3d9bb335: a command delay
    (validation 23.45x the noise without it) and a viscous friction after it (1.276x with it, 1.26x
    without: 1.264 here) - the viscous one was kept by a test of the wrong sign (dropped only if its
    removal *improved* validation by 1 %). Validation noise ratios here are set per set of effects."""
    from watflex_sim.diagnosis import validate

    ratio = {("delay", "viscous_friction"): 1.276, ("delay",): 1.264, ("viscous_friction",): 23.45, (): 23.5}

    class Runner:
        def simulate_models(self, models):
            return [tuple(e["effect"] for e in m.effects) for m in models]  # stands for each model's simulations

    monkeypatch.setattr(validate, "fit_scores", lambda data, sims, part: {"noise_ratio": ratio[sims], "nrmse": ratio[sims] / 100})
    both = Model([{"effect": "delay", "where": "command", "seconds": 0.011},
                  {"effect": "viscous_friction", "where": "elbow", "coefficient": -1e-3, "coefficient_negative": -3e-3}])
    model, sims, without = validate.eliminate(None, Runner(), both, ("delay", "viscous_friction"), lambda *a: None)
    assert sims == ("delay",) and [e["effect"] for e in model.effects] == ["delay"]
    assert [w["noise_ratio"] for w in without] == [23.5]  # what validation would be without the delay
    ratio[("delay",)] = 1.276 * 1.02  # now the viscous friction is worth 2 %: kept
    model, sims, without = validate.eliminate(None, Runner(), both, ("delay", "viscous_friction"), lambda *a: None)
    assert len(model.effects) == 2 and [w["noise_ratio"] for w in without] == [23.45, pytest.approx(1.30152)]


def test_a_later_finding_the_rest_explain_when_carried_on_is_dropped(monkeypatch):
    """settle.spare_a_later_finding(): of an offset and a backlash (seed 97's watflex-da19af81 logged at 2 ms: validation
    1.35 x the noise without the backlash, 22.5 x without the offset), the backlash is dropped when the offset and the
    rig's parameters, carried on by the pattern search, are within the noise (1.07 x: NOISE_MARGIN is 1.3), and the model
    so carried on goes on (the progress names it "the model without backlash at elbow"); it stays when the search
    ends at 1.4 x, or within the noise by the floors the backlash raised but at 1.5 x by those measured again without
    it, and the floors are then as they were; where no finding raised them they are not measured again. The offset,
    beyond COMPASS_REACH x the margin without it, is never tried. A single finding is left to the refit before it."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis import settle

    carried_ratio = {"raised": 1.07, "measured again": 1.07}  # by the floors judged by

    class Runner:
        def simulate(self, model):
            return tuple(e["effect"] for e in model.effects)  # stands for the model's simulations

    named = []  # what the pattern search's progress calls the model it carries on

    def polish(data, runner, model, sims, say, what="the final model"):
        named.append(what)
        return Model(model.effects, {**model.parameters, "elbow_inertia": 1.02}), ("carried", *sims)

    def scores(data, sims, part):
        ratio = carried_ratio[data.noise] if sims[0] == "carried" else 1.35
        return {"noise_ratio": ratio, "worst_ratio": ratio}

    def dropping(data, runner, model, sims, nominal, say):
        data.noise = "measured again"

    monkeypatch.setattr(settle, "pattern_polish", polish)
    monkeypatch.setattr(settle, "fit_scores", scores)
    monkeypatch.setattr(settle, "floors_after_dropping", dropping)
    data = SimpleNamespace(noise="raised", closed_loop_sq=None, discretisation_sq=None, discretisation=None)
    both = Model([{"effect": "actuator_offset", "where": "shoulder_torque_cmd", "offset": 0.85},
                  {"effect": "backlash", "where": "elbow", "width": 1.74e-4}], {"elbow_inertia": 1.0})
    ablated = [{"noise_ratio": 22.5}, {"noise_ratio": 1.35}]
    rejected = []
    model, sims = settle.spare_a_later_finding(data, Runner(), both, ablated, lambda *a: None, rejected, True, {})
    assert [e["effect"] for e in model.effects] == ["actuator_offset"] and model.parameters == {"elbow_inertia": 1.02}
    assert sims == ("carried", "actuator_offset") and [r["effect"] for r in rejected] == ["backlash"]
    assert data.noise == "measured again" and named == ["the model without backlash at elbow"]
    for carried_ratio["raised"], carried_ratio["measured again"] in ((1.4, 1.07), (1.07, 1.5)):
        data.noise, rejected = "raised", []
        assert settle.spare_a_later_finding(data, Runner(), both, ablated, lambda *a: None, rejected, True, {}) is None
        assert data.noise == "raised" and rejected == []
    carried_ratio["raised"] = 1.07
    model, _ = settle.spare_a_later_finding(data, Runner(), both, ablated, lambda *a: None, [], False, {})
    assert [e["effect"] for e in model.effects] == ["actuator_offset"] and data.noise == "raised"  # floors untouched
    assert settle.spare_a_later_finding(data, Runner(), both, [{"noise_ratio": 22.5}, {"noise_ratio": 4.0}],
                                        lambda *a: None, [], True, {}) is None
    assert settle.spare_a_later_finding(data, Runner(), Model(both.effects[:1]), [{"noise_ratio": 1.35}],
                                        lambda *a: None, [], True, {}) is None


def test_a_friction_finding_the_rigs_friction_scale_explains_is_parameter_error(monkeypatch):
    """settle.spare_for_a_rig_parameter(): seed 103's clean two-joint watflex-0a7fefae (shoulder friction x1.046, the
    refit stuck at x1.010) found a shoulder Coulomb friction of 0.32 / 0.29 N m. Without it, the shoulder's friction
    scale tried at 9 ratios across its 5 % tolerance: where one (here x1.0375) is within the noise (NOISE_MARGIN 1.3)
    the finding is dropped and that ratio kept; where none is (a 1.2 N m Coulomb friction: 25 x the noise at best), or
    the finding is not a friction effect at a joint with a friction scale, nothing changes."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis import settle

    class Runner:
        calls = 0

        def simulate(self, model):
            Runner.calls += 1
            return (tuple(e["effect"] for e in model.effects), model.parameters.get("shoulder_friction", 1.0))

    def scores(data, sims, part):  # the friction scale alone explains the data near x1.04
        effects, ratio = sims
        value = 1.0 if effects else data.best + 50 * abs(ratio - 1.04)
        return {"noise_ratio": value, "worst_ratio": value}

    monkeypatch.setattr(settle, "pattern_polish", lambda data, runner, model, sims, say, what="": (model, sims))
    monkeypatch.setattr(settle, "fit_scores", scores)
    rig = SimpleNamespace(parameters={f"{j}_friction": {"knob": "friction", "target": j, "tolerance": 0.05}
                                      for j in ("shoulder", "elbow")})
    data = SimpleNamespace(rig=rig, idle=frozenset(), best=1.0)
    coulomb = Model([{"effect": "coulomb_friction", "where": "shoulder", "torque_positive": 0.32,
                      "torque_negative": 0.29}], {"shoulder_friction": 1.01})
    rejected = []
    model, sims = settle.spare_for_a_rig_parameter(data, Runner(), coulomb, [{"noise_ratio": 7.17}],
                                                   lambda *a: None, rejected, False, {})
    assert model.effects == [] and model.parameters["shoulder_friction"] == pytest.approx(1.0375)
    assert Runner.calls == 9 and [r["effect"] for r in rejected] == ["coulomb_friction"]
    data.best = 25.0
    assert settle.spare_for_a_rig_parameter(data, Runner(), coulomb, [{"noise_ratio": 25.4}], lambda *a: None, [],
                                            False, {}) is None
    Runner.calls = 0
    backlash = Model([{"effect": "backlash", "where": "shoulder", "width": 1e-4}], {})
    assert settle.spare_for_a_rig_parameter(data, Runner(), backlash, [{"noise_ratio": 7.0}], lambda *a: None, [],
                                            False, {}) is None and Runner.calls == 0


def test_an_effect_on_a_rig_parameters_knob_is_as_uncertain_as_that_parameter(laser_recordings):
    """tie_knob_columns(): a tip-sensor gain effect (ratio 1.3) and the rig's tip_sensor_gain (refit at
    1.02, tolerance 2 %, rigs.md section 4) turn the same knob, so the data fix only their product; with one
    column for both, the effect's 95 % interval is its ratio x exp(+-1.96 sd / e), sd = 0.02 / sqrt 3 (the
    tolerance prior, uniform), however precise the data. Finite differences of unequal steps had made the
    pair look separable (seed 6, watflex-b2b8e0e9: a link stiffness 1.32 for 1.386, interval +-0.05 %).
    nominal_split() joins it with the same interval moved to the datasheet's split (gain 1.00)."""
    from watflex_sim.diagnosis.uncertainty import tie_knob_columns, tolerance_sd
    from watflex_sim.diagnosis.fitting import effect_slots_of, rig_slots

    data = prepare(laser_recordings, ["a", "b"])
    model = Model([dict(effect="sensor_gain", where="tip_sensor", ratio=1.3)], {"tip_sensor_gain": 1.02})
    slots = effect_slots_of(data, model) + rig_slots(data)
    i, j = 0, next(k for k, s in enumerate(slots) if s.where == ("param", "tip_sensor_gain"))
    rng = np.random.default_rng(1)
    J = rng.normal(size=(400, len(slots)))  # columns as finite differences would give them: all different
    tied = tie_knob_columns(data, model, slots, J)
    scale = 1.0 if slots[i].log else 1.3
    assert np.allclose(tied[:, j], J[:, i] * scale / 1.02) and np.array_equal(np.delete(tied, j, 1), np.delete(J, j, 1))
    r = 1e-4 * rng.normal(size=400)  # precise data
    prior = [tolerance_sd(s) for s in slots]
    low, high = intervals(slots, model, tied, r, prior)[i]
    sd = 0.02 / math.sqrt(3) / 1.02
    expected = (1.3 * math.exp(-1.96 * sd), 1.3 * math.exp(1.96 * sd)) if slots[i].log else (1.3 * (1 - 1.96 * sd), 1.3 * (1 + 1.96 * sd))
    assert low == pytest.approx(expected[0], rel=2e-3) and high == pytest.approx(expected[1], rel=2e-3)
    narrow = intervals(slots, model, J, r, prior)[i]
    assert narrow[1] - narrow[0] < 0.01 * (high - low)  # untied, the precise data "separate" them
    # nominal_split(): the fit's split (gain 1.02) is arbitrary, so the interval also spans the one about the
    # datasheet's gain (1.00): the product 1.326 over 1.00, with the same relative width
    from watflex_sim.diagnosis.uncertainty import nominal_split
    assert nominal_split(data, model, slots[i], low, high) == pytest.approx((low, high * 1.02))
    assert nominal_split(data, Model(model.effects, {"tip_sensor_gain": 0.98}), slots[i], low, high) == pytest.approx((low * 0.98, high))


def test_a_later_finding_must_remove_the_excess_that_asked_for_it():
    """excess_gain(): the share of validation's excess over the noise a later finding removes, measured
    where the excess is. Mean beyond NOISE_MARGIN (1.3): the mean's (1.618 -> 1.276 removes 55 %). Mean
    within but strain_2A at 1.359 (seed 5, watflex-86857155, after the payload): that channel's, so a
    0.09 % elbow-encoder gain that takes the mean 1.023 -> 0.941 and strain_2A 1.359 -> 1.336 removes
    6 % (< MIN_EXCESS_GAIN 25 %), not the 356 % the mean would say. Validation within the margin
    everywhere and its mean within EXCESS_FLOOR of the noise: nothing (0); its mean further (seed 82's
    laser_arm-a3b93926 after the payload, 1.13 x, training 1.26 x with a channel at 1.68 x): the mean's excess over 1,
    which a beam stiffness taking validation to 0.884 x removes whole; a model short of the noise (seed 83's clean
    two-joint watflex-bfdbfde3, an elbow-encoder gain taking 1.19 x to 1.10 x) still nothing."""
    from watflex_sim.diagnosis.validate import EXCESS_FLOOR, MIN_EXCESS_GAIN, excess_gain

    def held(mean, worst=1.0, channel="strain_2A", **others):
        return {"noise_ratio": mean, "worst_channel": channel, "worst_ratio": worst, "channel_ratios": {channel: worst, **others}}

    assert excess_gain(held(1.618, 2.0), held(1.276, 1.5)) == pytest.approx(0.342 / 0.618)
    gain = excess_gain(held(1.023, 1.359), held(0.941, 1.336))
    assert gain == pytest.approx(0.023 / 0.359) and gain < MIN_EXCESS_GAIN
    assert excess_gain(held(1.023, 1.359), held(1.0, 1.05)) == pytest.approx(0.309 / 0.359)
    assert excess_gain(held(1.05, 1.25), held(0.9, 1.0)) == 0.0 and 1.05 < 1.0 + EXCESS_FLOOR
    assert excess_gain(held(1.13, 1.25), held(0.884, 1.0)) == pytest.approx(0.246 / 0.13)
    assert excess_gain(held(1.19, 1.25), held(1.10, 1.0)) == 0.0  # seed 83's clean two-joint case: not to the noise


def test_an_explanation_within_the_noise_beside_the_chosen_one_is_an_alternative():
    """validate.rival, on the reports' own figures. Seed 70's watflex-76acf3b0 (a 0.189 kg tip payload; refit
    model at 4.60 x the noise on validation): the elbow torque gain chosen at 0.738 x, the payload at 0.806 x,
    9 % worse but both below the floor and the payload earning its place: an alternative. Seed 69's
    watflex-d72dd211: a position-dependent friction at 0.879 x beside the dwell stiction's 0.731 x, with
    training 4.9 % better for 4 parameters (under MIN_GAIN's 2 % each): not one. Seed 69's laser_arm-96cd750a:
    0.8945 x against 0.8947 x, within ALTERNATIVE_MARGIN with no gain of its own: one. Above the floor only the
    relative margin counts. Below it, a gap in squares beyond what the floor holds besides white noise
    (Data.absorbable: 0.283 for the payload case's recordings, 0.013 for seed 71's laser_arm-6b5ba9f1) tells them
    apart: that case with its proposed sweep run, the true beam x0.33 at 0.800 x and a hub compliance at 0.941 x."""
    from watflex_sim.diagnosis.validate import gains, rival

    def scores(mean):
        return {"noise_ratio": mean, "worst_channel": "strain_2A", "worst_ratio": mean, "channel_ratios": {"strain_2A": mean}}

    def fitted(train_before, held_before, train_after, held_after, n_params=1):
        return gains({"train": scores(train_after), "held_out": scores(held_after), "n_params": n_params},
                     scores(train_before), scores(held_before))

    gain, payload = fitted(4.6, 4.603, 0.71, 0.7381), fitted(4.6, 4.603, 0.77, 0.8063)
    assert rival(payload, gain, later=False, absorbable=1.0) and rival(payload, gain, later=False, absorbable=0.283)
    assert not rival(payload, gain, later=False, absorbable=0.013)  # 0.806^2 - 0.738^2 = 0.105
    beam, hub = fitted(8.65, 8.02, 0.80, 0.8001), fitted(8.65, 8.02, 0.89, 0.9409)
    assert rival(hub, beam, later=False, absorbable=1.0) and not rival(hub, beam, later=False, absorbable=0.013)
    dwell = fitted(0.92, 0.919, 0.72, 0.7309, 2)
    assert not rival(fitted(0.92, 0.919, 0.92 * (1 - 0.0489), 0.879, 4), dwell, later=False, absorbable=1.0)
    assert rival(fitted(1.0, 0.895, 1.0, 0.8945, 4), fitted(1.0, 0.895, 0.96, 0.8947), later=False, absorbable=1.0)
    assert not rival(fitted(4.6, 4.603, 1.02, 1.05), fitted(4.6, 4.603, 0.97, 0.98), later=False, absorbable=1.0)  # 7 % worse, above
    assert rival(fitted(4.6, 4.603, 1.20, 1.23), fitted(4.6, 4.603, 1.18, 1.20), later=False, absorbable=1.0)  # 2.5 % worse


def test_a_candidate_at_its_catalogue_bound_gives_way_to_a_rival_inside_its_range(laser_recordings):
    """refine.inside_catalogue, on seed 82's laser_arm-a3b93926 (beam x0.61 and a 0.76 kg payload; after the payload,
    validation at 1.13 x the noise): a hub compliance at the catalogue's stiffest 3e4 N m/rad (effects.CATALOGUE) took
    validation to 0.884 x, the true beam stiffness x0.634 to 0.885 x: the beam is taken. Not when the compliance is
    inside its range (2e4), nor for a rival at its own bound (a beam x1000, the rigid end), nor for one 7 % worse on
    validation; a bound at 0 (a one-way friction's other side) is a value, not a bound."""
    from watflex_sim.diagnosis.refine import at_catalogue_bound, inside_catalogue
    from watflex_sim.diagnosis.validate import gains

    data = prepare(laser_recordings, ["a", "b"])
    payload = dict(effect="payload", where="tip", mass=0.743)

    def scores(mean):
        return {"noise_ratio": mean, "worst_channel": "motor_current", "worst_ratio": mean, "channel_ratios": {"motor_current": mean}}

    def fitted(effect, held_after, **parameters):
        model = Model([payload, dict(effect=effect, where="hub" if effect == "joint_compliance" else "beam", **parameters)], {})
        return gains({"train": scores(0.858), "held_out": scores(held_after), "n_params": 1, "effect": effect,
                      "where": model.effects[1]["where"], "model": model}, scores(1.262), scores(1.131))

    beam = fitted("link_stiffness_change", 0.8854, ratio=0.634)
    assert inside_catalogue(data, [fitted("joint_compliance", 0.8841, stiffness=3e4), beam], True, 1) is beam
    inside = fitted("joint_compliance", 0.8841, stiffness=2e4)
    assert inside_catalogue(data, [inside, beam], True, 1) is inside
    at_bound = fitted("joint_compliance", 0.8841, stiffness=3e4)
    assert inside_catalogue(data, [at_bound, fitted("link_stiffness_change", 0.8854, ratio=1000.0)], True, 1) is at_bound
    assert inside_catalogue(data, [at_bound, fitted("link_stiffness_change", 0.946, ratio=0.634)], True, 1) is at_bound
    one_way = Model([dict(effect="coulomb_friction", where="hub", torque_positive=0.3, torque_negative=0.0)], {})
    assert not at_catalogue_bound(data, one_way, 0) and not at_catalogue_bound(data, at_bound["model"], 2)


def test_the_absorbable_share_of_the_floor(laser_recordings):
    """Data.absorbable: a floor twice a channel's white noise is 3/4 not that noise (1 - 1/2^2); as prepared
    (floor = the noise the recordings show) nothing is; the mean is over recordings and channels."""
    data = prepare(laser_recordings, ["a", "b"])
    assert data.absorbable == 0.0
    data.noise[0] = {c: 2.0 * n for c, n in data.noise[0].items()}
    assert data.absorbable == pytest.approx(0.75 * len(data.noise[0]) / sum(map(len, data.noise)))


def test_with_training_within_the_noise_validation_decides():
    """shortfall(): seed 59's laser_arm-7cf6ef08 (a beam 0.64 x as stiff; report of 0be39b8): training at
    0.86 x the noise, validation at 1.48 x (mean) with voltage_cmd at 1.92 x; the fitted stiffness took
    validation to 0.88 x (0.40 of its ratio, 125 % of its excess) but training by only 0.55 %, under the
    2 %/parameter (MIN_GAIN) a finding pays when training has something to gain. With training within
    NOISE_MARGIN it earns its place; the same gains with training at 1.5 x do not, nor does a candidate
    that removes less than MIN_EXCESS_GAIN of validation's excess or makes training worse."""
    from watflex_sim.diagnosis.validate import gains, shortfall

    def scores(mean, worst=1.0):
        return {"noise_ratio": mean, "worst_channel": "voltage_cmd", "worst_ratio": worst,
                "channel_ratios": {"voltage_cmd": worst}}

    def fitted(train_before, train_after, held_after, worst_after):
        result = {"train": scores(train_after), "held_out": scores(held_after, worst_after), "n_params": 1}
        return gains(result, scores(train_before), scores(1.4770, 1.918))

    stiffness = fitted(0.8558, 0.8511, 0.8792, 0.95)
    assert stiffness["excess_gain"] == pytest.approx((1.4770 - 0.8792) / 0.4770)
    assert shortfall(stiffness, later=False) == "" and shortfall(stiffness, later=True) == ""
    assert shortfall(fitted(1.5, 1.4918, 0.8792, 0.95), later=False) == "less than its parameters' cost"
    assert shortfall(fitted(0.8558, 0.8511, 1.40, 1.9), later=False) != ""  # 16 % of the excess
    assert shortfall(fitted(0.8558, 0.8600, 0.8792, 0.95), later=False) != ""  # training worse


def test_a_later_finding_far_from_the_noise_pays_its_parameters_on_both_parts():
    """validate.far_gain: the Quanser 2DSFL's real recordings (docs/rigs.md, 2026-12-03 at 9025277), link 2's stiffness
    found, training 881.6 x and validation 900.5 x the noise: a drive-1 compliance (1 parameter) took training 18.3 % and
    validation 15.4 % lower, 15 % of the excess, and was refused by MIN_EXCESS_GAIN (25 %). Its round began beyond
    FAR_FROM_NOISE, so it earns its place; a backlash there (2 parameters: 2.8 % / 2.4 %, under 2 x MIN_GAIN = 4 %)
    does not, nor do the compliance's gains in a round begun at 12 x the noise (a benchmark pair's scale)."""
    from watflex_sim.diagnosis.validate import FAR_FROM_NOISE, MIN_GAIN, gains, shortfall

    def scores(mean):
        return {"noise_ratio": mean, "worst_channel": "link1", "worst_ratio": mean, "channel_ratios": {"link1": mean}}

    def fitted(train_before, held_before, train_gain, held_gain, n_params):
        result = {"train": scores(train_before * (1 - train_gain)), "held_out": scores(held_before * (1 - held_gain)),
                  "n_params": n_params}
        return gains(result, scores(train_before), scores(held_before))

    compliance = fitted(881.6, 900.5, 0.183, 0.154, 1)
    assert compliance["excess_gain"] == pytest.approx(0.154, abs=0.001)  # the bar it used to miss
    assert shortfall(compliance, later=True) == "" and shortfall(compliance, later=False) == ""
    backlash = fitted(881.6, 900.5, 0.028, 0.024, 2)
    assert 2 * MIN_GAIN > backlash["held_gain"] and shortfall(backlash, later=True) != ""
    near = fitted(12.0, 12.0 * 0.98, 0.183, 0.154, 1)
    assert near["held_before"] < FAR_FROM_NOISE and "a later finding must remove 25 %" in shortfall(near, later=True)


def test_the_refit_compass_runs_only_near_the_noise():
    """compass_worth(): the refit's pattern search is for a refit short of the noise on some channel
    (a clean Watflex case at 2.2 x), not for one far off (a 0.33 kg payload left the refit at 11.7 x:
    the search only pushed the elbow inertia to its bound), nor for one already within the margin."""
    from watflex_sim.diagnosis.pattern import COMPASS_REACH, NOISE_MARGIN, compass_worth

    assert compass_worth({"noise_ratio": 2.2, "worst_ratio": 3.0})
    assert compass_worth({"noise_ratio": 1.1, "worst_ratio": 1.5})
    assert not compass_worth({"noise_ratio": 11.7, "worst_ratio": 30.0})
    assert not compass_worth({"noise_ratio": 1.1, "worst_ratio": 1.2})
    assert COMPASS_REACH * NOISE_MARGIN > 2.2


def test_the_final_model_is_carried_on_by_a_pattern_search_near_the_noise(monkeypatch):
    """pattern.pattern_polish (settle, before the verdict): the final model short of the noise but near it is searched
    on, and the search kept where validation is no worse. Figures of seed 83's two-joint watflex-490a4521 (an 11 ms
    command delay, found): training 1.47 x (elbow torque 1.64 x), validation 1.87 x (elbow encoder 3.41 x); searched
    from there to its end: 0.78 x and 0.84 x (tip 0.86 x and 0.98 x). Not searched: a model within the noise, or one 11.7 x
    off (compass_worth); refused: a search that leaves validation worse."""
    from watflex_sim.diagnosis import pattern
    from watflex_sim.diagnosis.data import Data, Model

    scores = {"short": ({"noise_ratio": 1.47, "worst_ratio": 1.64}, {"noise_ratio": 1.87, "worst_ratio": 3.41}),
              "searched": ({"noise_ratio": 0.78, "worst_ratio": 0.86}, {"noise_ratio": 0.84, "worst_ratio": 0.98}),
              "worse": ({"noise_ratio": 1.20, "worst_ratio": 1.25}, {"noise_ratio": 1.90, "worst_ratio": 2.0}),
              "within": ({"noise_ratio": 1.0, "worst_ratio": 1.2}, {"noise_ratio": 1.1, "worst_ratio": 1.25}),
              "far": ({"noise_ratio": 11.7, "worst_ratio": 30.0}, {"noise_ratio": 12.0, "worst_ratio": 31.0})}
    monkeypatch.setattr(pattern, "fit_scores", lambda data, sims, part: scores[sims][0 if part == "train" else 1])
    monkeypatch.setattr(pattern, "rig_slots", lambda data: [])
    monkeypatch.setattr(pattern, "effect_slots_of", lambda data, model: [])
    monkeypatch.setattr(pattern, "in_noise", lambda data, runner: None)
    ends = {}
    monkeypatch.setattr(pattern, "pattern_search", lambda data, runner, ev, model, free, sims: (Model([], {"moved": 1.0}), ends[sims]))
    model = Model([{"effect": "delay", "where": "command", "seconds": 0.011}], {})
    polish = lambda sims: pattern.pattern_polish(Data.__new__(Data), None, model, sims, lambda *a: None)  # noqa: E731
    ends["short"] = "searched"
    assert polish("short") == (Model([], {"moved": 1.0}), "searched")
    ends["short"] = "worse"
    assert polish("short") == (model, "short")
    ends["within"] = ends["far"] = "searched"
    assert polish("within") == (model, "within") and polish("far") == (model, "far")


def test_the_discretisation_error_joins_the_noise_floor(laser_recordings):
    """finer_discretisation: twice the segments and half the step of the model (a rig without generated
    flexible parts keeps its segments; one without parameters, a datasheet's, halves its compiled step);
    add_discretisation_error adds the RMS difference to a finer simulation
    in quadrature to each channel's noise and keeps it for the report."""
    from watflex_sim.diagnosis.floors import add_discretisation_error
    from watflex_sim.recording import Recording
    from watflex_sim.resim import finer_discretisation, scenario_from_recording
    from watflex_sim.rigdesc import load_rig

    laser, watflex = load_rig("laser_arm"), load_rig("watflex")
    scenario = scenario_from_recording(laser_recordings[0], laser)
    assert finer_discretisation(laser, scenario, 2) == {"n_segments": 22, "timestep": pytest.approx(5e-5)}
    assert finer_discretisation(laser, scenario, 1) == {}
    assert finer_discretisation(watflex, load_scenario("watflex_elbow_step"), 2) == {"n_segments": 24, "timestep": pytest.approx(2.5e-4)}
    quanser = load_rig("quanser_2dsfl")  # described by a datasheet alone: its compiled model's step, halved
    assert finer_discretisation(quanser, {"n_segments": 0, "timestep": 0.0}, 2) == {
        "timestep": pytest.approx(load_model(quanser).opt.timestep / 2, rel=1e-12)}
    data = prepare(laser_recordings, ["a", "b"])
    before = [dict(n) for n in data.noise]
    shifted = [Recording(r.time, {c: v + 0.03 for c, v in r.channels.items()}, r.meta) for r in data.recordings]
    add_discretisation_error(data, data.recordings, shifted)
    for i, chans in enumerate(data.channels):
        for c in chans:
            assert data.discretisation[i][c] == pytest.approx(0.03, rel=1e-9)
            assert data.noise[i][c] == pytest.approx(math.hypot(before[i][c], 0.03), rel=1e-12)


def test_a_coarser_discretisation_keeps_a_step_that_divides_the_control_period():
    """finer_discretisation below 1 (the screening's signatures, screening.SCREEN_FINER): half the segments (rounded,
    at least 2) and twice the step, the step only where it still divides the 1 ms control period."""
    from watflex_sim.resim import finer_discretisation
    from watflex_sim.rigdesc import load_rig

    laser, watflex = load_rig("laser_arm"), load_rig("watflex")
    assert finer_discretisation(laser, load_scenario("laser_arm_step"), 0.5) == {"n_segments": 6, "timestep": pytest.approx(2e-4)}
    assert finer_discretisation(watflex, load_scenario("watflex_elbow_step"), 0.5) == {"n_segments": 6, "timestep": pytest.approx(1e-3)}
    one_ms = load_scenario("watflex_elbow_step", ["timestep=0.001"])  # 2 ms would not divide the 1 ms period
    assert finer_discretisation(watflex, one_ms, 0.5) == {"n_segments": 6}
    assert finer_discretisation(watflex, load_scenario("watflex_elbow_step", ["n_segments=2", "timestep=0.001"]), 0.5) == {}
    assert finer_discretisation(watflex, load_scenario("watflex_elbow_step", ["n_segments=3"]), 0.5) == {
        "n_segments": 2, "timestep": pytest.approx(1e-3)}


def test_signatures_are_differences_at_one_discretisation(monkeypatch):
    """screening.signatures simulates the probes and the model itself SCREEN_FINER x as fine, in one call, and takes
    each column against that coarse model: an error of the coarse discretisation common to both cancels. A probe
    that diverges there is simulated as fine as the model, against the given residual r0. Here the residual is
    x col + e with e = 5 at the coarse discretisation, 0 at the model's: both columns come out as col exactly, in the
    units `per` turns spread units into (the screening compares in noise units, as the fits and the verdict)."""
    from watflex_sim.diagnosis import screening
    from watflex_sim.diagnosis.screening import SCREEN_FINER, Candidate

    col = np.array([1.0, -2.0, 0.5])
    calls = []

    def evaluator(runner, part="train", unit="spread", finer=1):
        def evaluate(models):
            calls.append((finer, len(models)))
            out = []
            for m in models:
                x = sum(e.get("damping", 0.0) + e.get("level", 0.0) for e in m.effects)
                diverges = finer != 1 and any(e.get("level", 0.0) > 0 for e in m.effects)
                out.append(None if diverges else x * col + (5.0 if finer != 1 else 0.0))
            return out
        return evaluate

    monkeypatch.setattr(screening, "evaluator", evaluator)
    monkeypatch.setattr(screening, "fed_back", lambda data: set())
    cands = [Candidate(name, "hub", {key: 0.2}, {key: Slot(("effect", -1, key), 0.0, 1.0)}, {key: 0.0})
             for name, key in (("viscous_friction", "damping"), ("coulomb_friction", "level"))]
    class Runner:  # a rig whose model has a coarser discretisation
        fidelity = 1.0

        def refinable(self, factor):
            return factor == SCREEN_FINER

    per = np.array([1.0, 2.0, 4.0])  # noise / spread of each element
    screening.signatures(None, Runner(), Model(), [], np.zeros(3), cands, per)
    assert calls == [(SCREEN_FINER, 3), (1, 1)]  # the base and both probes coarse; the diverged probe again, as fine
    for cand, key in zip(cands, ("damping", "level")):
        np.testing.assert_allclose(cand.signature[1.0][key], col / per, rtol=1e-12)


def test_the_watflex_model_is_coarser_than_its_noise_and_the_laser_arm_is_not():
    """What add_discretisation_error exists for (docs/diagnosis.md): a 1 s elbow step re-simulated with
    twice the segments and half the step (24 at 0.25 ms against 12 at 0.5 ms) differs from the model as
    committed by more than the noise on strain_2A (measured 1.8 x; the elbow encoder 3.3 x), a 1 s laser
    step by under a tenth of the tip sensor's noise (0.06 x)."""
    from watflex_sim.resim import finer_discretisation
    from watflex_sim.rigdesc import load_rig

    for rig, name, channel, low, high in (("watflex", "watflex_elbow_step", "strain_2A", 1.0, 10.0),
                                          ("laser_arm", "laser_arm_step", "tip_sensor", 0.0, 0.1)):
        description = load_rig(rig)
        scenario = load_scenario(name, ["duration_s=1.0"])
        ours = simulate(scenario).recording.channels[channel]
        finer = simulate({**scenario, **finer_discretisation(description, scenario, 2)}).recording.channels[channel]
        ratio = float(np.sqrt(np.nanmean((finer - ours) ** 2))) / description.channels[channel]["noise"]
        assert low < ratio < high, (rig, ratio)


def test_the_polish_also_starts_from_the_rig_as_its_datasheet_says(monkeypatch):
    """polish(): the rig's parameters fitted while physics was missing absorbed some of it; a fit from there
    can stall (README demo: validation 1.36 x the noise and a spurious third finding; from the datasheet's
    values, 0.84 x). Here every fit stalls where it starts (a rough cost), and training scores depend on the
    rig's ratio only, best at 1: the polish must come back with the start at `rig_start` ({}: the datasheet),
    keep the effect's value, and keep its own result when the restart fits worse."""
    from watflex_sim.diagnosis import refine

    monkeypatch.setattr(refine, "levenberg", lambda evaluate, model, free, x0, J, iters: (model, 0.0, None))
    monkeypatch.setattr(refine, "in_noise", lambda data, runner: None)
    monkeypatch.setattr(refine, "scored", lambda data, result, sims: {**result, "train": {"noise_ratio": sims}})

    class Runner:
        def simulate(self, model):
            return 1.0 + 50 * abs(model.parameters["beam_EI"] - 1.0)  # stands for the training noise ratio

        def simulate_models(self, models):
            return [self.simulate(m) for m in models]

    free = [Slot(("effect", 0, "width"), 1e-5, 0.5, log=True), Slot(("param", "beam_EI"), 0.95, 1.05)]
    found = Model([{"effect": "backlash", "where": "hub", "width": 2.9e-4, "position": 0.9}], {"beam_EI": 1.009})
    result = {"model": found, "free": free, "train": {"noise_ratio": Runner().simulate(found)}}
    polished = refine.polish(None, Runner(), result, rig_start={})
    assert polished["model"].parameters == {"beam_EI": 1.0} and polished["train"]["noise_ratio"] == 1.0
    assert polished["model"].effects == found.effects
    worse = refine.polish(None, Runner(), result, rig_start={"beam_EI": 1.04})
    assert worse["model"].parameters == {"beam_EI": 1.009}
    assert refine.polish(None, Runner(), result)["model"] is found  # no rig start: the fit alone


def test_a_rig_parameter_pinned_at_its_bound_asks_for_the_effect_that_turns_its_knob(laser_recordings):
    """beyond_tolerance(): the laser beam's EI refit to 0.95 (its -5 % bound, rigs.md) may be the datasheet wrong
    beyond its tolerance: the candidate is link_stiffness_change at the beam, and it is not held to a later
    finding's excess rule (seed 43: a beam 36 % softer beside a 5 ms delay was missed at 1.17 x the noise). An
    inertia at its bound has no such effect; EI inside its tolerance, or the effect already found, asks nothing."""
    from watflex_sim.diagnosis.tolerance import beyond_tolerance

    data = prepare(laser_recordings, ["pos", "neg"])
    pinned = beyond_tolerance(data, Model(parameters={"beam_EI": 0.95, "hub_inertia": 0.97}))
    assert [(c.effect, c.where) for c in pinned] == [("link_stiffness_change", "beam")]
    assert beyond_tolerance(data, Model(parameters={"beam_EI": 0.96, "hub_inertia": 0.97})) == []
    found = [{"effect": "link_stiffness_change", "where": "beam", "ratio": 0.64}]
    assert beyond_tolerance(data, Model(found, {"beam_EI": 0.95})) == []


def test_refit_parameters_say_which_quantity_their_value_is():
    """report.parameter_values: the laser arm's `hub_inertia` turns the hub geom's mass (rigs/laser_arm.toml: knob
    geom_mass), so its value is a mass in kg and says so, not an inertia in kg, with the inertia that mass gives the hub
    about its hinge in kg m^2 (the disc's m r^2 / 2: params.LASER_ARM.hub_inertia, J_arm - rho L^3/3 - m_tip L^2 of
    rigs.md section 1, 0.01938 kg m^2); `motor_inertia` is the hub joint's armature in kg m^2. EMPS's carriage slides:
    its mass has no inertia about a hinge."""
    from watflex_sim.params import LASER_ARM
    from watflex_sim.report import parameter_values

    values = parameter_values("laser_arm", {"hub_inertia": 1.03, "motor_inertia": 1.0})
    assert values["hub_inertia"]["unit"] == "kg" and values["hub_inertia"]["quantity"] == "mass of geom hub"
    assert values["hub_inertia"]["inertia"] == pytest.approx(1.03 * LASER_ARM.hub_inertia, rel=1e-6)
    assert values["hub_inertia"]["inertia_unit"] == "kg m^2" and values["hub_inertia"]["inertia_about"] == "joint hub"
    assert "inertia" not in parameter_values("emps", {"mass": 1.0})["mass"]
    assert values["motor_inertia"]["unit"] == "kg m^2" and values["motor_inertia"]["quantity"].startswith("armature")


def test_a_finer_simulators_data_widen_the_interval_to_its_value(monkeypatch):
    """discretisation_error() and fitting.intervals' bound on the bias it causes: Watflex elbow steps (+-0.5 rad,
    1.5 s, noise off) recorded with a 0.4 kg tip payload by a 2 x finer discretisation (24 segments a link, 0.25 ms:
    another implementation of the same datasheet). Our model (12 segments, 0.5 ms) fitted to them puts the payload
    off by its own discretisation's bias, with an interval from the data alone that reaches the truth at its very edge
    if at all; the bound |b| <= |g| |P e| on the bias of the error e a finer model shows (fitting.intervals) reaches
    past the truth, and stays an interval worth having (measured: 0.4025 kg, alone [0.3999, 0.4030], widened [0.3866,
    0.4163]: +-3.7 %; with the damping rule before 2026-12-08, link 2's first mode at 0.0079 (docs/models.md), alone
    [0.4003, 0.4029] missed it)."""
    from watflex_sim.diagnosis import uncertainty
    from watflex_sim.diagnosis.data import unit_change
    from watflex_sim.diagnosis.floors import add_discretisation_error
    from watflex_sim.diagnosis.fitting import effect_slots_of, levenberg, value_of
    from watflex_sim.diagnosis.runner import Runner, evaluator, in_units

    truth = 0.4  # kg
    recs = []
    for i, d in enumerate(("positive", "negative")):
        scenario = load_scenario("watflex_elbow_step", [f"direction={d}", "duration_s=1.5", "noise=false", f"seed={i}",
                                                        "n_segments=24", "timestep=0.00025"])
        scenario["effects"] = [{"effect": "payload", "where": "tip", "mass": truth}]
        recs.append(simulate(scenario).recording)
    data = prepare(recs, ["up", "down"])
    with Runner(data, workers=1) as runner:
        add_discretisation_error(data, runner.simulate(Model()), runner.simulate(Model(), finer=2))
        start = Model([{"effect": "payload", "where": "tip", "mass": 0.3}])
        slots = effect_slots_of(data, start)
        per = unit_change(data, "all", sims=runner.simulate(start))
        ours = levenberg(in_units(evaluator(runner, "all"), per), start, slots, [0.3], iters=10)[0]
        sims = runner.simulate(ours)
        widened = uncertainty.final_intervals(data, runner, ours, sims)[0]["mass"]
        monkeypatch.setattr(uncertainty, "discretisation_error", lambda *a: None)
        alone = uncertainty.final_intervals(data, runner, ours, sims)[0]["mass"]
    estimate = value_of(ours, slots[0])
    assert abs(estimate - truth) > 2e-3  # kg: what our discretisation costs the estimate
    assert truth < alone[0] + 0.1 * (alone[1] - alone[0])  # at its edge, if inside
    assert widened[0] <= truth <= widened[1]
    assert widened[1] - widened[0] < 0.1 * estimate, widened


def _slice_case(cost):
    """slice_reach() on one effect parameter x (bounds 0-10) whose cost is `cost(x)` (0.5 |r|^2, r of
    1,000 white elements so that s^2 is well defined), estimate 5.0 with an interval of [4.9, 5.1]."""
    from watflex_sim.diagnosis.fitting import Slot
    from watflex_sim.diagnosis.reach import slice_reach

    noise = np.random.default_rng(0).standard_normal(1000)
    noise /= np.sqrt(noise @ noise)

    def residual(x):
        return noise * np.sqrt(2 * cost(x))
    slots = [Slot(("effect", 0, "x"), 0.0, 10.0)]
    model = Model([{"effect": "test", "where": "here", "x": 5.0}])
    evaluate = lambda models: [residual(m.effects[0]["x"]) for m in models]  # noqa: E731
    return slice_reach(evaluate, model, slots, 0, residual(5.0), 4.9, 5.1)


def test_a_slice_leaves_a_smooth_minimum_alone_and_reaches_past_a_rough_one():
    """slice_reach(): on a parabola with its minimum at the estimate the slice adds nothing (its threshold,
    1.96^2/2 s^2 = 3.8 with s^2 ~ 2 x 1000 / 999, is below the parabola's 1,000 (x - 5)^2 = 10 at the first
    probes, +-0.1); with jumps of +-300 between probes (stick-slip: seed 47's structural damping jumped +-400
    between probes 0.01 apart) the probes at 4.6 and 5.4 beat the estimate by 140 and the interval reaches
    them, but not 4.2 and 5.8, 940 above them (the jumps' RMS about a parabola is ~170)."""
    smooth = lambda x: 1000 * (x - 5) ** 2 + 1000  # noqa: E731
    assert _slice_case(smooth) == pytest.approx((4.9, 5.1))
    jumps = {4.2: 300, 4.6: -300, 4.8: -50, 5.2: 300, 5.4: -300, 5.8: 300}
    rough = lambda x: smooth(x) + next((v for k, v in jumps.items() if abs(k - x) < 1e-6), 0.0)  # noqa: E731
    low, high = _slice_case(rough)
    assert low == pytest.approx(4.6) and high == pytest.approx(5.4)


def test_a_slice_follows_a_valley_where_the_others_can_move():
    """slice_reach() with the Jacobian: the cost along a slot is profiled, the other slots re-optimised to first order.
    Stand-in: x and y (bounds 0-10) on a valley y = x, r = 1e4 (y - x) w1 + 39.3 (x - 5) w2 + e (w1, w2 unit and
    orthogonal to each other and to the 1,000 white elements e), estimate (5, 5), interval given [4.99, 5.01]. Held at
    y = 5, a probe 0.01 off costs 0.5 (1e4 x 0.01)^2 = 5,000 more: the slice adds nothing. With y following x the
    cost rises by 0.5 x 39.3^2 d^2 only, within the threshold 1.96^2 / 2 s^2 = 1.93 (s^2 ~ 1000 / 998) up to
    d = 0.050: the probes at +-0.04 join, +-0.08 (4.9 more) do not (the profile likelihood's own 95 % interval)."""
    from watflex_sim.diagnosis.fitting import Slot
    from watflex_sim.diagnosis.reach import slice_reach

    rng = np.random.default_rng(1)
    e = rng.standard_normal(1000)
    w1, w2 = np.linalg.qr(np.column_stack([e, rng.standard_normal(1000), rng.standard_normal(1000)]))[0][:, 1:].T

    def residual(x, y):
        return 1e4 * (y - x) * w1 + 39.3 * (x - 5.0) * w2 + e
    slots = [Slot(("effect", 0, "x"), 0.0, 10.0), Slot(("effect", 0, "y"), 0.0, 10.0)]
    model = Model([{"effect": "test", "where": "here", "x": 5.0, "y": 5.0}])
    evaluate = lambda models: [residual(m.effects[0]["x"], m.effects[0]["y"]) for m in models]  # noqa: E731
    J = np.column_stack([-1e4 * w1 + 39.3 * w2, 1e4 * w1])  # d r / d x, d r / d y
    r = residual(5.0, 5.0)
    assert slice_reach(evaluate, model, slots, 0, r, 4.99, 5.01) == pytest.approx((4.99, 5.01))
    assert slice_reach(evaluate, model, slots, 0, r, 4.99, 5.01, J) == pytest.approx((4.96, 5.04))


def test_a_ripple_with_a_negative_amplitude_is_reported_in_the_one_form():
    """effects.canonical / explain.canonical_form: a sin(2 pi q / P + phase) = (-a) sin(2 pi q / P + phase +- pi), so a
    fit may land on either; the report gives a >= 0 with the phase in (-pi, pi], intervals moved with them. Seed 47,
    watflex-db692a60: truth 0.5745 N m at -2.300 rad, found -0.5600 at 0.8635 (scored 84 % off; the same torque at
    every angle)."""
    from watflex_sim.diagnosis.explain import canonical_form
    from watflex_sim.effects import canonical

    found = {"effect": "position_dependent_friction", "where": "elbow", "amplitude": -0.56001, "period": 1.38019,
             "phase": 0.86349, "spring": -0.0349}
    same = canonical(found)
    assert same["amplitude"] == pytest.approx(0.56001) and same["phase"] == pytest.approx(0.86349 - math.pi)
    torque = lambda e, q: e["amplitude"] * math.sin(2 * math.pi * q / e["period"] + e["phase"]) + e["spring"] * q  # noqa: E731
    for q in np.linspace(-1.0, 1.0, 9):
        assert torque(same, q) == pytest.approx(torque(found, q), abs=1e-12)
    model, ranges = canonical_form(Model([found]), {0: {"amplitude": (-0.5654, -0.5546), "phase": (0.8446, 0.8824),
                                                     "spring": (-0.045, -0.025)}})
    assert model.effects[0] == same
    assert ranges[0]["amplitude"] == (0.5546, 0.5654) and ranges[0]["spring"] == (-0.045, -0.025)
    assert ranges[0]["phase"] == pytest.approx((0.8446 - math.pi, 0.8824 - math.pi))
    assert canonical({"effect": "position_dependent_friction", "amplitude": -0.08, "phase": -1.5})["phase"] == pytest.approx(-1.5 + math.pi)
    positive = dict(found, amplitude=0.3)
    assert canonical(positive) is positive
    quarter = dict(found, phase=-math.pi / 2)  # shifted to +pi/2 = -phase: moved by pi, not mirrored
    assert canonical_form(Model([quarter]), {0: {"phase": (-1.7, -1.5)}})[1][0]["phase"] == pytest.approx((-1.7 + math.pi, -1.5 + math.pi))


def test_a_ripple_phase_is_fitted_across_pi():
    """fitting.effect_slots_of / effects.canonical: a phase is an angle (effects.Param.cyclic), its slot a turn centred
    on its value, so a fit that wants to cross -pi is not held at a wall there, and the report wraps it back into
    (-pi, pi]. Seed 116, watflex-e9576ce5: an elbow ripple's phase (truth 2.654 rad) was held at -pi, the lower bound
    of [-pi, pi], and its amplitude and period took up the misfit (2.77 N m over 1.197 rad for 1.8 over 1.233)."""
    from watflex_sim.diagnosis.fitting import effect_slots_of, levenberg
    from watflex_sim.effects import canonical

    effect = {"effect": "position_dependent_friction", "where": "elbow", "phase": -3.0}
    slot, = effect_slots_of(None, Model([effect]))  # a phase has no scale: no data needed
    assert (slot.low, slot.high) == pytest.approx((-3.0 - math.pi, -3.0 + math.pi))
    x = np.linspace(0.0, 2 * math.pi, 200)
    evaluate = lambda models: [np.sin(x + m.effects[0]["phase"]) - np.sin(x + 2.654) for m in models]  # noqa: E731
    model, _, _ = levenberg(evaluate, Model([effect]), [slot], [-3.0], iters=20)
    assert model.effects[0]["phase"] < -math.pi  # past the old wall
    assert canonical(model.effects[0])["phase"] == pytest.approx(2.654, abs=1e-3)
    assert canonical({**effect, "amplitude": -0.5, "phase": 3.0})["phase"] == pytest.approx(3.0 - math.pi)


def _ripple_slots(motion: float) -> dict:
    """A position-dependent friction's slots for the ripple stand-ins below, the period's in a motion range `motion` (rad)
    as the catalogue scales it (0.2-200 ranges)."""
    return {"amplitude": Slot(("effect", -1, "amplitude"), -15.0, 15.0), "period": Slot(("effect", -1, "period"), 0.2 * motion, 200 * motion, log=True),
            "phase": Slot(("effect", -1, "phase"), -np.pi, np.pi), "spring": Slot(("effect", -1, "spring"), -50.0, 50.0)}


def test_a_ripples_period_is_found_by_a_scan_where_its_start_is_in_another_basin():
    """period_scans(): a ripple's residual is far from convex in its period (seed 52: a 0.77 rad Watflex elbow ripple
    fitted at 1.35 rad from the start at 3 x the motion's range, 5 x the noise left). On a stand-in whose residual is
    the ripple's torque along 0.54 rad of motion (exactly linear in a sin + b cos at a given period), the scan
    from the screening's start (period 1.63 rad, a spring absorbing part of the ripple) must land within the ladder's
    spacing of the true 0.77 rad (neighbouring periods drift at most half a cycle apart over the range; the rung
    nearest 0.77 is 0.761, 1 % off) with amplitude and phase near the truth, and cost a tenth of the start's."""
    from watflex_sim.diagnosis.scan import period_ladder, period_scans
    from watflex_sim.diagnosis.screening import Candidate

    motion, x = 0.544, np.linspace(0.0, 0.544, 600)  # rad

    def torque(e):
        return e["amplitude"] * np.sin(2 * np.pi * x / e["period"] + e["phase"]) + e["spring"] * x

    truth = {"amplitude": 0.85, "period": 0.77, "phase": -2.575, "spring": 0.0}

    def evaluate(models):
        return [torque(m.effects[-1]) - torque(truth) for m in models]

    slots = _ripple_slots(motion)
    cand = Candidate("position_dependent_friction", "elbow", {"amplitude": 1.5, "period": 3 * motion, "phase": 0.0, "spring": 0.0},
                     slots, {"amplitude": 0.0, "spring": 0.0})
    start = {"amplitude": -1.77, "period": 1.63, "phase": 0.0, "spring": 4.32}  # seed 52's screening estimate
    cost = lambda r: float(r @ r)  # noqa: E731
    none = np.zeros((x.size, 0))
    (found, found_cost), = period_scans(evaluate, cand, Model(), start, [(cost, (none, np.zeros(0), np.zeros(0), np.zeros(0)), start)])
    ladder = period_ladder(slots["period"], motion)
    assert min(ladder) == pytest.approx(0.2 * motion) and 4 * motion < max(ladder) <= 8 * motion
    drift = -np.diff(motion / np.array(ladder))  # cycles of phase over the range between neighbouring periods
    assert np.all(drift <= 0.5 + 1e-9)  # half a cycle: the truth is at most a quarter cycle from a rung
    assert abs(found["period"] / truth["period"] - 1) < 0.02
    assert abs(found["amplitude"] - truth["amplitude"]) < 0.1 * truth["amplitude"]
    assert abs(found["phase"] - truth["phase"]) < 0.2  # rad
    assert found_cost == pytest.approx(cost(evaluate([cand.model(Model(), found)])[0]))
    assert found_cost < 0.1 * cost(evaluate([cand.model(Model(), start)])[0])


def test_every_period_rung_is_carried_one_step_before_the_best_are_chosen():
    """scan_rungs(every=True), as period_scans runs it: every rung's first linear estimate is simulated and the rest
    taken by the three best first estimates and the three that cost least there. Stand-in for stick-slip (seed 75,
    watflex-6cc78dba: an elbow ripple of 0.56 N m at 1.231 rad, the rung at 1.05 rad not among the three best first
    estimates, fitted at 0.344 rad, 8 x the noise): the motion answers only the torque beyond a dead zone of 0.2 N m,
    r = dz(ripple) - dz(truth), the truth 0.6 N m at 0.761 rad (phase -2.575), probed at 0.5 N m. The probe's column is
    the ripple's tips only, and the three best first estimates end at 4.096 rad, cost 16.0; with every rung carried
    one step the scan lands on the rung at 0.762 rad, cost 0.24, and never costs more than from those three."""
    from watflex_sim.diagnosis import scan
    from watflex_sim.diagnosis.screening import Candidate

    motion, x = 0.544, np.linspace(0.0, 0.544, 600)  # rad

    def torque(e):
        return e["amplitude"] * np.sin(2 * np.pi * x / e["period"] + e["phase"]) + e["spring"] * x

    def dead_zone(t):
        return np.sign(t) * np.maximum(np.abs(t) - 0.2, 0.0)

    truth = {"amplitude": 0.6, "period": 0.761, "phase": -2.575, "spring": 0.0}

    def evaluate(models):
        return [dead_zone(torque(m.effects[-1])) - dead_zone(torque(truth)) for m in models]

    slots = _ripple_slots(motion)
    cand = Candidate("position_dependent_friction", "elbow", {"amplitude": 0.5, "period": 3 * motion, "phase": 0.0, "spring": 0.0},
                     slots, {"amplitude": 0.0, "spring": 0.0})
    cost = lambda r: float(r @ r)  # noqa: E731
    none = np.zeros((x.size, 0))
    start = dict(cand.start)
    ways = [(cost, (none, np.zeros(0), np.zeros(0), np.zeros(0)), start)]
    (found, found_cost), = scan.period_scans(evaluate, cand, Model(), start, ways)
    rungs = scan.scan_rungs
    with patch.object(scan, "scan_rungs", lambda *a, **k: rungs(*a, **{**k, "every": False, "ring": ()})):
        (three, three_cost), = scan.period_scans(evaluate, cand, Model(), start, ways)
    assert abs(three["period"] / truth["period"] - 1) > 0.5 and three_cost > 10.0
    assert abs(found["period"] / truth["period"] - 1) < 0.02 and found_cost < 0.5
    assert found_cost <= three_cost


def test_a_ripple_longer_than_the_motion_is_scanned_at_a_ring_of_phases():
    """period_scans(): at a rung of a cycle or less over the motion's range a ripple acts as a bias and a slope, and
    where the joint sticks the residual is far from linear in its a sin + b cos: the probes' linear estimate, carried
    on, is no guide (seed 93, watflex-3f8a52e2: an elbow ripple of 0.784 N m at 1.127 rad over 0.54 rad of motion, the
    rung at 1.056 rad estimated at 1.47 N m with a spring of -0.78 N m/rad and left at 8.4e6; scanned at 0.359 rad,
    3.8e6, fitted there, 12 x the noise left; the truth costs 1.7e5). Such rungs are also simulated at RING_PHASES
    phases at RING_SIZES of the start's amplitude, the least costly point a contender: there the scan lands at 1.056 rad,
    0.816 N m, -0.72 rad (3.8e5), and the fit at 0.7837 N m, 1.129 rad, -0.943 rad, `explained`. Stand-in: a response
    that grows as the cube of the ripple's torque (the further beyond what holds the joint, the more it moves), the
    truth 0.78 N m at 1.127 rad (phase -0.94) along 0.544 rad, probed at 1.375 N m as the screening starts it. Without
    the ring the scan lands at another period (0.762 rad); with it at the ladder's rung nearest the truth (1.066 rad:
    the rungs are 1.4 x apart there), the amplitude within 15 % and the phase within 0.15 rad, and costs less."""
    from watflex_sim.diagnosis import scan
    from watflex_sim.diagnosis.screening import Candidate

    motion, x = 0.544, np.linspace(0.0, 0.544, 600)  # rad

    def torque(e):
        return e["amplitude"] * np.sin(2 * np.pi * x / e["period"] + e["phase"]) + e["spring"] * x

    truth = {"amplitude": 0.78, "period": 1.127, "phase": -0.94, "spring": 0.0}

    def evaluate(models):
        return [torque(m.effects[-1]) ** 3 - torque(truth) ** 3 for m in models]

    cand = Candidate("position_dependent_friction", "elbow", {"amplitude": 1.375, "period": 3 * motion, "phase": 0.0, "spring": 0.0},
                     _ripple_slots(motion), {"amplitude": 0.0, "spring": 0.0})
    cost = lambda r: float(r @ r)  # noqa: E731
    none = np.zeros((x.size, 0))
    ways = [(cost, (none, np.zeros(0), np.zeros(0), np.zeros(0)), dict(cand.start))]
    (found, found_cost), = scan.period_scans(evaluate, cand, Model(), dict(cand.start), ways)
    rungs = scan.scan_rungs
    with patch.object(scan, "scan_rungs", lambda *a, **k: rungs(*a, **{**k, "ring": ()})):
        (linear, linear_cost), = scan.period_scans(evaluate, cand, Model(), dict(cand.start), ways)
    assert abs(linear["period"] / truth["period"] - 1) > 0.25
    assert abs(math.log(found["period"] / truth["period"])) < 0.5 * math.log(scan.PERIOD_LADDER)
    assert abs(found["amplitude"] / truth["amplitude"] - 1) < 0.15 and abs(found["phase"] - truth["phase"]) < 0.15
    assert found_cost < linear_cost


def test_a_ripples_period_is_scanned_beside_the_other_effects_the_shortlist_names():
    """scan.period_scans() with scan.beside(): a ripple's period scanned against a residual that another missing
    effect dominates lands where a wrong period mimics that effect (seed 68, watflex-db048a3c: an elbow ripple of
    1.35 N m at 0.82 rad beside a Coulomb friction of 0.86 / 0.99 N m was scanned and fitted at 0.116 rad). Stand-in:
    the ripple of the test above plus another effect whose residual is 1.0 x a square wave of 0.12 rad along the
    motion (a friction's sign at each reversal of a staircase). The scan alone takes the wrong period (within 10 % of
    0.12); the same scan with the other's signature column re-solved beside it, from the same rung simulations, must
    land within 2 % of the true 0.77 rad with the amplitude within 5 % and the phase within 0.1 rad, and leave a
    hundredth of the cost; with the other effect absent from the data both ways agree (the period to the digit, the
    amplitude within 1 %). Both are fitted from (effect_fit.fit_candidate): the fit that leaves less residual is kept."""
    from watflex_sim.diagnosis.fitting import refit_cost
    from watflex_sim.diagnosis.scan import beside, period_scans
    from watflex_sim.diagnosis.screening import Candidate

    motion, x = 0.544, np.linspace(0.0, 0.544, 600)  # rad
    square = np.sign(np.sin(2 * np.pi * x / 0.12))  # the other effect's residual per N m

    def torque(e):
        return e["amplitude"] * np.sin(2 * np.pi * x / e["period"] + e["phase"]) + e["spring"] * x

    truth = {"amplitude": 0.85, "period": 0.77, "phase": -2.575, "spring": 0.0}
    slots = _ripple_slots(motion)
    cand = Candidate("position_dependent_friction", "elbow", {"amplitude": 1.5, "period": 3 * motion, "phase": 0.0, "spring": 0.0},
                     slots, {"amplitude": 0.0, "spring": 0.0}, periodic="period")
    other = Candidate("coulomb_friction", "elbow", {"torque": 0.5}, {"torque": Slot(("effect", -1, "torque"), 0.0, 5.0)}, {"torque": 0.0})
    other.signature = {1.0: {"torque": square}}
    start = {"amplitude": -1.77, "period": 1.63, "phase": 0.0, "spring": 4.32}  # seed 52's screening estimate
    columns, at, low, high = beside(cand, [cand, other])
    assert columns.shape == (x.size, 1) and at.tolist() == [0.0] and low.tolist() == [0.0] and high.tolist() == [5.0]
    assert beside(cand, [cand]) is None
    none = np.zeros((x.size, 0))
    ways = [(lambda r: float(r @ r), (none, np.zeros(0), np.zeros(0), np.zeros(0)), start),
            (lambda r: refit_cost(columns, r, at, low, high), (columns, at, low, high), start)]

    def scans(size: float) -> list[tuple[dict, float]]:
        def evaluate(models):
            return [torque(m.effects[-1]) - torque(truth) - size * square for m in models]
        return period_scans(evaluate, cand, Model(), start, ways)

    (alone, _), (found, cost) = scans(1.0)
    assert abs(alone["period"] / 0.12 - 1) < 0.1
    assert abs(found["period"] / truth["period"] - 1) < 0.02
    assert abs(found["amplitude"] / truth["amplitude"] - 1) < 0.05 and abs(found["phase"] - truth["phase"]) < 0.1
    assert cost < 0.01 * float(square @ square)
    (alone, _), (found, _) = scans(0.0)
    assert found["period"] == pytest.approx(alone["period"]) and found["amplitude"] == pytest.approx(alone["amplitude"], rel=0.01)



def test_a_ripple_is_fitted_again_from_the_period_the_scan_beside_the_others_chose():
    """fit_candidate(): where the scan beside the shortlist's others (scan.period_scans' second way) lands on another
    period than the scan beside the rig alone, the candidate is fitted from both and the second fit is returned under
    'also', for the round to judge (seed 68, watflex-db048a3c: from the second way's 1.05 rad the fit left more |r|^2
    than the wrong 0.116 rad, 1.50e8 against 0.96e8, yet removed more of the training excess, 0.336 against 0.260, and
    led to the pair; by |r|^2 alone it was lost). Stand-in: the scans return a wrong period (first) and one 10 % off
    the truth (second); the first fit stays where it starts, the carry-on reaches the truth from within 20 % of its
    period. Returned: the wrong period's fit, and under 'also' the truth. Where both ways agree within half a ladder
    rung: no 'also'. Fails without the second way's fit."""
    from types import SimpleNamespace
    from watflex_sim.diagnosis import effect_fit
    from watflex_sim.diagnosis.screening import Candidate

    x = np.linspace(0.0, 0.544, 600)  # rad
    truth = {"amplitude": 0.85, "period": 0.77, "phase": -2.575, "spring": 0.0}

    def torque(e):
        return e["amplitude"] * np.sin(2 * np.pi * x / e["period"] + e["phase"]) + e["spring"] * x

    def evaluate(models):
        return [torque(m.effects[-1]) - torque(truth) for m in models]

    wrong = {"amplitude": 0.1, "period": 0.12, "phase": 0.0, "spring": 0.0}
    near = dict(truth, period=0.85, amplitude=-0.85)
    stays = lambda data, evaluate, base, cand, rig_columns, iters, values: {"effect": cand.effect, "where": cand.where,  # noqa: E731
                                                                             "model": cand.model(base, values), "cost": 0.0}

    def carried(evaluate, cand, first, iters):
        found = first["model"].effects[-1]
        moved = dict(truth) if abs(np.log(found["period"] / truth["period"])) < np.log(1.2) else found
        return {**first, "model": Model(first["model"].effects[:-1] + [dict(found, **moved)])}

    slots = {"amplitude": Slot(("effect", -1, "amplitude"), -15.0, 15.0), "period": Slot(("effect", -1, "period"), 0.1, 100.0, log=True),
             "phase": Slot(("effect", -1, "phase"), -np.pi, np.pi), "spring": Slot(("effect", -1, "spring"), -50.0, 50.0)}
    cand = Candidate("position_dependent_friction", "elbow", {"amplitude": 1.5, "period": 1.6, "phase": 0.0, "spring": 0.0},
                     slots, {"amplitude": 0.0, "spring": 0.0}, estimate=dict(wrong), periodic="period")
    data = SimpleNamespace(rig=SimpleNamespace(parameters={}), idle=set())
    for second, expected in ((near, truth), (dict(wrong, amplitude=0.2), None)):
        with patch.object(effect_fit, "period_scans", lambda evaluate, cand, base, values, ways: [(wrong, 1.0), (second, 2.0)]), \
                patch.object(effect_fit, "fit_from", stays), patch.object(effect_fit, "carry_on", carried):
            out = effect_fit.fit_candidate(data, evaluate, Model(), cand, np.zeros((x.size, 0)), 6)
        assert out["model"].effects[-1]["period"] == wrong["period"]
        if expected is None:
            assert "also" not in out
        else:
            assert [a["model"].effects[-1]["period"] for a in out["also"]] == [truth["period"]]
            assert out["also"][0]["model"].effects[-1]["amplitude"] == truth["amplitude"]
            assert out["also"][0]["start"] == effect_fit.BESIDE_START  # the report tells the two fits apart


DWELL_TRUTH = {"gain": 0.53, "time_constant": 0.67}  # a dwell-time stiction like seed 63's watflex-bddd453b (0.527, 0.666 s)
DWELL_RESTS = np.geomspace(0.02, 8.0, 200)  # s


def _dwell_rise(models):
    """Stand-in residual of a dwell-time stiction: its break-away's rise gain (1 - exp(-t / tau)) over DWELL_RESTS,
    the model's against DWELL_TRUTH's."""
    def rise(e):
        return e["gain"] * (1 - np.exp(-DWELL_RESTS / e["time_constant"]))
    return [rise(m.effects[-1]) - rise(DWELL_TRUTH) for m in models]


def _dwell_slots():
    return {"gain": Slot(("effect", -1, "gain"), 0.0, 3.0), "time_constant": Slot(("effect", -1, "time_constant"), 0.05, 30.0, log=True)}


def test_a_time_constant_is_found_by_a_scan_where_its_start_is_in_another_basin():
    """scan_shape(): a dwell-time stiction's time constant (seeds 54, 55, 62, 63: 0.6-0.7 s fitted at 1.5-2 s from the
    catalogue's 2 s start, the gain twice the truth) is scanned over shape_ladder with the gain re-solved at each rung.
    Stand-in: the break-away's rise over 200 rests of 0.02-8 s, gain (1 - exp(-t / tau)), with the truth's 0.53 at
    0.67 s; from the screening's estimate at the start (gain 1.2, tau 2 s) the scan must land on a rung within
    SHAPE_LADDER^0.5 of the truth (the rungs are SHAPE_LADDER apart), its gain within 25 % of the truth's, and
    cost less than a tenth of the start's. Fails where only a ripple's period was scanned (cost None, values kept).
    same_rung: the fit is started again from the rung only where it is another rung than the start's."""
    from watflex_sim.diagnosis.scan import SHAPE_LADDER, same_rung, scan_shape, shape_ladder
    from watflex_sim.diagnosis.screening import Candidate

    rest, truth, evaluate = DWELL_RESTS, DWELL_TRUTH, _dwell_rise
    slots = _dwell_slots()
    cand = Candidate("dwell_time_stiction", "elbow", {"gain": 0.5, "time_constant": 2.0}, slots, {"gain": 0.0})
    start = {"gain": 1.2, "time_constant": 2.0}
    cost = lambda r: float(r @ r)  # noqa: E731
    (found, found_cost), *others = scan_shape(evaluate, cand, Model(), start, cost, np.zeros((rest.size, 0)), np.zeros(0), np.zeros(0), np.zeros(0))
    assert len(others) == 2 and all(found_cost <= c for _, c in others)  # PERIOD_CHECKED contenders, least first
    ladder = shape_ladder(slots["time_constant"])
    assert min(ladder) > 0.05 and max(ladder) < 30.0 and np.allclose(np.diff(np.log(ladder)), np.log(SHAPE_LADDER))
    assert found_cost is not None and found_cost < 0.1 * cost(evaluate([cand.model(Model(), start)])[0])
    assert abs(np.log(found["time_constant"] / truth["time_constant"])) <= 0.5 * np.log(SHAPE_LADDER) + 1e-9
    assert abs(found["gain"] / truth["gain"] - 1) < 0.25
    assert found_cost == pytest.approx(cost(evaluate([cand.model(Model(), found)])[0]))
    # a second fit only from another rung: within half a rung (x1.41) the fit would start where the first does
    assert same_rung(cand, {"time_constant": 2.0}, {"time_constant": 2.8}) and not same_rung(cand, start, found)


def test_a_shape_scan_steps_with_the_slope_at_its_estimate_where_the_residual_bends_in_the_size():
    """scan_rungs(local=True): a shape scan's Gauss-Newton steps take the size parameter's slope at each contender
    (LOCAL_STEP), not the probe's secant from neutral (seed 59: a dwell's gain re-solved to ~0.5, its probe level, at
    every rung, and the scan picked the time constant that suits that gain). Stand-in: _dwell_rise's rise bent by
    stick-slip-like saturation, tanh(gain (1 - exp(-t / tau))), truth gain 2.5 at 0.67 s; the secant from 0 to the
    0.5 probe is 2.2 x the slope at 2.5. The scan must land within half a rung of 0.67 s with the gain within 15 % (the
    rung's 0.57 s takes a gain ~10 % lower) and leave less than 5 % of the cost it leaves with the secant's steps
    (old code: rung 0.28 s, gain 1.39, cost 0.99; now 0.57 s, 2.21, 0.014)."""
    from watflex_sim.diagnosis import scan
    from watflex_sim.diagnosis.screening import Candidate

    truth = {"gain": 2.5, "time_constant": 0.67}

    def bent(models):
        def rise(e):
            return np.tanh(e["gain"] * (1 - np.exp(-DWELL_RESTS / e["time_constant"])))
        return [rise(m.effects[-1]) - rise(truth) for m in models]

    def cost(r):
        return float(r @ r)

    cand = Candidate("dwell_time_stiction", "elbow", {"gain": 0.5, "time_constant": 2.0}, _dwell_slots(), {"gain": 0.0})
    start, no_rig = {"gain": 1.2, "time_constant": 2.0}, (np.zeros((DWELL_RESTS.size, 0)), np.zeros(0), np.zeros(0), np.zeros(0))
    (found, found_cost), *_ = scan.scan_shape(bent, cand, Model(), start, cost, *no_rig)
    assert abs(np.log(found["time_constant"] / truth["time_constant"])) <= 0.5 * np.log(scan.SHAPE_LADDER) + 1e-9
    assert abs(found["gain"] / truth["gain"] - 1) < 0.15

    local_rungs = scan.scan_rungs

    def secant_only(*args, **kwargs):
        return local_rungs(*args, **{**kwargs, "local": False})
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(scan, "scan_rungs", secant_only)
        (_, secant_cost), *_ = scan.scan_shape(bent, cand, Model(), start, cost, *no_rig)
    assert found_cost < 0.05 * secant_cost


def test_an_effect_with_a_shape_parameter_is_fitted_from_its_scan_and_from_its_start_and_the_better_kept():
    """fit_candidate(): a dwell-time stiction is fitted from the screening's values and from scan_shape's best rung,
    and the fit whose residual is the least is kept. On the real cost the two ends of the valley are not joined
    by Levenberg-Marquardt's steps (seed 63, watflex-bddd453b: from the 2 s start 1.22 at 1.91 s, from the rung
    0.47 at 0.62 s, a fifth of the residual, truth 0.53 at 0.67 s); here the fit is a stand-in that stays where it
    starts (the worst case of a rough valley), on the stand-in residual of the scan's test. Kept: the rung's fit
    (time constant within half a rung of the truth) from the 2 s start; the start's own fit where the start fits
    better than every rung. Fails where only the start was fitted."""
    from types import SimpleNamespace
    from watflex_sim.diagnosis import effect_fit
    from watflex_sim.diagnosis.scan import SHAPE_LADDER
    from watflex_sim.diagnosis.screening import Candidate

    rest, truth, evaluate = DWELL_RESTS, DWELL_TRUTH, _dwell_rise
    def stays(data, evaluate, base, cand, rig_columns, iters, values):
        return {"effect": cand.effect, "where": cand.where, "model": cand.model(base, values), "cost": 0.0}

    slots = _dwell_slots()
    data = SimpleNamespace(rig=SimpleNamespace(parameters={}), idle=set())
    for start, expected in (({"gain": 1.2, "time_constant": 2.0}, "rung"), (dict(truth), "start")):
        cand = Candidate("dwell_time_stiction", "elbow", {"gain": 0.5, "time_constant": 2.0}, slots, {"gain": 0.0},
                         estimate=start)
        with patch.object(effect_fit, "fit_from", stays), patch.object(effect_fit, "carry_on", lambda evaluate, cand, first, iters: first):
            found = effect_fit.fit_candidate(data, evaluate, Model(), cand, np.zeros((rest.size, 0)), 6)["model"].effects[-1]
        if expected == "rung":
            assert abs(np.log(found["time_constant"] / truth["time_constant"])) <= 0.5 * np.log(SHAPE_LADDER) + 1e-9
            assert abs(found["gain"] / truth["gain"] - 1) < 0.25
        else:
            assert found["time_constant"] == truth["time_constant"] and found["gain"] == truth["gain"]


def test_a_shape_candidate_is_fitted_from_every_contender_of_its_scan_not_only_the_cheapest():
    """fit_candidate(): the fit starts from each of scan_shape's contenders that is not within half a rung of a start
    already taken (same_rung), and the least residual after the fit is kept, whichever contender scanned cheapest: at
    the scan's stage the rig is re-solved to first order only (seed 59's pair watflex-26f64029: its contenders 2.26 s
    at cost 8,454, 4.53 s at 8,611, 1.13 s with gain 0.336 at 9,012, truth 0.32 at 0.80 s; the cheapest is the start's own
    rung, so nothing else was fitted and 2.0 s was found). Stand-in: the scan returns those three (the cheapest first),
    the fit stays where it starts, the residual is _dwell_rise's against a truth of 0.32 at 0.80 s. Fitted: the start
    and the 4.53 s and 1.13 s contenders (2.26 s is the start's rung); kept: 1.13 s. Fails where only the cheapest
    contender was a start."""
    from types import SimpleNamespace
    from watflex_sim.diagnosis import effect_fit
    from watflex_sim.diagnosis.screening import Candidate

    truth = {"gain": 0.32, "time_constant": 0.80}

    def evaluate(models):
        def rise(e):
            return e["gain"] * (1 - np.exp(-DWELL_RESTS / e["time_constant"]))
        return [rise(m.effects[-1]) - rise(truth) for m in models]

    contenders = [({"gain": 0.534, "time_constant": 2.263}, 8453.7), ({"gain": 0.627, "time_constant": 4.525}, 8610.7),
                  ({"gain": 0.336, "time_constant": 1.131}, 9011.9)]
    starts = []

    def stays(data, evaluate, base, cand, rig_columns, iters, values):
        starts.append(values["time_constant"])
        return {"effect": cand.effect, "where": cand.where, "model": cand.model(base, values), "cost": 0.0}

    start = {"gain": 0.505, "time_constant": 2.0}
    cand = Candidate("dwell_time_stiction", "elbow", {"gain": 0.5, "time_constant": 2.0}, _dwell_slots(), {"gain": 0.0},
                     estimate=start)
    data = SimpleNamespace(rig=SimpleNamespace(parameters={}), idle=set())
    with (patch.object(effect_fit, "fit_from", stays), patch.object(effect_fit, "scan_shape", lambda *args: contenders),
          patch.object(effect_fit, "carry_on", lambda evaluate, cand, first, iters: first),
          patch.object(effect_fit, "shape_profile", lambda *args: None)):
        found = effect_fit.fit_candidate(data, evaluate, Model(), cand, np.zeros((DWELL_RESTS.size, 0)), 6)["model"].effects[-1]
    assert starts == [2.0, 4.525, 1.131]
    assert found["time_constant"] == 1.131 and found["gain"] == 0.336


def test_a_fitted_shape_is_profiled_along_the_valley_its_sizes_make():
    """scan.shape_profile() and fit_candidate(): a Stribeck friction whose data sample it in a narrow speed band is
    pinned there only (break-away x exp(-(v / v_s)^2) at those speeds): a faster decay is made up by a larger
    break-away, a valley diagonal in (v_s, break-away) that Levenberg-Marquardt did not walk (seed 107's
    watflex-f535260d: 1.088 N m at v_s 0.0103 rad/s fitted at 1.61 N m with v_s 0.00899, the 0.009 it started from;
    |r|^2 2.3e5 against the truth's 3.7e4). Stand-in: the excess at speeds 0.009-0.014 rad/s, the fit standing at 0.009
    rad/s with the break-away that fits best there (1.508 N m; a static stand-in's valley is wider than stick-slip's).
    The profile (v_s x 2^(+-1/4, +-1/2), the break-aways x 0.35-2) finds v_s 0.0107 with a break-away within 10 % of
    the truth and half the fit's residual at most; fit_candidate starts a fit there and keeps it (the fit a stand-in
    that stays where it starts). Fails without the profile."""
    from types import SimpleNamespace
    from watflex_sim.diagnosis import effect_fit
    from watflex_sim.diagnosis.scan import shape_profile
    from watflex_sim.diagnosis.screening import Candidate

    speeds = np.linspace(0.009, 0.014, 50)  # rad/s
    truth = {"breakaway_positive": 0.0, "breakaway_negative": 1.088, "v_s": 0.0103}

    def evaluate(models):
        def excess(e):
            return e["breakaway_negative"] * np.exp(-(speeds / e["v_s"]) ** 2)
        return [(excess(m.effects[-1]) - excess(truth)) / 0.01 for m in models]

    slots = {n: Slot(("effect", -1, n), 0.0, 5.0) for n in ("breakaway_positive", "breakaway_negative")}
    slots["v_s"] = Slot(("effect", -1, "v_s"), 0.001, 1.0, log=True)
    start = {"breakaway_positive": 0.0, "breakaway_negative": 1.508, "v_s": 0.009}
    neutral = {"breakaway_positive": 0.0, "breakaway_negative": 0.0}
    cand = Candidate("stribeck_friction", "shoulder", start, slots, neutral, estimate=start)
    fitted = cand.model(Model(), start)
    (r_fit,) = evaluate([fitted])
    found = shape_profile(evaluate, cand, fitted)
    (r_found,) = evaluate([cand.model(Model(), found)])
    assert found["v_s"] == pytest.approx(0.009 * 2 ** 0.25)
    assert abs(found["breakaway_negative"] / truth["breakaway_negative"] - 1) < 0.10
    assert r_found @ r_found < r_fit @ r_fit / 2

    def stays(data, evaluate, base, cand, rig_columns, iters, values):
        return {"effect": cand.effect, "where": cand.where, "model": cand.model(base, values), "cost": 0.0}

    data = SimpleNamespace(rig=SimpleNamespace(parameters={}), idle=set())
    with (patch.object(effect_fit, "fit_from", stays), patch.object(effect_fit, "scan_shape", lambda *args: []),
          patch.object(effect_fit, "carry_on", lambda evaluate, cand, first, iters: first)):
        kept = effect_fit.fit_candidate(data, evaluate, Model(), cand, np.zeros((speeds.size, 0)), 6)["model"]
    kept = kept.effects[-1]
    assert kept["v_s"] == found["v_s"] and kept["breakaway_negative"] == found["breakaway_negative"]


def test_a_difference_over_a_cliff_is_taken_from_the_gentler_side():
    """reach.gentler_side(): a one-sided difference that steps over a cliff of the cost (seed 54: a Watflex
    dwell-time stiction whose gain +0.15 left the elbow stuck, |dr| 2.3e5 noise units against 390 for -0.15; its 95 %
    interval was +-0.002 around 1.53, the truth 0.60) is replaced by the other side's. Stand-in: the residual, 1,000
    white elements of unit sd, grows as 3 (g - 1.5) below g = 1.6 and jumps by 100 per element above it (and
    with a second parameter k along a ramp). Forward
    (the Jacobian's step, 0.05 x the 0-3 span = 0.15) the column is ~100 / 0.15 per element and the interval from
    `fitting.intervals` +-0.0002; from the gentler side the column is 3 per element, the interval at least 1.96 x 1 /
    (3 sqrt 1000) = +-0.021 and at most 1.6 x that (0.029: `intervals` also reaches the Gauss-Newton step to this
    noise's own least-squares minimum). A parameter whose residual has no cliff keeps its forward column."""
    from watflex_sim.diagnosis.fitting import Slot, intervals, jacobian
    from watflex_sim.diagnosis.reach import gentler_side

    noise = np.random.default_rng(1).standard_normal(1000)
    noise *= np.sqrt(1000) / np.linalg.norm(noise)
    ramp = np.linspace(-1.0, 1.0, 1000)  # k's column: orthogonal to the gain's

    def residual(g, k):
        return noise + 3.0 * (g - 1.5) + (100.0 if g > 1.6 else 0.0) + 2.0 * (k - 1.0) * ramp
    slots = [Slot(("effect", 0, "gain"), 0.0, 3.0), Slot(("effect", 0, "k"), 0.0, 3.0)]
    model = Model([{"effect": "test", "where": "here", "gain": 1.5, "k": 1.0}])
    evaluate = lambda models: [residual(m.effects[0]["gain"], m.effects[0]["k"]) for m in models]  # noqa: E731
    u, r = np.array([1.5, 1.0]), residual(1.5, 1.0)
    forward = jacobian(evaluate, model, slots, u, r)
    gentle = gentler_side(evaluate, model, slots, u, r, forward, 2)
    assert np.linalg.norm(forward[:, 0]) > 100 * np.linalg.norm(gentle[:, 0])
    assert np.allclose(gentle[:, 0], 3.0) and np.array_equal(gentle[:, 1], forward[:, 1])
    narrow, wide = intervals(slots, model, forward, r)[0], intervals(slots, model, gentle, r)[0]
    assert narrow[1] - narrow[0] < 0.001
    white = 1.96 / (3 * np.sqrt(1000))  # the white-noise half-width from the gentle column
    assert white <= (wide[1] - wide[0]) / 2 <= 1.6 * white
    # a parameter fitted a hair above its lower bound (seed 77's one-way shoulder Coulomb friction, the other side at
    # 8e-17 N m): the step back to the bound changes nothing, and is no side at all; the forward column stays
    # (k's residual now 2 k along the ramp: its least squares at the bound, 1.96 sd = 0.054)
    at_bound = Model([{"effect": "test", "where": "here", "gain": 1.5, "k": 8e-17}])
    near = lambda models: [residual(m.effects[0]["gain"], 1.0 + m.effects[0]["k"]) for m in models]  # noqa: E731
    u0, r0 = np.array([1.5, 8e-17]), near([at_bound])[0]
    forward0 = jacobian(near, at_bound, slots, u0, r0)
    kept = gentler_side(near, at_bound, slots, u0, r0, forward0, 2)
    assert np.array_equal(kept[:, 1], forward0[:, 1])
    assert intervals(slots, at_bound, kept, r0)[1][1] < 0.1  # not its whole bounds (3)


def test_the_screening_refits_the_findings_so_far_beside_the_rigs_parameters(laser_recordings):
    """screening.with_findings: in a later round each parameter of the effects found so far gets a Jacobian column
    (per unit of its value; a log-scaled one's from a log step, divided by its value) on a linear slot, so `screen`
    refits them to first order as the candidate fits will. The residual here is what a second effect leaves once a
    first one (an actuator gain) has taken up part of it: the second's signature s = g + e (g: the gain's column),
    r0 = -(s - g) = -e. Held at its value, the gain lets s explain only |e|^2 / (|g|^2 + |e|^2) = 8 % of r0 (seed 55:
    a current limit behind a gain screened at -2.6 %); refit beside it, s explains all of it (linear algebra: r0
    lies in the span of g and s), at its true size 1.0, the gain moving by -1.0 within its bounds (0.1-5). Columns by a linear stand-in for the simulation (exact for a
    linear slot; a log step of 0.1 gives (e^0.1 - 1) / 0.1 = 1.052 x the slope)."""
    from watflex_sim.diagnosis import Candidate, screen
    from watflex_sim.diagnosis.fitting import effect_slots_of
    from watflex_sim.diagnosis.screening import with_findings

    data = prepare(laser_recordings, ["a", "b"])
    model = Model([dict(effect="actuator_gain", where="voltage_cmd", ratio=1.8),
                   dict(effect="dwell_time_stiction", where="hub", gain=0.5, time_constant=2.0)])
    slots = effect_slots_of(data, model)
    assert [(s.name, s.log) for s in slots] == [("ratio", False), ("gain", False), ("time_constant", True)]
    rng = np.random.default_rng(3)
    n = 600
    g, d1, d2 = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)  # per unit of ratio, gain, time constant
    e = 0.3 * rng.normal(size=n)
    r0 = -e

    def evaluate(models):
        return [r0 + (m.effects[0]["ratio"] - 1.8) * g + (m.effects[1]["gain"] - 0.5) * d1
                + (m.effects[1]["time_constant"] - 2.0) * d2 for m in models]

    rig = rng.normal(size=(n, 1)) * 1e-3
    free, at = [Slot(("param", "p"), 0.95, 1.05)], np.array([1.0])
    columns, linear, values = with_findings(evaluate, data, model, r0, rig, free, at)
    assert columns.shape == (n, 4) and [s.log for s in linear] == [False] * 4
    assert np.allclose(columns[:, 1], g) and np.allclose(columns[:, 2], d1)
    assert np.allclose(columns[:, 3], d2 * math.expm1(0.1) / 0.1)
    assert list(values) == [1.0, 1.8, 0.5, 2.0]

    def candidate():
        return Candidate("current_saturation", "voltage_cmd", {"k": 0.5}, {"k": Slot(("effect", -1, "k"), 0.0, 3.0)},
                         {"k": 0.0}, signature={1.0: {"k": g + e}})
    held, refit = candidate(), candidate()
    screen([held], rig, free, at, r0)
    screen([refit], columns, linear, values, r0)
    assert held.gain < 0.1
    assert refit.gain > 0.99 and refit.estimate["k"] == pytest.approx(1.0, rel=0.01)
    assert with_findings(evaluate, data, Model(), r0, rig, free, at)[0] is rig  # nothing found: the rig's alone


def test_the_candidate_fits_simulations_go_together_call_by_call():
    """runner.Gathered: three threads (the candidate fits) with 3, 1 and 2 calls of different sizes share one
    evaluator. Each call waits for the other live threads' calls; the k-th calls go together in thread order (a
    thread that has ended no longer holds the others up), each thread gets back its own answers, and an error of
    the shared evaluator is raised in every thread that was waiting on it."""
    import threading

    from watflex_sim.diagnosis.runner import Gathered

    batches = []

    def evaluate(models):
        batches.append(list(models))
        if "boom" in models:
            raise RuntimeError("worker failed")
        return [m * 10 for m in models]

    calls = {0: [[1, 2], [3], [4, 5, 6]], 1: [[7]], 2: [[8], [9, 10]]}
    gathered = Gathered(evaluate, len(calls))
    got = {}

    def work(k):
        try:
            got[k] = [gathered.caller(k)(models) for models in calls[k]]
        finally:
            gathered.leave()

    threads = [threading.Thread(target=work, args=(k,)) for k in calls]
    for t in threads[::-1]:  # started in reverse: the order of the batches must not depend on it
        t.start()
    for t in threads:
        t.join(5)
    assert got == {k: [[m * 10 for m in models] for models in calls[k]] for k in calls}
    assert batches == [[1, 2, 7, 8], [3, 9, 10], [4, 5, 6]]

    gathered, errors = Gathered(evaluate, 2), []

    def failing(k):
        try:
            gathered.caller(k)(["boom"] if k == 0 else [1])
        except RuntimeError as exc:
            errors.append((k, str(exc)))
        finally:
            gathered.leave()

    threads = [threading.Thread(target=failing, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(5)
    assert sorted(errors) == [(0, "worker failed"), (1, "worker failed")]


def test_a_model_simulated_a_moment_ago_is_not_simulated_again(laser_recordings):
    """runner.evaluator: a residual asked for again (the same model, part, unit and fidelity) comes from the runner's
    memo (Runner.remember) without a simulation job, equal to the first to the bit and a copy of it; a model asked
    twice in one call is simulated once; the noise units follow this process' noise as it changes (calibrate_noise);
    past the memo's limit of others the first is simulated again."""
    from watflex_sim.diagnosis.runner import Runner, evaluator

    data = prepare(laser_recordings, ["pos", "neg"])
    payload = Model([{"effect": "payload", "where": "tip", "mass": 0.1}])
    with Runner(data, 1) as runner:
        evaluate = evaluator(runner)
        first = evaluate([payload])[0]
        jobs = runner.jobs
        again, twice = evaluate([Model([dict(payload.effects[0])]), payload])
        assert runner.jobs == jobs and np.array_equal(again, first) and np.array_equal(twice, first) and again is not first
        again[:] = 0.0  # the caller's to change
        assert np.array_equal(evaluate([payload])[0], first)
        evaluate([Model(), Model()])
        assert runner.jobs == jobs + len(laser_recordings)  # one model, once
        in_noise = evaluator(runner, unit="noise")
        before = in_noise([payload])[0]
        runner.data.noise[:] = [{c: 2 * v for c, v in n.items()} for n in data.noise]
        assert np.allclose(in_noise([payload])[0], before / 2)
        runner.memo.limit = 8 * first.nbytes  # eight residuals, where MEMO_BYTES keeps hundreds
        evaluate([Model(parameters={"beam_EI": 1 + k * 1e-4}) for k in range(8)])
        jobs = runner.jobs
        evaluate([payload])
        assert runner.jobs == jobs + len(laser_recordings)


def test_motion_is_the_reference_where_no_measured_joint_moves():
    """motion_channel(): seed 59's watflex-1e32daae (single-link set-up, shoulder locked, the elbow encoder
    left out: seen through the strains only) had every residual window labelled "near zero velocity
    (shoulder_angle at rest)", read off the locked shoulder's encoder. With no measured position moving a
    tenth as far as a reference, the moving reference is the motion: a 0.5 rad elbow step at 1 s moves
    "positive" during its rise, and rests after it. With the elbow encoder there, the encoder is."""
    from watflex_sim.diagnosis.motion import motion_channel
    from watflex_sim.diagnosis.locate import regimes
    from watflex_sim.recording import Recording
    from watflex_sim.rigdesc import load_rig

    rig = load_rig("watflex")
    t = np.arange(0.0, 3.0, 0.001)
    step = 0.5 * np.clip((t - 1.0) / 0.2, 0.0, 1.0)  # rad, a 0.2 s ramp from 1 s
    channels = {"shoulder_reference": 0 * t, "elbow_reference": step, "shoulder_angle": 1e-6 * np.sin(t)}
    rec = Recording(t, channels, {})
    assert motion_channel(rec, rig) == "elbow_reference"
    assert regimes(rec, rig, 1050, 1150).startswith("positive motion")
    assert regimes(rec, rig, 2000, 2100).startswith("near zero velocity (elbow_reference at rest)")
    assert motion_channel(Recording(t, {**channels, "elbow_angle": 0.98 * step}, {}), rig) == "elbow_angle"


def test_where_the_moving_joints_encoder_is_not_recorded_its_motion_is_simulated():
    """motion.motions: with the elbow encoder left out the motion is the stepped elbow reference, whose robust peak
    rate is ~0 (seed 73's watflex-349124fc: an elbow viscous friction sized by scale_of's "effort/speed" at
    +-1e15 N m s/rad, never screened; every window "at rest"). The elbow as the nominal model moves it is used
    instead, and it is what the encoder records: the same noise-free recording with and without the encoder gives
    the same viscous scale (to 1e-9: one simulation; ~1 rad/s for a 0.5 rad step) and the same regime words
    around the elbow's fastest sample."""
    from watflex_sim.diagnosis import scale_of
    from watflex_sim.diagnosis.motion import motion_channel, motions, peak, peak_speed
    from watflex_sim.diagnosis.locate import regimes
    from watflex_sim.effects import CATALOGUE
    from watflex_sim.recording import Recording
    from watflex_sim.rigdesc import load_rig

    seen = simulate(load_scenario("watflex_elbow_step", ["duration_s=1.5"])).recording
    blind = Recording(seen.time, {c: v for c, v in seen.channels.items() if c != "elbow_angle"}, seen.meta)
    rig = load_rig("watflex")
    assert motion_channel(blind, rig) == "elbow_reference"
    assert peak(np.gradient(blind.channels["elbow_reference"], blind.time)) < 1e-9  # rad/s: a step's robust rate
    viscous = CATALOGUE["viscous_friction"][1][0]
    with_encoder, without = prepare([seen], ["seen"]), prepare([blind], ["blind"])
    assert scale_of(without, viscous, "elbow") == pytest.approx(scale_of(with_encoder, viscous, "elbow"), rel=1e-9)
    assert 0.5 < peak_speed(without) < 2.0  # rad/s
    fastest = int(np.argmax(np.abs(np.gradient(seen.channels["elbow_angle"]))))
    window = fastest - 25, fastest + 25
    assert regimes(blind, rig, *window, motions(without)[0]) == regimes(seen, rig, *window) == "positive motion"
    assert regimes(blind, rig, *window).startswith("near zero velocity")  # the reference alone


def _local_case(misfit: float, discretisation: float = 0.0, seed: int = 7):
    """A 6 s strain channel at 1 kHz, white sensor noise 0.01 V (its whole-recording noise), measured = the model + a
    bump of `misfit` x the noise over 0.1 s at 2 s (a misfit at one transient), the model's discretisation changing
    it by `discretisation` x the noise over the same 0.1 s (floors.calibrate_noise's per-sample record)."""
    from watflex_sim.diagnosis.data import Data
    from watflex_sim.recording import Recording
    from watflex_sim.rigdesc import load_rig

    t = np.arange(0.0, 6.0, 1e-3)  # s
    noise = 0.01  # V
    model = 0.5 * np.sin(2 * np.pi * 0.5 * t)  # V
    bump = np.where(np.abs(t - 2.05) < 0.05, 1.0, 0.0)
    measured = model + misfit * noise * bump + noise * np.random.default_rng(seed).normal(size=t.size)
    data = Data([Recording(t, {"strain_2A": measured}, {})], ["step.csv"], load_rig("watflex"), [["strain_2A"]],
                [{"strain_2A": float(np.std(measured))}], [{"strain_2A": noise}], [split_blocks(t)[0]],
                sensor_noise=[{"strain_2A": noise}], discretisation_sq=[{"strain_2A": (discretisation * noise * bump) ** 2}])
    return data, [Recording(t, {"strain_2A": model}, {})], [Recording(t, {"strain_2A": model + misfit * noise * bump}, {})]


def test_a_misfit_at_one_transient_is_not_within_the_noise():
    """locate.local_excess (seed 61's watflex-a0129499, a dwell-time stiction: 0.92 x the noise on the whole, called
    `nothing_missing`, while the step after the dwell leaves 0.1 s windows 5.6-6.3 x above what noise and
    discretisation leave there). In miniature: a bump of 6 x the noise for 0.1 s in 6 s is 1.04 x on the whole
    (sqrt(1 + 36 x 0.1 / 6)), within NOISE_MARGIN, but one window of 0.1 s stands ~6 x above its local null
    (sqrt(1 + 36)); the verdict without findings is then `unexplained`, not `nothing_missing`. White noise alone
    leaves no window above LOCAL_MARGIN (100-sample windows: chance ~1.4 x at most), nor does a bump of 9 x the noise
    where the model's own discretisation changes it by 2 x: counted DISCRETISATION_COUNT = 2 times, the local null is
    1 + (2 x 2)^2 = 17 noise variances, the window sqrt(82 / 17) = 2.2 x (counted once: sqrt(82 / 5) = 4.05 x, flagged)."""
    from watflex_sim.diagnosis.scores import fit_scores
    from watflex_sim.diagnosis.locate import LOCAL_MARGIN, local_excess, local_gain, local_ratio
    from watflex_sim.diagnosis.validate import within
    from watflex_sim.diagnosis.verdict import verdict_of

    data, sims, exact = _local_case(6.0)
    whole = fit_scores(data, sims, "all")
    assert whole["noise_ratio"] == pytest.approx(math.sqrt(1 + 36 * 0.1 / 6), abs=0.03)
    assert within(whole)  # on the whole (which half holds the bump is the split's choice)
    windows = local_excess(data, sims)
    assert len(windows) == 1 and windows[0]["channel"] == "strain_2A"
    assert windows[0]["ratio"] == pytest.approx(math.sqrt(37), rel=0.1) and 1.95 <= windows[0]["t_start"] <= 2.05
    assert windows[0]["t_end"] - windows[0]["t_start"] == pytest.approx(0.1, abs=2e-3)
    assert verdict_of(Model(), whole, whole, 0.0, [], windows) == "unexplained"
    assert verdict_of(Model(), whole, whole, 0.0, [], []) == "nothing_missing"
    # a model with the bump in removes the windows' excess: local ratio ~1, gain ~1
    assert local_ratio(data, exact, windows) == pytest.approx(1.0, abs=0.15)
    assert local_gain(data, windows, sims, exact) == pytest.approx(1.0, abs=0.05)
    assert max(local_excess(data, exact) or [{"ratio": 0.0}], key=lambda w: w["ratio"])["ratio"] < LOCAL_MARGIN
    assert local_excess(*_local_case(9.0, discretisation=2.0)[:2]) == []
    with patch("watflex_sim.diagnosis.locate.DISCRETISATION_COUNT", 1.0):
        assert len(local_excess(*_local_case(9.0, discretisation=2.0)[:2])) == 1
    assert local_excess(*_local_case(0.0)[:2]) == []


def test_a_verdict_reached_at_the_effect_limit_does_not_claim_the_catalogue_was_searched():
    """verdict.verdict_reason: where the search stopped at max_effects (`limit`) the reason says so instead of "no
    further catalogue effect earns its place", which only a round that fitted the candidates and kept none can say
    (EMPS both runs at --max-effects 1: `unexplained` at 29.8 x the noise after one finding, its reason claimed the
    catalogue had been tried). Scores in noise units, as fit_scores gives them."""
    from watflex_sim.diagnosis.verdict import verdict_reason

    far = {"noise_ratio": 25.8, "worst_ratio": 36.3, "worst_channel": "vir"}
    refit = {"noise_ratio": 47.8, "worst_ratio": 77.9, "worst_channel": "vir"}
    searched = verdict_reason("unexplained", far, far, refit, refit, 0.4, [])
    stopped = verdict_reason("unexplained", far, far, refit, refit, 0.4, [], limit=1)
    assert "no further catalogue effect earns its place" in searched and "--max-effects" not in searched
    assert "limit of 1 finding (--max-effects)" in stopped and "no further catalogue effect" not in stopped
    explained = verdict_reason("explained", far, far, refit, refit, 0.85, [], limit=2)
    assert "85 %" in explained and "limit of 2 findings" in explained and "no further catalogue effect" not in explained
    # elimination dropped one of the two (an independent simulator's hidden 2 kg payload: round 1's joint compliance
    # swapped for a sensor gain, then dropped as vague): the reason says how many were kept
    one_kept = verdict_reason("explained", far, far, refit, refit, 0.85, [], limit=2, kept=1)
    assert "(--max-effects; 1 kept, the others dropped since)" in one_kept
    assert "kept" not in verdict_reason("explained", far, far, refit, refit, 0.85, [], limit=2, kept=2)
    within = {"noise_ratio": 1.0, "worst_ratio": 1.2, "worst_channel": "vir"}  # within the noise: nothing is left to search, the limit is moot
    assert "--max-effects" not in verdict_reason("explained", within, within, refit, refit, 1.0, [], limit=2)


def test_one_channel_far_above_its_noise_is_not_explained_by_the_share_of_the_mean():
    """verdict.lone_channel: findings that remove EXPLAINED_SHARE of the mean's excess explain the data unless the
    whole is within the noise and one channel stays beyond LONE_CHANNEL x its own. Scores of seed 81's
    laser_arm-493fe444 (a motor-current sensor gain x1.82 beside a backlash, found as the backlash and a beam damping
    x6.7): training 0.61 x, validation 1.02 x, the motor current 2.82 x, 99 % of the excess removed - `explained`
    before. Far from the noise (EMPS: 25.8 x on the whole) the share still decides; a channel at 1.55 x (the most
    any right `explained` report of seeds 75-81 left) stays `explained`."""
    from watflex_sim.diagnosis.validate import NOISE_MARGIN
    from watflex_sim.diagnosis.verdict import LONE_CHANNEL, lone_channel, verdict_of, verdict_reason

    found = Model([{"effect": "backlash", "where": "hub", "width": 7.6e-5, "position": 0.0}])
    train = {"noise_ratio": 0.61, "worst_ratio": 2.20, "worst_channel": "motor_current"}
    held = {"noise_ratio": 1.02, "worst_ratio": 2.82, "worst_channel": "motor_current"}
    refit = {"noise_ratio": 7.12, "worst_ratio": 14.6, "worst_channel": "motor_current"}
    assert LONE_CHANNEL == pytest.approx(2 * NOISE_MARGIN)
    assert lone_channel(train, held) == ("motor_current", 2.82)
    assert verdict_of(found, train, held, 0.99, []) == "unexplained"
    reason = verdict_reason("unexplained", train, held, refit, refit, 0.99, [], limit=2)
    assert "motor_current stays 2.82 x its noise" in reason and "--max-effects" in reason
    far = {"noise_ratio": 25.8, "worst_ratio": 36.3, "worst_channel": "vir"}
    assert lone_channel(far, far) is None and verdict_of(found, far, far, 0.85, []) == "explained"
    near = dict(held, worst_ratio=1.55)
    assert lone_channel(train | {"worst_ratio": 1.2}, near) is None
    assert verdict_of(found, train | {"worst_ratio": 1.2}, near, 0.9, []) == "explained"


def test_in_a_round_for_local_windows_a_finding_must_remove_their_excess(monkeypatch):
    """validate.shortfall with `local_gain` (a round asked for by locate.local_excess): training and validation
    cannot show a 0.1 s misfit among many channels and recordings, so a finding earns its place by removing
    LOCAL_GAIN (half) of the windows' excess with neither worse; elimination keeps a finding the windows need
    even where validation's mean hardly moves without it (0.3 % here, under MIN_HELD_GAIN: set by hand, as in
    the test above), and drops it where no window asked for it."""
    from watflex_sim.diagnosis import validate
    from watflex_sim.diagnosis.locate import local_excess

    def result(train_gain, held_gain, local):
        return {"train_gain": train_gain, "held_gain": held_gain, "local_gain": local, "n_params": 2}

    assert validate.shortfall(result(0.002, 0.001, 0.8), later=False) == ""
    assert "local windows" in validate.shortfall(result(0.002, 0.001, 0.3), later=False)
    assert validate.shortfall(result(-0.01, 0.001, 0.8), later=False) != ""  # training worse

    data, sims, exact = _local_case(6.0)
    windows = local_excess(data, sims)

    class Runner:
        def simulate_models(self, models):
            return [exact if m.effects else sims for m in models]

    monkeypatch.setattr(validate, "fit_scores", lambda data, s, part: {"noise_ratio": 0.950 if s is exact else 0.953})
    found = Model([{"effect": "dwell_time_stiction", "where": "elbow", "gain": 0.1}])
    model, _, without = validate.eliminate(data, Runner(), found, exact, lambda *a: None, windows)
    assert model.effects == found.effects and without[0]["local_needed"]
    model, _, _ = validate.eliminate(data, Runner(), found, exact, lambda *a: None)  # no windows: dropped
    assert model.effects == []


def test_the_diagnosis_simulates_half_as_fine_where_that_is_as_good_against_the_noise(laser_recordings):
    """fidelity.choose_fidelity: the laser arm simulated half as fine (6 segments at 0.2 ms for 11 at 0.1 ms) is within
    COARSE_MARGIN (0.15) x the noise of its own (RMS) on every channel of two 2 s steps (measured 0.09 x; 0.04-0.07 x
    on seeds 65-66's 6 s recordings): every later simulation runs so, and one FINER x finer than that is the model's
    own again, sample for sample; a model with stick-slip there goes back to as fine (keep_fidelity). On 0.4 s steps the
    transient is most of the recording (0.20 x): as fine as the model. So is Watflex's 1 s elbow step, several times its
    noise off half as fine (0.5-7.5 x on 6 s recordings)."""
    from watflex_sim.diagnosis.fidelity import COARSE_MARGIN, choose_fidelity, keep_fidelity
    from watflex_sim.diagnosis.runner import Runner
    from watflex_sim.diagnosis.screening import SCREEN_FINER
    from watflex_sim.diagnosis.uncertainty import FINER

    said = []
    steps = [simulate(load_scenario("laser_arm_step", [f"direction={d}", "duration_s=2.0", f"seed={i}"])).recording
             for i, d in enumerate(("positive", "negative"))]
    data = prepare(steps, ["a.csv", "b.csv"])
    with Runner(data, 1) as runner:
        ours = runner.simulate(Model())
        sims, error = choose_fidelity(data, runner, ours, lambda kind, message: said.append(message))
        assert runner.fidelity == SCREEN_FINER and 0.05 < error < COARSE_MARGIN, error
        assert said and f"{error:.2f} x the noise" in said[0]
        again = runner.simulate(Model())  # at the fidelity chosen: the coarse simulation it returned
        assert all(np.array_equal(a.channels[c], b.channels[c]) for a, b in zip(again, sims) for c in a.channels)
        assert not np.array_equal(sims[0].channels["tip_sensor"], ours[0].channels["tip_sensor"])
        assert runner.refinable(FINER)
        model_own = runner.simulate(Model(), finer=FINER)
        assert all(np.array_equal(a.channels[c], b.channels[c]) for a, b in zip(model_own, ours) for c in a.channels)

        # fidelity.keep_fidelity: a smooth finding keeps the coarse model; stick-slip at the hub (the laser demo's gear
        # stiction) takes it beyond the margin, and the diagnosis goes back to the model's own for good
        payload = Model([{"effect": "payload", "where": "tip", "mass": 0.1}])
        assert keep_fidelity(data, runner, payload, runner.simulate(payload), lambda kind, message: None)
        assert runner.fidelity == SCREEN_FINER
        stiction = Model([{"effect": "coulomb_friction", "where": "hub", "torque_positive": 2.778, "torque_negative": 0.926}])
        coarse = runner.simulate(stiction)
        fine = keep_fidelity(data, runner, stiction, coarse, lambda kind, message: said.append(message))
        assert runner.fidelity == 1.0 and "from now on" in said[-1]
        assert all(np.array_equal(a.channels[c], b.channels[c]) for a, b in zip(fine, runner.simulate(stiction)) for c in a.channels)

    step = simulate(load_scenario("watflex_elbow_step", ["duration_s=1.0"])).recording
    for recordings in (laser_recordings, [step]):
        data = prepare(recordings, [f"{i}.csv" for i in range(len(recordings))])
        with Runner(data, 1) as runner:
            ours = runner.simulate(Model())
            sims, error = choose_fidelity(data, runner, ours, lambda kind, message: None)
            assert runner.fidelity == 1.0 and sims is ours and error > COARSE_MARGIN, error


def test_a_round_whose_candidate_does_not_stand_the_coarse_model_is_fitted_as_fine(monkeypatch):
    """fidelity.fine_for_round: on the laser arm simulated half as fine (choose_fidelity), a round whose fitted candidates
    are all smooth (a tip payload) stays coarse and untouched; one with a candidate that the coarse model misjudges
    (the demo's gear stick-slip, beyond COARSE_MARGIN x the noise from its own, as in keep_fidelity's test) goes to
    the model's own fidelity before the round chooses: every candidate carried on there (refine.carry_on, stubbed
    here: refine.carry_on_each) and the current model's simulations returned as fine, so the candidates' gains are against
    like."""
    from watflex_sim.diagnosis import fidelity
    from watflex_sim.diagnosis.effect_fit import scored
    from watflex_sim.diagnosis.runner import Runner
    from watflex_sim.diagnosis.screening import SCREEN_FINER

    carried = []
    monkeypatch.setattr(fidelity, "carry_on_each", lambda data, runner, items: [
        carried.append(result) or {**result, "carried": True} for result, _ in items])
    steps = [simulate(load_scenario("laser_arm_step", [f"direction={d}", "duration_s=2.0", f"seed={i}"])).recording
             for i, d in enumerate(("positive", "negative"))]
    data = prepare(steps, ["a.csv", "b.csv"])
    quiet = lambda kind, message: None  # noqa: E731
    with Runner(data, 1) as runner:
        sims, _ = fidelity.choose_fidelity(data, runner, runner.simulate(Model()), quiet)
        assert runner.fidelity == SCREEN_FINER
        payload = Model([{"effect": "payload", "where": "tip", "mass": 0.1}])
        smooth = [scored(data, {"model": payload, "effect": "payload", "where": "tip"}, runner.simulate(payload))]
        assert fidelity.fine_for_round(data, runner, Model(), sims, smooth, quiet) == (smooth, sims)
        assert runner.fidelity == SCREEN_FINER and not carried
        stiction = Model([{"effect": "coulomb_friction", "where": "hub", "torque_positive": 2.778, "torque_negative": 0.926}])
        rough = smooth + [scored(data, {"model": stiction, "effect": "coulomb_friction", "where": "hub"}, runner.simulate(stiction))]
        said = []
        out, now = fidelity.fine_for_round(data, runner, Model(), sims, rough,
                                           lambda kind, message: said.append(message))
        assert runner.fidelity == 1.0 and "coulomb_friction at hub" in said[-1] and "from now on" in said[-1]
        assert [r["effect"] for r in carried] == ["payload", "coulomb_friction"] and all(r["carried"] for r in out)
        fine_stiction = runner.simulate(stiction)  # carried on from its simulations as fine, not the coarse ones
        assert np.array_equal(carried[1]["sims"][0].channels["tip_sensor"], fine_stiction[0].channels["tip_sensor"])
        assert all(np.array_equal(a.channels[c], b.channels[c]) for a, b in zip(now, runner.simulate(Model())) for c in a.channels)


def _refits_scored_by(monkeypatch, ratio_of):
    """earlier's refits stood in for: levenberg keeps its start, and a model's training and validation noise ratios are
    both `ratio_of(model)` (the simulations' stand-in); returns a Runner class for swap_earlier."""
    from watflex_sim.diagnosis import earlier

    n_params = {"stribeck_friction": 3, "coulomb_friction": 2, "position_dependent_friction": 4, "actuator_gain": 1,
                "actuator_offset": 1}

    class Runner:
        def simulate(self, model):
            return ratio_of(model)

    monkeypatch.setattr(earlier, "levenberg", lambda evaluate, model, free, x0, J, iters: (model, 0.0, None))
    monkeypatch.setattr(earlier, "in_noise", lambda data, runner: None)
    monkeypatch.setattr(earlier, "effect_slots_of", lambda data, model: [])
    monkeypatch.setattr(earlier, "rig_slots", lambda data: [])
    monkeypatch.setattr(earlier, "parameter_count", lambda data, effect: n_params[effect["effect"]])
    monkeypatch.setattr(earlier, "fit_scores", lambda data, sims, part: {"noise_ratio": sims})
    monkeypatch.setattr(earlier, "scored", lambda data, result, sims: {**result, "sims": sims,
                                                                        "train": {"noise_ratio": sims},
                                                                        "held_out": {"noise_ratio": sims}})
    return Runner


def _fitted(effect, held, score, where="hub", **values):
    """A round's fitted result as swap_earlier reads it."""
    return {"effect": effect, "where": where, "model": Model([{"effect": effect, "where": where, **values}]),
            "held_out": {"noise_ratio": held}, "score": score}


def test_an_earlier_finding_is_replaced_by_its_runner_up_once_the_later_ones_are_in(monkeypatch):
    """swap_earlier(): seed 65, laser_arm-d6ea25d4 (hub Coulomb friction beside a voltage gain x1.132): with the
    gain missing, a Stribeck friction fitted validation best in round 1 (1.83 x the noise, Coulomb 2.19 x) and was
    kept beside the gain. Each runner-up within SWAP_WITHIN (1.5 x) of the winner is refit in its place beside the
    later findings, and taken when validate.gains scores it better against the model without the winner (training
    and validation falls, MIN_GAIN = 0.02 per parameter). Noise ratios here are set per set of effects: without
    the friction 5.5 x; Stribeck (3 parameters) 0.77 x: score 2 (5.5 - 0.77) / 5.5 - 0.06 = 1.660; Coulomb
    (2 parameters) 0.75 x: 1.687, taken; at 0.95 x: 1.615, not taken; a position-dependent friction at 0.90 x: 1.593."""
    from watflex_sim.diagnosis import earlier

    ratio = {("actuator_gain",): 5.5, ("actuator_gain", "stribeck_friction"): 0.77,
             ("actuator_gain", "coulomb_friction"): 0.75, ("actuator_gain", "position_dependent_friction"): 0.90}
    Runner = _refits_scored_by(monkeypatch, lambda model: ratio[tuple(sorted(e["effect"] for e in model.effects))])
    gain = {"effect": "actuator_gain", "where": "voltage_cmd", "ratio": 1.118}
    current = earlier.scored(None, {"model": Model([{"effect": "stribeck_friction", "where": "hub"}, gain])}, 0.77)
    round_1 = (_fitted("stribeck_friction", 1.83, 1.187), [_fitted("coulomb_friction", 2.19, 1.0),
                                                           _fitted("position_dependent_friction", 2.26, 1.18),
                                                           _fitted("viscous_friction", 3.0, 0.9)])  # 3.0 > 1.5 x 1.83
    out, tried = earlier.swap_earlier(None, Runner(), current, [round_1], 1e-3)
    assert [e["effect"] for e in out["model"].effects] == ["actuator_gain", "coulomb_friction"]
    assert out["score"] == pytest.approx(2 * (5.5 - 0.75) / 5.5 - 0.04)
    assert [(a["effect"], b["effect"]) for a, b in tried] == [("position_dependent_friction", "stribeck_friction"),
                                                              ("stribeck_friction", "coulomb_friction")]
    assert tried[1][0]["model"].effects[-1]["effect"] == "stribeck_friction"  # the one replaced, last: alternative_entry
    ratio[("actuator_gain", "coulomb_friction")] = 0.95
    out, tried = earlier.swap_earlier(None, Runner(), current, [round_1], 1e-3)
    assert out is current and [a["effect"] for a, _ in tried] == ["position_dependent_friction", "coulomb_friction"]


def test_a_ripple_runner_up_is_fitted_anew_beside_the_later_findings(monkeypatch):
    """swap_earlier(anew): seed 116, laser_arm-3cd2e177, a hub ripple (0.083 N m over 0.039 rad, the hub moving 2 mrad)
    beside a voltage gain x0.735. With the gain missing, round 1 kept a voltage offset (9.91 x the noise) over the
    ripple (9.95 x), fitted at 0.010 rad with a spring of -36 N m/rad; refit from there beside the gain it reached
    2.95 x on validation against the offset's 1.43 x (swap_earlier's tries printed); the true ripple refit in its
    place 0.77 x. Stand-ins: the gain alone 16 x; a ripple scores by its period. A ripple runner-up is also fitted anew
    (`anew`, once a place though the round fitted it twice) and refit from there; the better is taken: score
    2 (16 - 0.77) / 16 - 0.08 = 1.824 against the offset's 2 (16 - 1.43) / 16 - 0.02 = 1.801. Without `anew`, not."""
    from watflex_sim.diagnosis import earlier

    def ratio_of(model):
        effects = {e["effect"]: e for e in model.effects}
        if "position_dependent_friction" in effects:
            return 0.77 if effects["position_dependent_friction"]["period"] == 0.039 else 2.95
        return 1.43 if "actuator_offset" in effects else 16.0

    Runner = _refits_scored_by(monkeypatch, ratio_of)
    gain = {"effect": "actuator_gain", "where": "voltage_cmd", "ratio": 0.735}
    offset = {"effect": "actuator_offset", "where": "voltage_cmd", "offset": 0.0215}
    current = earlier.scored(None, {"model": Model([offset, gain])}, 1.43)
    ripples = [_fitted("position_dependent_friction", 9.95, 0.92, period=0.0104, amplitude=0.37),
               _fitted("position_dependent_friction", 9.69, 0.81, period=0.001, amplitude=0.28)]
    round_1 = (_fitted("actuator_offset", 9.91, 0.93, where="voltage_cmd", offset=0.029), ripples)
    out, tried = earlier.swap_earlier(None, Runner(), current, [round_1], 1e-3)
    assert out is current and len(tried) == 2  # from round 1's fits: 2.95 x, not taken
    calls = []

    def anew(base, effect, where):
        calls.append((effect, where, tuple(e["effect"] for e in base.effects)))
        return Model(base.effects + [{"effect": effect, "where": where, "period": 0.039, "amplitude": -0.083}])

    out, tried = earlier.swap_earlier(None, Runner(), current, [round_1], 1e-3, anew)
    assert [e["effect"] for e in out["model"].effects] == ["actuator_gain", "position_dependent_friction"]
    assert out["model"].effects[-1]["period"] == 0.039 and out["score"] == pytest.approx(2 * (16 - 0.77) / 16 - 0.08)
    assert calls == [("position_dependent_friction", "hub", ("actuator_gain",))]


def test_a_hunting_loop_raises_the_noise_floor_it_is_judged_by():
    """floors.raise_noise_floor: the floor (what the rig's noise leaves in closed loop, what a finer step changes) is
    measured again with the findings in. A hub backlash of 1.2e-4 rad in the laser arm's tip loop makes the loop hunt,
    and the recordings' own noise then moves the tip far more than with the nominal model (measured on 2 s steps:
    tip sensor 0.0103 -> 0.0410 V, x4.0; seed 75's laser_arm-214f6418, 6 s: x12); the nominal model, measured again,
    raises nothing. floors.floors_after_dropping: once elimination drops the backlash, the floors are the nominal
    model's again (every FLOORS field), and with it kept they are raised again to the same values (NOISE_SEED)."""
    from copy import deepcopy

    from watflex_sim.diagnosis.floors import FLOORS, calibrate_noise, floors_after_dropping, raise_noise_floor
    from watflex_sim.diagnosis.runner import Runner

    backlash = {"effect": "backlash", "where": "hub", "width": 1.2e-4}  # rad
    recs = []
    for i, d in enumerate(("positive", "negative")):
        scenario = load_scenario("laser_arm_step", [f"direction={d}", "duration_s=2", f"seed={i}"])
        scenario["effects"] = [backlash]
        recs.append(simulate(scenario).recording)
    data = prepare(recs, ["up", "down"])
    with Runner(data, workers=1) as runner:
        sims = runner.simulate(Model())
        calibrate_noise(data, runner, Model(), sims, lambda *a: None)
        nominal = [dict(n) for n in data.noise]
        assert raise_noise_floor(data, runner, Model(), sims, lambda *a: None) == []
        assert data.noise == nominal
        floors = deepcopy({k: getattr(data, k) for k in FLOORS})
        found = Model([backlash])
        found_sims = runner.simulate(found)
        raised = raise_noise_floor(data, runner, found, found_sims, lambda *a: None)
        for i, name in enumerate(data.names):
            assert any(r.startswith(f"{name}: tip_sensor x") for r in raised)
            assert data.noise[i]["tip_sensor"] > 3.0 * nominal[i]["tip_sensor"]
            assert all(data.noise[i][c] >= nominal[i][c] for c in nominal[i])  # raised, never lowered
        with_backlash = [dict(n) for n in data.noise]
        floors_after_dropping(data, runner, Model(), sims, floors, lambda *a: None)
        for k in FLOORS:  # the nominal model's again, field by field, sample by sample
            mine, nominal_k = getattr(data, k), floors[k]
            assert len(mine) == len(nominal_k) and all(a.keys() == b.keys() for a, b in zip(mine, nominal_k))
            assert all(np.array_equal(a[c], b[c]) for a, b in zip(mine, nominal_k) for c in a)
        floors_after_dropping(data, runner, found, found_sims, floors, lambda *a: None)
        assert data.noise == with_backlash


def test_with_no_finding_left_the_rig_is_refit_in_the_floors_units(monkeypatch):
    """refit.without_findings: where no finding is left and the nominal refit is not within the noise, the rig's
    parameters are refit without effects (in the calibrated floors' units) from where the findings' fits left them
    and from the nominal refit's, and the better on training is taken where it is no worse on validation than the
    nominal refit. Seed 78's two-joint clean watflex-1875e76b: the nominal refit at 8.16 / 7.74 x the noise (training
    / validation), a strain gain of 1 fitted beside the rig's parameters at 0.83 / 0.86 x, dropped as vague, and the
    case left `unexplained` at the nominal refit. Stand-ins for the refit and the scores."""
    from watflex_sim.diagnosis import refit as R

    ratios = {("nominal", "train"): 8.16, ("nominal", "held_out"): 7.74}
    monkeypatch.setattr(R, "fit_scores", lambda data, sims, part: {"noise_ratio": ratios[(sims[0], part)],
                                                                   "worst_ratio": ratios[(sims[0], part)]})
    left, nominal, nominal_sims = Model([], {"link2_EI": 0.955}), Model([], {"link2_EI": 1.05}), ["nominal"]
    fits = {0.955: (0.951, ["from left"]), 1.05: (1.03, ["from nominal"])}
    seen = []

    def refit_on_training(data, runner, m):
        seen.append(m)
        value, sims = fits[m.parameters["link2_EI"]]
        return Model([], {"link2_EI": value}), sims
    monkeypatch.setattr(R, "refit_on_training", refit_on_training)
    ratios |= {("from left", "train"): 0.83, ("from left", "held_out"): 0.86,
               ("from nominal", "train"): 2.1, ("from nominal", "held_out"): 2.0}
    model, sims = R.without_findings(None, None, left, nominal, nominal_sims, lambda *a: None)
    assert sims == ["from left"] and model.parameters == {"link2_EI": 0.951}
    assert [m.parameters for m in seen] == [left.parameters, nominal.parameters] and not any(m.effects for m in seen)
    ratios[("from left", "held_out")] = 7.8  # better on training, worse on validation than the nominal refit
    assert R.without_findings(None, None, left, nominal, nominal_sims, lambda *a: None)[1] == ["from nominal"]
    ratios[("from nominal", "held_out")] = 7.9
    assert R.without_findings(None, None, left, nominal, nominal_sims, lambda *a: None) == (nominal, nominal_sims)
    ratios[("nominal", "train")] = ratios[("nominal", "held_out")] = 0.9  # within the noise: no refit at all
    seen.clear()
    assert R.without_findings(None, None, left, nominal, nominal_sims, lambda *a: None) == (nominal, nominal_sims)
    assert seen == []


def test_a_friction_law_is_started_where_its_sliding_curve_matches_the_found_ones(laser_recordings):
    """laws.curve_start: a law's parameters by least squares of its sliding curve (friction.exponential) on the
    found laws' curve at the given speeds. A Stribeck friction's own curve gives back its parameters (seed 79's
    laser_arm-49948fef truth: break-away 0.05081 / 0.05143 N m, v_s 0.0103 rad/s); a Coulomb friction matched to that
    case's Coulomb + viscous pair (c - b |v|, b > 0 negative viscous, on evenly spread speeds up to 0.02 rad/s) is in
    each direction the curve's mean, c - b mean|v| (the least-squares constant): 0.05238 - 2.3235 x 0.01025."""
    from watflex_sim.diagnosis.laws import curve_start

    data = prepare(laser_recordings, ["a", "b"])
    speeds = np.r_[np.linspace(-0.04, -0.0005, 50), np.linspace(0.0005, 0.04, 50)]  # rad/s
    truth = {"effect": "stribeck_friction", "where": "hub", "breakaway_positive": 0.05081, "breakaway_negative": 0.05143,
             "v_s": 0.0103}
    start = curve_start(data, Model([truth]), [], "stribeck_friction", "hub", speeds)
    assert all(start[k] == pytest.approx(truth[k], rel=1e-6) for k in ("breakaway_positive", "breakaway_negative", "v_s"))
    pair = Model([{"effect": "coulomb_friction", "where": "hub", "torque_positive": 0.05238, "torque_negative": 0.05320},
                  {"effect": "viscous_friction", "where": "hub", "coefficient": -2.3235, "coefficient_negative": -2.2562}])
    speeds = np.r_[np.linspace(-0.02, -0.0005, 50), np.linspace(0.0005, 0.02, 50)]
    start = curve_start(data, pair, [], "coulomb_friction", "hub", speeds)
    mean_speed = float(np.mean(np.linspace(0.0005, 0.02, 50)))  # 0.01025 rad/s
    assert start["torque_positive"] == pytest.approx(0.05238 - 2.3235 * mean_speed, rel=1e-5)
    assert start["torque_negative"] == pytest.approx(0.05320 - 2.2562 * mean_speed, rel=1e-5)


def test_two_friction_laws_at_one_joint_give_way_to_one_that_scores_better(monkeypatch):
    """laws.one_law: seed 79's laser_arm-49948fef, a small hub Stribeck friction found as a Coulomb friction and then a
    negative viscous term (validation 0.755 x the noise; 2.56 x without both). The Stribeck law refit in their place
    (measured: 0.757 x) is scored by validate.gains against the model without the pair, MIN_GAIN = 0.02 per parameter:
    2 (2.56 - 0.757) / 2.56 - 0.06 = 1.349 against the pair's 2 (2.56 - 0.755) / 2.56 - 0.08 = 1.330: taken, the pair
    kept for the alternatives (its two laws last); at 0.80 x, 1.315: not taken. Two laws of which one is not a
    sliding curve (a position-dependent friction beside a viscous one, seed 79's true pair) are left alone."""
    from types import SimpleNamespace

    from watflex_sim.diagnosis import earlier, laws

    ratio = {(): 2.56, ("coulomb_friction", "viscous_friction"): 0.755, ("stribeck_friction",): 0.757}

    class Runner:
        def simulate(self, model):
            return ratio.get(tuple(sorted(e["effect"] for e in model.effects)), 3.0)  # stands for the simulations

    monkeypatch.setattr(earlier, "levenberg", lambda evaluate, model, free, x0, J, iters: (model, 0.0, None))
    monkeypatch.setattr(earlier, "in_noise", lambda data, runner: None)
    monkeypatch.setattr(earlier, "effect_slots_of", lambda data, model: [])
    monkeypatch.setattr(earlier, "rig_slots", lambda data: [])
    for module in (laws, earlier):
        monkeypatch.setattr(module, "parameter_count", lambda data, effect: {"stribeck_friction": 3}.get(effect["effect"], 2))
    monkeypatch.setattr(earlier, "fit_scores", lambda data, sims, part: {"noise_ratio": sims})
    monkeypatch.setattr(earlier, "scored", lambda data, result, sims: {**result, "sims": sims,
                                                                        "train": {"noise_ratio": sims},
                                                                        "held_out": {"noise_ratio": sims}})
    monkeypatch.setattr(laws, "joint_speeds", lambda data, sims, joint: np.zeros(0))
    monkeypatch.setattr(laws, "curve_start", lambda data, model, rest, law, joint, speeds: {"effect": law, "where": joint})
    places = {law: ["hub"] for law in ("coulomb_friction", "stribeck_friction", "viscous_friction", "position_dependent_friction")}
    data = SimpleNamespace(rig=SimpleNamespace(effects=places))
    pair = [{"effect": "coulomb_friction", "where": "hub"}, {"effect": "viscous_friction", "where": "hub"}]
    current = earlier.scored(None, {"model": Model(pair)}, 0.755)
    out, tried = laws.one_law(data, Runner(), current, 1e-3)
    assert [e["effect"] for e in out["model"].effects] == ["stribeck_friction"]
    assert out["score"] == pytest.approx(2 * (2.56 - 0.757) / 2.56 - 0.06)
    (kept, taken, before), = tried
    assert taken is out and before == 0 and kept["score"] == pytest.approx(2 * (2.56 - 0.755) / 2.56 - 0.08)
    assert [e["effect"] for e in kept["model"].effects] == ["coulomb_friction", "viscous_friction"]
    ratio[("stribeck_friction",)] = 0.80
    out, tried = laws.one_law(data, Runner(), current, 1e-3)
    assert out is current and [t[0]["effect"] for t in tried] == ["stribeck_friction"]
    ripple = earlier.scored(None, {"model": Model([pair[1], {"effect": "position_dependent_friction", "where": "hub"}])},
                            0.7)
    assert laws.one_law(data, Runner(), ripple, 1e-3) == (ripple, [])


def test_an_earlier_finding_s_size_is_restarted_a_decade_away_beside_a_later_candidate_that_falls_just_short(monkeypatch):
    """earlier.restart_earlier and validate.near_place: seed 80's laser_arm-a66d52a5 (hub Stribeck friction beside a
    4.6e-5 rad backlash: each alone fits worse than neither, 5.00 x and 5.22 x against 4.75 x, both 2.00 x): the
    backlash found first at 4.24e-6 rad, the Stribeck fitted beside it removed 16 % of validation's excess where a later
    finding must remove 25 % (MIN_EXCESS_GAIN): within NEAR_SHARE (half) of it, so the Stribeck is fitted again with
    the earlier finding's log-scaled width restarted 10 x and 0.1 x from 4.24e-6 (its position, linear, is not) and the
    best-scored fit is returned (measured on the case: from 4.24e-5, backlash 4.63e-5 and Stribeck 0.0539 / 0.0611 N m,
    v_s 0.0144 rad/s, validation 0.53 x the noise, `explained`)."""
    from watflex_sim.diagnosis import earlier
    from watflex_sim.diagnosis.validate import MIN_EXCESS_GAIN, NEAR_SHARE, near_place

    assert NEAR_SHARE * MIN_EXCESS_GAIN == pytest.approx(0.125)
    short = {"train_gain": 0.167, "held_gain": 0.099, "excess_gain": 0.160, "n_params": 3, "train_within": False}
    assert near_place(short, later=True) and not near_place(short, later=False)  # a first finding has no such bar
    assert not near_place({**short, "excess_gain": 0.10}, later=True)
    assert not near_place({**short, "excess_gain": 0.30}, later=True)  # earns its place: nothing to restart

    slots = [Slot(("effect", 0, "width"), 1e-7, 1e-4, True), Slot(("effect", 0, "position"), -1.0, 1.0, False)]
    monkeypatch.setattr(earlier, "effect_slots_of", lambda data, model: slots)
    tried = []

    def fit(base):  # the round's candidate fit on top of `base`, judged: the truth's width scores best
        width = base.effects[0]["width"]
        tried.append((width, base.effects[0]["position"]))
        return [{"model": base, "score": -abs(math.log10(width / 4.6e-5))}]

    current = Model([{"effect": "backlash", "where": "hub", "width": 4.24e-6, "position": 0.1745}])
    best = earlier.restart_earlier(None, current, fit)
    assert [(pytest.approx(w), p) for w, p in tried] == [(4.24e-5, 0.1745), (4.24e-7, 0.1745)]
    assert best["model"].effects[0]["width"] == pytest.approx(4.24e-5)
    tried.clear()
    earlier.restart_earlier(None, Model([{**current.effects[0], "width": 2e-5}]), fit)
    assert tried[0][0] == 1e-4  # clamped to the slot's bound


def test_a_side_the_noise_makes_look_like_friction_is_not_ruled_out():
    """uncertainty.realisation_reach: laser-arm 2.5 mm steps either way (4 s, the rig's noise on) with a hub Coulomb
    friction of 0.0984 N m against negative motion only (seed 113's laser_arm-b895983b, our simulator). The rig's
    noise fed back makes a rig at rest creep the free way, and a noise-free re-simulation of the truth fits worse than
    a biased estimate with a positive side of 0.027 N m (measured 6,059 against 7,986 in noise units, seeds 20 / 21;
    the trap itself is asserted). Its interval (the diagnosis' 0.023-0.031 N m there) must reach 0: the data are
    nearer some noisy realisation of the model with that side at 0 than the estimate's are on average (measured
    5,898-6,396 against 9,044). The negative side, which the data do need, keeps its interval off 0."""
    from watflex_sim.diagnosis import uncertainty
    from watflex_sim.diagnosis.data import residual_vector, unit_change
    from watflex_sim.diagnosis.runner import Runner

    truth = [{"effect": "coulomb_friction", "where": "hub", "torque_positive": 0.0, "torque_negative": 0.0984}]  # N m
    recs = []
    for i, way in enumerate(("positive", "negative")):
        scenario = load_scenario("laser_arm_step", [f"direction={way}", "duration_s=4", f"seed={20 + i}"])
        scenario["effects"] = truth
        recs.append(simulate(scenario).recording)
    data = prepare(recs, ["up", "down"])
    estimate = Model([{**truth[0], "torque_positive": 0.027, "torque_negative": 0.0976}])
    with Runner(data, workers=1) as runner:
        sims = runner.simulate(estimate)
        per = unit_change(data, "all", sims=sims)

        def cost(runs):
            return float(np.sum((residual_vector(data, runs, "all") / per) ** 2))

        assert cost(sims) < cost(runner.simulate(Model(truth))) - 1000  # the trap: noise-free, the estimate fits better
        costs = [cost(runs) for runs in runner.simulate_seeds(estimate, list(uncertainty.REPLICATE_SEEDS))]
        out = {0: {"torque_positive": (0.023, 0.031), "torque_negative": (0.0946, 0.1005)}}
        uncertainty.realisation_reach(data, runner, estimate, per, costs, out)
    assert out[0]["torque_positive"] == (0.0, 0.031)
    assert out[0]["torque_negative"] == (0.0946, 0.1005)


def test_an_alternative_the_settled_model_leaves_behind_is_not_listed():
    """validate.told_apart(): seed 120's laser_arm-91f8db5b listed a hub ripple at 5.90 x the noise beside round 2's
    model at 5.76 x (within ALTERNATIVE_MARGIN, 3 %); once the delay's step was searched again the model was at 0.76 x,
    within the 1.3 x margin, and the ripple no longer an alternative. Kept where the final model is outside the margin
    too, or the alternative within it, or within 3 % of the final model."""
    from watflex_sim.diagnosis.validate import told_apart

    assert told_apart({"validation_noise_ratio": 5.904}, {"noise_ratio": 0.763})
    assert not told_apart({"validation_noise_ratio": 5.904}, {"noise_ratio": 5.762})  # both outside: a rival
    assert not told_apart({"validation_noise_ratio": 1.25}, {"noise_ratio": 0.76})  # within the margin too
    assert not told_apart({"validation_noise_ratio": 1.32}, {"noise_ratio": 1.29})  # 2.3 % apart
