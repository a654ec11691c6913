"""One physics, two drivers: lockstep.simulate_batch gives engine.simulate's recordings, bit for bit.

The batch runs the same ControlLoop control half and the same MuJoCo step (mujoco.batch is
bit-identical to a loop of mj_step). The joint friction is computed by two codes - the single run's
passive callback, per joint on floats, and the batch's BatchFriction on arrays - that do the same
arithmetic in the same order (numpy's exp and sin, x * x, the torque added to what the rig applies
in qfrc_applied). Before they did (math.exp, a float's ** 2.0, the callback's torque in qfrc_passive)
a laser arm with Stribeck friction differed by 4e-15 V after 3 s, and inside a diagnosis stick-slip
made such an ulp another finding. So every channel must be equal: TOL is 0.
"""
import numpy as np
import pytest

from watflex_sim.engine import SimulationError, simulate
from watflex_sim.lockstep import simulate_batch
from watflex_sim.scenario import load_scenario

TOL = 0.0  # see the module docstring


def _max_differences(single, batched) -> dict[str, float]:
    """Per channel, the largest |single - batch| (NaN where both are NaN, e.g. camera between frames)."""
    assert set(single.channels) == set(batched.channels)
    out = {}
    for c, x in single.channels.items():
        y = batched.channels[c]
        assert np.array_equal(np.isnan(x), np.isnan(y)), c
        finite = ~np.isnan(x)
        out[c] = float(np.max(np.abs(x[finite] - y[finite]), initial=0.0))
    return out


def _compare(scenarios):
    """Every scenario's batch recording against its single run; a structure with one member would
    run on the single-run driver, so the cases below come at least in pairs (`always`: in lockstep however
    few, where simulate_batch would otherwise run them one by one)."""
    results = simulate_batch(scenarios, nthread=2, always=True)
    for scenario, result in zip(scenarios, results):
        single = simulate(scenario).recording
        worst = _max_differences(single, result.recording)
        assert max(worst.values()) <= TOL, (scenario["name"], worst)
        np.testing.assert_array_equal(single.time, result.recording.time)
    return results


def test_laser_arm_seeds_and_coulomb_friction_match_single_runs():
    """Per-simulation noise seeds (different recordings), and a diagnosis effect that adds
    joint friction to the laser arm's hub (the batch's array friction, not the callback)."""
    base = ["duration_s=0.6"]
    coulomb = "effects=[{effect='coulomb_friction', where='hub', torque_positive=0.02, torque_negative=0.03}]"
    scenarios = [load_scenario("laser_arm_step", base + [f"seed={s}"]) for s in (1, 2)]
    scenarios.append(load_scenario("laser_arm_step", base + [coulomb]))
    results = _compare(scenarios)
    a, b = (r.recording.channels["tip_sensor"] for r in results[:2])
    assert not np.array_equal(a, b)  # the seeds are really per simulation


def test_stribeck_friction_on_an_unquantised_channel_matches_single_runs():
    """The Stribeck level (alpha1 exp(-(v/v_s)^2)) and viscous term at the laser arm's hub, 3 s: the tip
    sensor is not quantised, so an ulp of friction shows (4e-15 V when the callback used math.exp)."""
    law = "{alpha0=0.3, alpha1=0.4, alpha2=0.5, v_s=0.05}"
    _compare([load_scenario("laser_arm_step", ["duration_s=3", f"seed={s}", f"joint_friction={{hub={{positive={law}, "
                                               f"negative={law}}}}}"]) for s in (1, 2)])


def test_watflex_elbow_step_with_payload_and_locked_shoulder_match_single_runs():
    """Nominal Watflex joint friction (levels set between steps), a payload (per-simulation masses)
    and a locked shoulder (another model structure; alone in it, it runs on the single-run driver)."""
    base = ["duration_s=0.6"]
    scenarios = [load_scenario("watflex_elbow_step", base),
                 load_scenario("watflex_elbow_step", base + ["payload_kg=0.2", "seed=3"]),
                 load_scenario("watflex_elbow_step", base + ["locked_joints={shoulder=0.0}"])]
    _compare(scenarios)


