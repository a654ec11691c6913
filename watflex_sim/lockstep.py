"""Many simulations in lockstep: B scenarios of one rig stepped together on `mujoco.batch.Batch`.

One physics, two drivers: each scenario is set up by `engine.ControlLoop` and runs its control
half (`ControlLoop.control`: sensors, controller, converters, saturation, effects) on its own
objects, which read and write rows of the batch's live arrays; the physics of all of them is one
`Batch.step` per physics step, with the joint friction computed for the whole batch on arrays
between steps (joint_friction.BatchFriction) instead of a per-simulation passive callback.
Scenarios whose models differ in structure (segments, locked joints, added bodies or joints) run
in separate batches; within one, the model fields that differ are per-simulation (`expand`). A
group too small for a batch to pay (`_pays`) runs on the single-run driver (engine.run), one by one.
"""
from __future__ import annotations

import logging
import time as wallclock

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from .engine import CHECK_EVERY, MAX_QVEL, ControlLoop, SimResult, SimulationError, Tape, run
from .columns import ColumnControl
from .joint_friction import BatchFriction
from .rigdesc import RigDescription

log = logging.getLogger(__name__)

LOCKSTEP_LEAST = 8  # simulations of one structure below which the single-run driver is cheaper
LOCKSTEP_PER_CALL = 3  # ... and per Batch.step call a tick (_pays)
COLUMNS_LEAST, COLUMNS_PER_CALL = 6, 1  # the same where the control half runs on arrays (columns.py)
_ROWS = ("qpos", "qvel", "ctrl", "xpos", "site_xpos", "sensordata")  # the MjData fields rigs and the loop touch
_SIZES = ("nq", "nv", "nu", "na", "nbody", "njnt", "ngeom", "nsite", "nsensordata", "neq", "ntendon",
          "nmocap", "nuserdata", "nM", "nD", "nB", "nC", "nJmom", "nbvh", "nbvhstatic", "nbvhdynamic", "npair",
          "nexclude", "nplugin", "nhistory")


class _Rows:
    """One simulation's rows of the batch's arrays under MjData's names (a rig's `data`)."""

    def __init__(self, arrays: dict[str, np.ndarray], i: int):
        for name, array in arrays.items():
            setattr(self, name, array[i])


def structure(model: mujoco.MjModel) -> tuple:
    """What must be equal for two models to share a batch: the sizes MjData is laid out by."""
    return tuple(getattr(model, n, 0) for n in _SIZES)


def simulate_batch(scenarios: list[dict], parameter_names: dict | None = None,
                   nthread: int = 0, rig: RigDescription | None = None, always: bool = False) -> list[SimResult | SimulationError]:
    """Run checked scenarios (scenario.load_scenario) of one or more rigs in lockstep; nthread 0: all CPUs;
    `rig`: the scenarios' rig, loaded (else each is loaded by its scenario's name). A structure's group
    runs one by one on the single-run driver where a batch would not pay (`_pays`), unless `always`
    (any group of two or more in lockstep: the tests that compare the drivers).

    Returns per scenario its SimResult (recording identical to `engine.simulate`'s, see
    tests/test_lockstep.py) or the SimulationError that stopped it (the others go on).
    Raises ConfigError for an impossible configuration, before anything runs.
    """
    loops = [ControlLoop(s, parameter_names, rig) for s in scenarios]
    groups: dict[tuple, list[int]] = {}
    for i, loop in enumerate(loops):
        groups.setdefault((structure(loop.model), loop.n_sub), []).append(i)
    out: list = [None] * len(loops)
    for group in groups.values():
        columnar = [i for i in group if ColumnControl.fits([loops[i]])]  # a member whose control half has no
        apart = [i for i in group if i not in columnar]  # column form runs apart, not the whole group
        for members in _alike(loops, columnar) + [apart]:
            if not members:
                continue
            if len(members) == 1 or not (always or _pays([loops[i] for i in members])):  # the single-run driver
                for i in members:  # is cheaper here (same recordings)
                    out[i] = _alone(loops[i])
                continue
            for i, result in zip(members, _Lockstep([loops[i] for i in members], nthread).run()):
                out[i] = result
    return out


def _alike(loops: list[ControlLoop], members: list[int]) -> list[list[int]]:
    """`members` (loops of one structure, each with a column form) in classes that share one: a hinge added at the
    shoulder and one added at the elbow make models of one structure whose sensors read other joints (a diagnosis'
    backlash and compliance probes, which all ran on per-member control while they shared a batch)."""
    classes: list[list[int]] = []
    for i in members:
        home = next((c for c in classes if ColumnControl.fits([loops[c[0]], loops[i]])), None)
        if home is None:
            classes.append([i])
        else:
            home.append(i)
    return classes


