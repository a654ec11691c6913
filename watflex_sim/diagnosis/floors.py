"""The noise floors a model is judged by, beyond the recordings' own noise: noise correlated by a sensor's filter,
what the rig's noise leaves in closed loop, what our own discretisation leaves.

Contract: `add_coloured_noise`, `add_closed_loop_noise` and `add_discretisation_error` raise `data`'s floors from a
model's simulations; `calibrate_noise` simulates what they need and adds them for a model (the refit nominal one);
`raise_noise_floor` measures them again with a model's findings in and raises each floor they exceed by more than
RAISED; `floors_after_dropping` sets the floors a model left after elimination is judged by (the nominal model's
FLOORS, raised again with the findings kept). Those that simulate tell the progress through `say(kind, message)`.
"""
from __future__ import annotations

import math
from copy import deepcopy
from dataclasses import replace

import numpy as np

from ..recording import Recording
from .data import Data, Model
from .noise import PLATEAU, coloured_noise, measured_noise, quantised
from .runner import Runner
from .uncertainty import FINER, NOISE_SEED

FLOORS = ("noise", "closed_loop_sq", "discretisation_sq", "discretisation")  # the Data fields raise_noise_floor raises
RAISED = 1.1  # raise_noise_floor raises a channel's floor measured again with the findings only beyond this factor
# (a noise ratio 10 % lower: within what the floor's own estimate moves by, and the rest of the diagnosis unchanged)


def add_coloured_noise(data: Data, sims: list[Recording]) -> list[str]:
    """Raise each measured channel's noise, and its `sensor_noise`, to the coloured_noise of its residual against
    `sims` (a model, noise off) where that is more than PLATEAU x larger (what the estimates scatter by): the
    recording's noise measured where the model has taken the motion away. prepare's estimate reads noise correlated
    over a few samples (a real sensor's filter) as less than it is, and nothing in the catalogue is made of that
    shortfall. Commands are left to add_closed_loop_noise (the controller's answer to the noise), quantised channels
    (QUANTUM_SHARE) to measured_noise. Returns "recording: channel xfactor" of each raised."""
    data.sensor_noise = [dict(n) for n in data.sensor_noise]  # raise_noise_floor's scratch shares the list
    measured, raised = set(data.rig.of_kind("measured")), []
    for i, (rec, sim) in enumerate(zip(data.recordings, sims)):
        for c in (c for c in data.channels[i] if c in measured):
            residual = np.asarray(sim.channels[c]) - np.asarray(rec.channels[c])
            finite = np.isfinite(residual)  # a slower sensor's samples (the 25 Hz camera) are its own spacing apart
            if finite.sum() < 3:
                continue
            noise = coloured_noise(residual[finite], float(np.median(np.diff(rec.time[finite]))))
            if (noise > PLATEAU * data.sensor_noise[i][c]  # then whether quantised: the step's rms error, its unit
                    and not quantised(rec.channels[c], noise)):
                raised.append(f"{data.names[i]}: {c} x{noise / data.sensor_noise[i][c]:.2f}")
                data.sensor_noise[i][c] = noise
                data.noise[i][c] = max(data.noise[i][c], noise)
    return raised


def add_closed_loop_noise(data: Data, clean: list[Recording], noisy: list[Recording]) -> None:
    """Raise each channel's noise to what the rig's measurement noise alone leaves in closed loop: the
    RMS difference between the model simulated with its noise on and off. Fed back through the
    controller, sensor noise moves the rig itself (with stick-slip, where a joint comes to rest), so a
    perfect model is off by more than the sensor noise; open loop, this is the sensor noise. The rig
    description's noise model is checked against the recording: where the simulated channel jitters
    more than the recorded one (its measured_noise), the floor is scaled down by that ratio (a white
    noise declared on an encoder that is really quantised would otherwise pass through a velocity loop
    as volts of jitter the recording does not have, and hide real misfits). Kept per sample too
    (`data.closed_loop_sq`, scaled alike)."""
    data.closed_loop_sq = [{} for _ in data.recordings]
    for i, (rec, a, b) in enumerate(zip(data.recordings, clean, noisy)):
        for c in data.channels[i]:
            every = np.asarray(b.channels[c]) - np.asarray(a.channels[c])
            d = every[np.isfinite(every)]
            if d.size:
                simulated, recorded = measured_noise(np.asarray(b.channels[c])), measured_noise(rec.channels[c])
                scale = min(1.0, recorded / simulated) if simulated > 0 else 1.0
                data.closed_loop_sq[i][c] = np.nan_to_num(scale * every) ** 2
                data.noise[i][c] = max(data.noise[i][c], scale * float(np.sqrt(np.mean(d**2))))