def test_watflex_friction_variants_match_single_runs():
    """The rest of the friction law on arrays: position-dependent torque and dwell-time stiction
    (effects), and LuGre presliding (watflex_presliding)."""
    ripple = ("effects=[{effect='position_dependent_friction', where='elbow', amplitude=0.05, period=0.5, spring=0.1},"
              " {effect='dwell_time_stiction', where='elbow', gain=0.5, time_constant=0.2}]")
    _compare([load_scenario(name, ["duration_s=0.6", f"seed={seed}", *sets]) for seed in (1, 2)
              for name, sets in (("watflex_elbow_step", [ripple]), ("watflex_presliding", []))])


def test_a_diverging_member_is_dropped_and_the_others_go_on():
    """A timestep far too large for the laser arm's beam (README: stable below 0.2 ms) diverges."""
    good = load_scenario("laser_arm_step", ["duration_s=0.6"])
    bad = load_scenario("laser_arm_step", ["duration_s=0.6", "timestep=0.001"])
    ok, failed = simulate_batch([good, bad], always=True)
    assert isinstance(failed, SimulationError)
    with pytest.raises(SimulationError):
        simulate(bad)
    assert max(_max_differences(simulate(good).recording, ok.recording).values()) == 0.0


def test_jittered_commands_match_single_runs(tmp_path, monkeypatch):
    """A rig with control_jitter_s (tests/test_jitter.py's EMPS copy, 2 ms period, 1.5 ms jitter):
    each simulation releases its command at its own substep (ControlLoop.release), two seeds."""
    from test_jitter import make_rig, scenario

    make_rig(tmp_path, monkeypatch, "0.0015")
    _compare([scenario(tmp_path, [f"seed={s}"], duration=0.6) for s in (1, 2)])


def test_a_model_that_cannot_be_built_fails_alone_in_a_resimulation_batch():
    """resim.resimulate_many: a member whose effects make an impossible model (a payload 5 kg lighter than
    the laser arm's 0 kg, as a diagnosis step beyond a slot's physical range can propose) gives its own
    SimulationError; the member beside it is simulated as alone (identical channels)."""
    from watflex_sim.resim import resimulate, resimulate_many

    rec = simulate(load_scenario("laser_arm_step", ["duration_s=0.2", "payload_kg=0"])).recording
    bad = [{"effect": "payload", "where": "tip", "mass": -5.0}]
    failed, fine = resimulate_many([(rec, bad), (rec, [])], nthread=1)
    assert isinstance(failed, SimulationError) and "cannot be built" in str(failed)
    alone = resimulate(rec)
    assert all(np.array_equal(fine.channels[c], alone.channels[c], equal_nan=True) for c in alone.channels)


def test_small_groups_run_one_by_one_where_a_batch_would_not_pay():
    """lockstep._pays (tools/bench.py section 6): a batch pays a fixed cost per Batch.step call and tick,
    and joint friction makes one call per physics step (the laser arm: 10 a tick). Measured on one thread,
    1 s runs, lockstep / one by one, with the control half on arrays (columns.py): Watflex 1.13 at B = 4, 0.92
    at 6; the laser arm 1.02 at 4, 0.96 at 6; with hub friction 1.04 at 6, 0.95 at 8, 0.90 at 10. With each
    member's own control half (an effect on it, here a sensor delay): Watflex 1.3-1.6 at B = 2-4, 0.83-0.92 from
    8; the laser arm with hub friction ~1 at 8-16, 0.75-0.83 at 32."""
    from watflex_sim.engine import ControlLoop
    from watflex_sim.lockstep import _pays

    def loops(name, n, sets=()):
        return [ControlLoop(load_scenario(name, ["duration_s=0.1", f"seed={i}", *sets])) for i in range(n)]

    coulomb = "{effect='coulomb_friction', where='hub', torque_positive=0.02, torque_negative=0.03}"
    delay = "{effect='delay', where='hub_angle', seconds=0.002}"
    assert _pays(loops("watflex_elbow_step", 6)) and not _pays(loops("watflex_elbow_step", 4))
    assert _pays(loops("laser_arm_step", 6)) and not _pays(loops("laser_arm_step", 4))
    assert not _pays(loops("laser_arm_step", 8, [f"effects=[{coulomb}]"]))
    assert _pays(loops("laser_arm_step", 10, [f"effects=[{coulomb}]"]))
    assert not _pays(loops("laser_arm_step", 16, [f"effects=[{coulomb}, {delay}]"]))
    assert _pays(loops("laser_arm_step", 30, [f"effects=[{coulomb}, {delay}]"]))