def _pays(loops: list[ControlLoop]) -> bool:
    """Whether stepping these loops (one structure) in lockstep costs less than running them one by one:
    a batch pays a fixed cost per Batch.step call and tick (the call, the array friction's numpy work),
    and with joint friction or jitter it makes one call per physics step, not one per tick. Measured
    (tools/bench.py section 6; 1 s re-simulations, lockstep / single-run time, both cores busy, +-20 %): Watflex (2 calls a tick)
    1.56 / 1.09 / 0.83 / 0.56 at B = 2 / 4 / 8 / 16; the laser arm with hub friction (10 calls) 1.8-2.0 at
    B = 4-8, 1.02 at 16, 0.75 at 32; without friction (1 call) 0.90-0.93 at 16-32."""
    substepped = any(loop.friction.joints for loop in loops) or any(loop.delays is not None for loop in loops)
    calls = loops[0].n_sub if substepped else 1  # Batch.step calls per tick
    if ColumnControl.fits(loops):
        return len(loops) >= max(COLUMNS_LEAST, COLUMNS_PER_CALL * calls)
    return len(loops) >= max(LOCKSTEP_LEAST, LOCKSTEP_PER_CALL * calls)


def _alone(loop: ControlLoop) -> SimResult | SimulationError:
    try:
        return run(loop)
    except SimulationError as exc:
        return exc