def add_discretisation_error(data: Data, ours: list[Recording], finer: list[Recording]) -> None:
    """Raise each channel's noise floor by what the simulator's own discretisation leaves: the RMS
    difference between the model simulated as it is and `finer` (resim.finer_discretisation), added in
    quadrature (independent of the measurement noise). Another implementation of the same datasheet
    differs from ours by at least our own discretisation error, and a real rig by that and more: no
    finding should be made of it. Measured on 6 s Watflex elbow steps (12 segments at 0.5 ms): against
    twice as fine, strain_2A 3.1-3.4 x its noise, the elbow encoder 3.0 x (the 0.1 rad staircase: 0.9 x and
    1.7 x); against four times as fine 4.0-4.2 x and 3.6-4.8 x (so a factor 2 is a lower bound); laser arm
    0.02-0.06 x. The added part is kept per recording and channel in `data.discretisation` (the report's
    noise table), and per sample, squared, in `data.discretisation_sq`."""
    data.discretisation = [{} for _ in data.recordings]
    data.discretisation_sq = [{} for _ in data.recordings]
    for i, (a, b) in enumerate(zip(ours, finer)):
        for c in data.channels[i]:
            every = np.asarray(b.channels[c]) - np.asarray(a.channels[c])
            d = every[np.isfinite(every)]
            if d.size:
                error = float(np.sqrt(np.mean(d**2)))
                data.discretisation[i][c] = error
                data.discretisation_sq[i][c] = np.nan_to_num(every) ** 2
                data.noise[i][c] = math.hypot(data.noise[i][c], error)


def raise_coloured_noise(data: Data, sims: list[Recording], say) -> list[str]:
    """add_coloured_noise on the residual of `sims`, the progress told of each floor raised; returns them."""
    raised = add_coloured_noise(data, sims)
    if raised:
        say("noise", "noise correlated over a few samples (a sensor's filter), more than its samples' differences "
                     f"show: floors raised ({', '.join(raised)})")
    return raised


def calibrate_noise(data: Data, runner: Runner, model: Model, sims: list[Recording], say) -> None:
    """Add to `data` the recordings' noise correlated over a few samples (add_coloured_noise, on the residual
    of `sims`, `model`'s), what the rig's noise leaves in closed loop (`model` simulated with noise on) and, where
    a finer discretisation exists, what it changes (add_closed_loop_noise, add_discretisation_error)."""
    raise_coloured_noise(data, sims, say)
    say("noise", "simulating the refit model with the rig's noise on: what noise alone leaves in closed loop")
    noisy = runner.simulate(model, noise_seed=NOISE_SEED)
    if noisy is not None:
        add_closed_loop_noise(data, sims, noisy)
    if runner.refinable(FINER):
        say("noise", f"simulating the refit model {FINER} x finer (segments, step): what our own discretisation leaves")
        finer = runner.simulate(model, finer=FINER)
        if finer is not None:
            add_discretisation_error(data, sims, finer)


def raise_noise_floor(data: Data, runner: Runner, model: Model, sims: list[Recording], say) -> list[str]:
    """Measure again what the rig's noise leaves in closed loop and what a finer discretisation changes, with `model`
    (calibrate_noise from the recordings' own noise, `data.sensor_noise`), and raise to it each channel's floor that it
    exceeds by more than RAISED (its per-sample floors too). The floor was measured with the refit nominal model; a
    finding that makes the loop hunt or stick can make it far more sensitive to noise and step: seed 75's
    laser_arm-214f6418, a hub backlash of 1.234e-4 rad in closed loop, raised the tip sensor's floor 12 x (0.0101 to
    0.1205 V): by the old floor the truth was 6.2 x the noise and a spurious beam damping x6.2 earned its place beside
    the backlash found (1.28 x); by the new, the truth is 1.03 x and the backlash found 1.27 x. Returns "recording:
    channel xfactor" of each floor raised."""
    scratch = replace(data, noise=[dict(n) for n in data.sensor_noise])
    calibrate_noise(scratch, runner, model, sims, lambda *a: None)
    raised = []
    for i, name in enumerate(data.names):
        for c in data.channels[i]:
            if scratch.noise[i][c] <= RAISED * data.noise[i][c]:
                continue
            raised.append(f"{name}: {c} x{scratch.noise[i][c] / data.noise[i][c]:.2g}")
            data.noise[i][c] = scratch.noise[i][c]
            for kind in FLOORS[1:]:  # the per-sample floors and the discretisation part
                mine, new = getattr(data, kind), getattr(scratch, kind)
                if new and c in new[i]:
                    if not mine:
                        setattr(data, kind, mine := [{} for _ in data.names])
                    mine[i][c] = np.maximum(mine[i].get(c, 0.0), new[i][c])
    if raised:
        say("noise", "with the findings in, noise and step leave more: floors raised (" + ", ".join(raised) + ")")
    return raised


def floors_after_dropping(data: Data, runner: Runner, model: Model, sims: list[Recording], nominal: dict, say) -> None:
    """Set the floors `model`, left after elimination dropped findings, is judged by: the nominal model's (`nominal`,
    the FLOORS fields as calibrate_noise left them), raised again by what noise and step leave with the findings kept
    (raise_noise_floor; none kept: the nominal model's as they were, no simulation). A floor raised by a dropped
    finding's hunting would otherwise judge the rest by a noise their model does not make."""
    for name, floor in deepcopy(nominal).items():
        setattr(data, name, floor)
    if model.effects:
        raise_noise_floor(data, runner, model, sims, say)