@pytest.fixture
def built(monkeypatch):
    """Every ColumnControl lockstep builds (None where a group has no column form): proof a case ran on arrays."""
    from watflex_sim import lockstep

    made = []
    original = lockstep.ColumnControl.of
    monkeypatch.setattr(lockstep.ColumnControl, "of", lambda *a: made.append(original(*a)) or made[-1])
    return made


def test_the_control_half_on_arrays_matches_single_runs(built):
    """columns.py: the rigs' sensors and converters and the controllers' column forms (open loop, pd_joint's
    Butterworth-filtered difference, PID with integral, limit and command filter, state feedback through a
    discretised rate filter, pd_tip with a difference) give each member the single run's numbers, bit for bit;
    the spy makes sure every case really ran on arrays."""
    pid = ("controller={type='pid', command='elbow_torque_cmd', position='elbow_angle', reference='elbow_reference', "
           "kp=60.0, ki=40.0, kd=12.0, rate_hz=30.0, limit=1.5, command_filter_hz=80.0}")
    feedback = ("controller={type='state_feedback', commands=['elbow_torque_cmd'], states=['elbow_angle', "
                "'rate:elbow_angle'], gains=[[60.0, 12.0]], references={elbow_angle='elbow_reference'}, rate_hz=40.0, "
                "rate_method='bilinear', command_filter_hz=100.0}")
    cases = [("watflex_elbow_triangle", []), ("watflex_elbow_staircase", []), ("watflex_elbow_step", [pid]),
             ("watflex_elbow_step", [feedback]), ("laser_arm_step", ["controller.kd=0.002"])]
    for name, sets in cases:
        built.clear()
        _compare([load_scenario(name, ["duration_s=0.5", f"seed={s}", *sets]) for s in (1, 2)])
        assert built and all(c is not None for c in built), name


def test_a_diagnosis_resimulation_batch_runs_on_arrays_and_matches_single_runs(built):
    """resim.resimulate_many, as the diagnosis calls it: one laser-arm recording re-simulated with six refit
    models (ratios of the beam's stiffness) in lockstep, on arrays, equals each re-simulated alone."""
    from watflex_sim.resim import resimulate, resimulate_many

    rec = simulate(load_scenario("laser_arm_step", ["duration_s=0.5", "seed=4"])).recording
    ratios = [0.97, 0.99, 1.0, 1.01, 1.02, 1.04]
    together = resimulate_many([(rec, [], {"beam_EI": r}) for r in ratios], nthread=1)
    assert len(built) == 1 and built[0] is not None
    for r, sim in zip(ratios, together):
        alone = resimulate(rec, [], {"beam_EI": r})
        assert all(np.array_equal(sim.channels[c], alone.channels[c], equal_nan=True) for c in alone.channels), r


def test_members_with_a_control_half_of_their_own_run_apart_and_the_rest_on_arrays(built):
    """simulate_batch: a resimulation batch where some members carry an effect on the control half that has no
    column form (here a sensor delay, as the diagnosis' signature probes do) has those run apart, not the whole group
    on per-member control (a Watflex signature batch spent 18 s of 33 in per-member control that way, 6 s in
    physics); every member still equals its run alone."""
    from watflex_sim.resim import resimulate, resimulate_many

    rec = simulate(load_scenario("laser_arm_step", ["duration_s=0.5", "seed=4"])).recording
    delay = [{"effect": "delay", "where": "hub_angle", "seconds": 0.002}]
    jobs = [(rec, [], {"beam_EI": r}) for r in (0.97, 0.99, 1.0, 1.01, 1.02, 1.04)] + [(rec, delay, {})]
    together = resimulate_many(jobs, nthread=1)
    assert len(built) == 1 and built[0] is not None  # the six plain members, on arrays; the seventh alone
    for job, sim in zip(jobs, together):
        alone = resimulate(*job)
        assert all(np.array_equal(sim.channels[c], alone.channels[c], equal_nan=True) for c in alone.channels), job[1:]