class _Lockstep:
    """One batch of loops whose models share a structure."""

    def __init__(self, loops: list[ControlLoop], nthread: int):
        self.loops = loops
        first = loops[0].model
        self.batch = batch = mjbatch.Batch(first, len(loops), nthread=nthread)
        for field in sorted(mjbatch.MODEL_FIELDS):  # per-simulation values where the models differ
            values = [_model_field(loop.model, field) for loop in loops]
            if values[0] is None:
                continue
            stacked = np.array(values)
            if (stacked == stacked[0]).all():
                continue
            batch.expand(field)[:] = stacked.reshape(batch.expand(field).shape)
        friction = [loop.friction for loop in loops]
        self.friction = None
        if any(f.joints for f in friction):
            self.friction = BatchFriction(friction, batch.expand("dof_frictionloss"), first.nv)
        n_state = mujoco.mjtState.mjSTATE_INTEGRATION
        for i, loop in enumerate(loops):  # each set-up state (settled, at its initial values) into its row
            mujoco.mj_getState(loop.model, loop.data, batch.state[i], n_state)
        self.qpos, self.qvel, self.ctrl = batch.bind("qpos"), batch.bind("qvel"), batch.bind("ctrl")
        self.bound_applied = batch.bind("qfrc_applied")
        self.constraint = np.array([loop.data.qfrc_constraint for loop in loops])  # from each set-up forward
        self.bound_constraint = batch.bind("qfrc_constraint")
        self.applied = self.bound_applied.copy()  # what rigs apply (disturbances); friction is added to it
        arrays = {"qpos": self.qpos, "qvel": self.qvel, "ctrl": self.ctrl, "xpos": batch.bind("xpos"),
                  "site_xpos": batch.bind("site_xpos"), "qfrc_applied": self.applied,
                  # MuJoCo's sensors (an accelerometer): each set-up's for the first tick (not in the state), then
                  # the batch's (read-only) copied after each tick's physics
                  "sensordata": np.array([loop.data.sensordata for loop in loops])}
        self.sensordata = arrays["sensordata"]
        self.bound_sensordata = batch.bind("sensordata") if first.nsensordata else None
        self.disturbed = any(getattr(loop.rig, "_disturbances", None) for loop in loops)
        self.jittered = any(loop.delays is not None for loop in loops)  # commands due within a tick
        self.substepped = self.friction is not None or self.jittered  # one Batch.step per physics step
        tip = mujoco.mj_name2id(first, mujoco.mjtObj.mjOBJ_SITE, "tip")
        for i, loop in enumerate(loops):
            rows = _Rows(arrays, i)
            loop.data = loop.rig.data = rows
            if tip >= 0:
                loop.rig._tip_xpos = rows.site_xpos[tip]
        batch.forward(stage=mujoco.mjtStage.mjSTAGE_POS)  # positions for the first sensors and frames
        self.columns = ColumnControl.of(loops, arrays, tip)  # the control half on arrays, where it has that form

    def run(self) -> list[SimResult | SimulationError]:
        loops, batch, columns = self.loops, self.batch, self.columns
        tapes = [Tape(loop) for loop in loops]
        n_sub = loops[0].n_sub
        failed: dict[int, SimulationError] = {}
        ends = {loop.n_ticks for loop in loops}
        reads = {(loop.rig.positions_every, tape.frame_every) for loop, tape in zip(loops, tapes)}
        live, ids, dropped = list(range(len(loops))), None, 0
        start = wallclock.perf_counter()
        for k in range(max(ends)):
            if k in ends or len(failed) != dropped:  # members that ended or failed leave the batch
                live = [i for i, loop in enumerate(loops) if k < loop.n_ticks and i not in failed]
                ids, dropped = (np.array(live) if len(live) < len(loops) else None), len(failed)
            if not live:
                break
            if any(k % every == 0 for _, every in reads):
                for i in live:
                    tapes[i].frame(k)
            if columns is not None:
                columns.tick(k)
            else:
                for i in live:
                    tapes[i].write(k, *loops[i].control(k))
            # positions after the tick (engine: mj_kinematics) only where the next tick reads them
            positions = any((every and (k + 1) % every == 0) or (k + 1) % frames == 0 for every, frames in reads)
            for j in range(n_sub):
                self._forces()
                if self.jittered:  # a command due at substep j reaches its plant now
                    for i in live:
                        loops[i].release(j)
                last = j == n_sub - 1 or not self.substepped
                try:
                    batch.step(ids, nstep=1 if self.substepped else n_sub,
                               stage=mujoco.mjtStage.mjSTAGE_POS if last and positions else mujoco.mjtStage.mjSTAGE_NONE)
                except mjbatch.SimulationError as exc:
                    for i in exc.ids:
                        failed[int(i)] = SimulationError(f"simulation failed (at t = {k * loops[i].period:.3f} s): "
                                                         f"{batch.error(int(i))}; nothing was written")
                    live = [i for i in live if i not in failed]
                    ids = np.array(live)
                if self.friction is not None:
                    self.constraint[:] = self.bound_constraint
                if last:
                    break
            if self.bound_sensordata is not None:
                self.sensordata[:] = self.bound_sensordata
            if columns is not None:
                columns.growth.update(k, live, failed)
            else:
                for i in live:
                    try:
                        loops[i].monitor.update(loops[i].data, k)
                    except SimulationError as exc:
                        failed[i] = exc
            if k % CHECK_EVERY == CHECK_EVERY - 1 or k + 1 in ends:
                self._check(live, k, failed)
        wall = (wallclock.perf_counter() - start) / len(loops)  # s per simulation
        for i, exc in failed.items():
            log.info("%s dropped from its batch: %s", loops[i].scenario["name"], exc)
        if columns is not None:
            for i, (loop, tape) in enumerate(zip(loops, tapes)):
                tape.table = columns.member_table(i, loop.n_ticks)
        return [failed.get(i) or tape.result(wall) for i, tape in enumerate(tapes)]

    def _forces(self) -> None:
        """Friction (levels and torques) and the rigs' applied forces for the coming physics step."""
        if self.friction is not None:
            torque = self.friction.step(self.qpos, self.qvel, self.constraint)
            np.add(self.applied, torque, out=self.bound_applied)
        elif self.disturbed:
            self.bound_applied[:] = self.applied

    def _check(self, live: list[int], k: int, failed: dict) -> None:
        """engine._check_state for the whole batch: MuJoCo warnings, velocity not finite or too large."""
        warned = self.batch.warning.reshape(len(self.loops), -1).any(axis=1)
        speed = np.einsum("ij,ij->i", self.qvel, self.qvel)
        for i in live:
            if i in failed or k >= self.loops[i].n_ticks:
                continue
            if warned[i] or not speed[i] < MAX_QVEL**2:
                t = (k + 1) * self.loops[i].period
                cause = "a MuJoCo warning" if warned[i] else f"velocity not finite or above {MAX_QVEL:g}"
                failed[i] = SimulationError(f"simulation diverged (detected at t = {t:.3f} s): {cause}; "
                                            "try a smaller timestep or lower gains; nothing was written")


def _model_field(model: mujoco.MjModel, field: str):
    """An MjModel field by its Batch name ('opt.timestep' for an option), as an array; None if absent."""
    owner, name = (model.opt, field[4:]) if field.startswith("opt.") else (model, field)
    value = getattr(owner, name, None)
    return None if value is None else np.asarray(value)