def test_sensor_and_actuator_gains_offsets_and_limits_run_on_arrays_and_match_single_runs(built):
    """columns.Patches: members with a sensor gain or offset (on a channel the controller reads and on one it does not)
    or an actuator gain, offset or limit, beside members without, run on arrays and equal their single runs bit for
    bit. The laser arm's refit tip-sensor gain (rigs/laser_arm.toml) is such a sensor gain on every model a diagnosis
    simulates: until it had a column form every laser diagnosis batch ran per-member control."""
    laser = ["{effect='sensor_gain', where='tip_sensor', ratio=1.013}",
             "{effect='sensor_offset', where='motor_current', offset=0.003}",
             "{effect='actuator_gain', where='voltage_cmd', ratio=0.93}, {effect='current_saturation', where='voltage_cmd', limit=0.5}",
             "{effect='actuator_offset', where='voltage_cmd', offset=0.05}"]
    watflex = ["{effect='sensor_gain', where='strain_2A', ratio=-1.0}",
               "{effect='sensor_offset', where='elbow_angle', offset=0.002}",
               "{effect='actuator_gain', where='elbow_torque_cmd', ratio=1.1}, {effect='actuator_offset', "
               "where='elbow_torque_cmd', offset=0.4}, {effect='current_saturation', where='elbow_torque_cmd', limit=0.3}"]
    for name, effects in (("laser_arm_step", laser), ("watflex_elbow_step", watflex)):
        built.clear()
        scenarios = [load_scenario(name, ["duration_s=0.5", "seed=1"])]
        scenarios += [load_scenario(name, ["duration_s=0.5", "seed=1", f"effects=[{e}]"]) for e in effects]
        results = _compare(scenarios)
        assert len(built) == 1 and built[0] is not None, name  # one batch, on arrays
        plain = results[0].recording.channels
        assert all(not all(np.array_equal(plain[c], r.recording.channels[c], equal_nan=True) for c in plain)
                   for r in results[1:]), name  # each effect really acts


@pytest.mark.parametrize("noise_seed", [None, 7])
@pytest.mark.parametrize("rig, path, name, ratios", [
    ("quanser_2dsfl", "quanser_2dsfl/data_fsf_th11.mat", "link2_stiffness", [0.92, 0.96, 1.0, 1.02, 1.05, 1.08]),
    ("emps", "emps/DATA_EMPS.mat", "mass", [0.8, 0.9, 1.0, 1.1, 1.2, 1.25]),
    ("emps", "emps/DATA_EMPS.mat", "drive_gain", [0.98, 0.99, 1.0, 1.01, 1.015, 1.02]),  # an actuator gain (Patches)
    ("quanser_2dsfl_lab_lqg", "quanser_2dsfl/lab/lqg_step_20deg_run01.mat", "drive1_damping",
     [0.8, 0.9, 1.0, 1.1, 1.2, 1.25]),  # a lab's LQG (linear at 10 ms) beside state feedback (parallel), settled
])
def test_rigs_described_as_data_run_on_arrays_and_match_single_runs(built, rig, path, name, ratios, noise_seed):
    """columns.GenericColumns: a rig described as data (rigs/quanser_2dsfl.toml: link strains as hinge sums,
    state feedback through an Euler rate filter, current commands; rigs/emps.toml: cascade P with the 2-tap
    difference, a converter step; rigs/quanser_2dsfl_lab_lqg.toml: a lab's state space at 10 ms beside state
    feedback at 2 ms, from rest at -20 deg, where the law starts as it holds there) re-simulated in lockstep on arrays
    equals each re-simulated alone (2 s), with the rig's measurement noise off and on (the draws taken ahead in the
    single run's order)."""
    from pathlib import Path

    from watflex_sim.recording import read_recording
    from watflex_sim.resim import resimulate, resimulate_many
    from watflex_sim.rigdesc import load_rig

    description = load_rig(rig)
    rec = read_recording(Path(__file__).parent / "data" / path, sidecar=description.sidecar)
    together = resimulate_many([(rec, [], {name: r}, 2.0, noise_seed) for r in ratios], nthread=1, rig=description)
    assert len(built) == 1 and built[0] is not None
    for r, sim in zip(ratios, together):
        alone = resimulate(rec, [], {name: r}, until=2.0, noise_seed=noise_seed, rig=description)
        assert all(np.array_equal(sim.channels[c], alone.channels[c], equal_nan=True) for c in alone.channels), r


def test_members_started_at_rest_and_away_from_it_share_a_linear_law_on_arrays(built):
    """A batch may hold runs that start at the nominal pose (a linear law from zero) beside runs that start at rest
    elsewhere (`initial`: the law settled there, `Linear.settle`), as a diagnosis of a lab's cut files does: one column
    form for all (controllers/linear.py LinearColumns, parallel.py ParallelColumns: the lab's LQG at 10 ms beside
    state feedback at 2 ms), each member equal to its run alone, bit for bit, and the settled ones unlike the rest."""
    base = load_scenario("quanser_lab_lqg_step", ["duration_s=1.0"])
    away = [{**base, "initial": {"hub1": a, "link1": 0.0}} for a in (-0.2, 0.3)]
    results = _compare([base, {**base, "seed": 2}, *away])
    assert len(built) == 1 and built[0] is not None and list(built[0].settling) == [False, False, True, True]
    assert abs(results[2].recording.channels["hub1"][0] + 0.2) < 1e-3


def test_the_observer_and_its_friction_compensation_run_on_arrays_and_match_single_runs(built):
    """Observer.columns and FrictionCompensation.columns (controllers/): the two-joint observer with the qualified
    compensation at both joints (the benchmark's two-joint set-up, whose lockstep calls spent ~55 % of their time in
    each member's control half before), the rigid observer with members' poles unlike, and every other scheme with
    the members' slope factors unlike give each member its single run's numbers, bit for bit (the observer's Phi x is
    written out as sums in both drivers: a BLAS product sums in another order). A compensation around a controller
    with no column form (passivity) has none either, and runs apart."""
    from watflex_sim.controllers.friction_compensation import SCHEMES
    from watflex_sim.columns import ColumnControl
    from watflex_sim.engine import ControlLoop

    cases = [("watflex_observer_two_joint", [[], []]),
             ("watflex_observer_step", [["controller.rigid=true"], ["controller.rigid=true", "controller.a=[12.0]"]])]
    cases += [("watflex_observer_step", [[f"controller.compensation.scheme='{scheme}'", f"controller.compensation.k_s={k}"]
                                         for k in (250.0, 300.0)]) for scheme in SCHEMES if scheme != "qualified"]
    for name, sets in cases:
        built.clear()
        _compare([load_scenario(name, ["duration_s=1.5", f"seed={s}", *extra]) for s, extra in enumerate(sets, 1)])
        assert built and all(c is not None for c in built), (name, sets)
    assert not ColumnControl.fits([ControlLoop(load_scenario("watflex_passivity_trajectory", ["duration_s=0.1"]))])


def test_members_whose_sensors_read_other_joints_run_in_classes_on_arrays(built):
    """lockstep._alike: a two-joint recording re-simulated with a backlash added at the elbow and at the shoulder -
    models of one structure whose encoders read other coordinates, as a diagnosis' backlash and compliance probes
    are - runs as two batches on arrays, not as one on per-member control; every member equals its run alone."""
    from watflex_sim.resim import resimulate, resimulate_many

    rec = simulate(load_scenario("watflex_observer_two_joint", ["duration_s=1.2", "seed=4"])).recording
    jobs = [(rec, [{"effect": "backlash", "where": joint, "width": width, "position": 0.0}], {})
            for joint in ("elbow", "shoulder") for width in (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3)]
    together = resimulate_many(jobs, nthread=1)
    assert len(built) == 2 and all(c is not None for c in built)
    for job, sim in zip(jobs, together):
        alone = resimulate(*job)
        assert all(np.array_equal(sim.channels[c], alone.channels[c], equal_nan=True) for c in alone.channels), job[1]


def test_a_settled_start_kept_from_before_gives_the_same_recording():
    """engine._settle_bearings keeps the settled MjData of the last models it settled (by a digest of the whole
    model): a run that starts from that copy records what a run that settles again records, bit for bit, and
    another model (a payload) is settled anew, not given the first one's start."""
    import mujoco

    from watflex_sim import engine
    from watflex_sim.model import load_model

    model = load_model("watflex")
    states = []
    engine._SETTLED.clear()
    for _ in range(2):  # settled, then from the copy kept
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        mujoco.mj_forward(model, data)
        engine._settle_bearings(model, data)
        state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        states.append(state)
    assert len(engine._SETTLED) == 1 and np.array_equal(states[0], states[1])
    scenario = load_scenario("watflex_observer_two_joint", ["duration_s=1.2", "seed=3"])
    engine._SETTLED.clear()
    fresh = simulate(scenario).recording
    assert len(engine._SETTLED) == 1
    kept = simulate(scenario).recording
    assert all(np.array_equal(fresh.channels[c], kept.channels[c], equal_nan=True) for c in fresh.channels)
    simulate(load_scenario("watflex_observer_two_joint", ["duration_s=0.01", "payload_kg=0.5"]))
    assert len(engine._SETTLED) == 2


def test_latest_keeps_the_most_recently_used_within_its_limit():
    """latest.Latest (the cache of model specs, settled starts and residuals): with a limit of 10 bytes, a 4-byte and a
    6-byte value fit; a third of 4 bytes drops the least recently used - the 6-byte one once the 4-byte one was asked
    for again - and a value larger than the limit is not kept at all; None is a value, told from a missing key."""
    from watflex_sim.latest import Latest

    kept = Latest(10, lambda v: 0 if v is None else v.nbytes)
    kept.put("a", np.zeros(4, np.uint8))
    kept.put("b", np.zeros(6, np.uint8))
    assert len(kept) == 2 and kept.get("a") is not None  # "a" now the most recently used
    kept.put("c", np.zeros(4, np.uint8))
    assert "b" not in kept and "a" in kept and "c" in kept
    kept.put("d", None)
    assert "d" in kept and kept.get("d", "missing") is None and kept.get("e", "missing") == "missing"
    kept.put("huge", np.zeros(11, np.uint8))
    assert "huge" not in kept and len(kept) == 0  # everything went to make room, and it still did not fit
    kept.put("a", np.zeros(4, np.uint8))
    kept.put("a", np.zeros(8, np.uint8))  # replaced: its old size no longer counts
    assert len(kept) == 1 and kept.get("a").nbytes == 8


def test_a_model_spec_kept_from_before_compiles_to_the_same_model():
    """model.kept_spec keeps the spec a model generator built for a segment count, a model file parsed or a
    datasheet's model, and hands out copies: a model loaded from the copy is the one built anew (the first load,
    the kept specs cleared), byte for byte (mj_saveModel), and an edit of one copy (a payload) leaves the next one
    as it was."""
    import hashlib

    import mujoco

    from watflex_sim import model as models

    def digest(model):
        buffer = np.empty(mujoco.mj_sizeModel(model), np.uint8)
        mujoco.mj_saveModel(model, None, buffer)
        return hashlib.sha1(buffer.tobytes()).hexdigest()

    for rig, n in (("watflex", 7), ("laser_arm", 4), ("laser_arm", 0), ("quanser_2dsfl", 0)):
        models._SPECS.clear()
        built = digest(models.load_model(rig, n_segments=n))
        assert len(models._SPECS) == 1
        edited = digest(models.load_model(rig, n_segments=n, payload_kg=0.3))
        assert edited != built and digest(models.load_model(rig, n_segments=n)) == built
