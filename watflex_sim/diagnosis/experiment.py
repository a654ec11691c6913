"""The experiment that would decide: when several explanations fit the data alike, simulate each on a
menu of experiments the rig can run and propose the one whose predictions differ most, in noise units.

Contract: the menu is built from the recordings themselves, so it works for any rig: each recorded
experiment with its reference (or, open loop, its command) scaled x0.3 and x2 about its start, mirrored,
slowed to a third of its speed, and replaced by a sweep (a logarithmic chirp as far from the start as the
recorded signal went, from SWEEP_CYCLES cycles over the recording up to SWEEP_TOP of the control rate).
`propose_experiment` returns the proposal for the report, with the
scenario as a dict and how hard it drives the rig (`drive`: each command's peak and time at its limit, as
predicted under the chosen explanation: look before running it on a real rig); `to_toml` writes it as a scenario
file (`watflex-sim run FILE` runs it).
"""
from __future__ import annotations

import copy
import math

import numpy as np
from scipy.signal import chirp

from ..engine import SimulationError, simulate
from ..resim import scenario_from_recording
from .data import Data, Model
from .runner import held

VARIANTS = {"x0.3": (0.3, 1.0), "x2": (2.0, 1.0), "mirrored": (-1.0, 1.0), "3x slower": (1.0, 3.0),
            "as a sweep": (None, 1.0)}  # (scale, time stretch); scale None: a chirp of the signal's excursion
SWEEP_CYCLES = 2.0  # the sweep's lowest frequency: cycles over the recording's length
SWEEP_TOP = 0.05  # its highest: this share of the control rate (50 Hz at 1 ms). Steps excite a flexible arm's
# first mode only: a laser hub compliance and a softer beam that fit three steps alike (seed 71, laser_arm-31e8e2c7)
# differ by at most 0.5 x the noise on the other variants, by 1.5 x on a 1-50 Hz sweep of the step's size


def _variant(data: Data, i: int, scale: float | None, stretch: float) -> dict:
    """Recording i's experiment with its driving signals scaled about their first value (scale None: replaced
    by a sweep as far from it as they went) and stretched in time."""
    rec = data.recordings[i]
    scenario = scenario_from_recording(rec, data.rig)
    drive = set(data.rig.of_kind("reference")) | (set(data.rig.of_kind("command")) if scenario.get("command") else set())
    for key in ("reference", "command"):
        for signal in scenario.get(key) or []:
            if signal.get("kind") == "samples" and signal["channel"] in drive:
                v = np.asarray(signal["values"], float)
                v0 = v[np.isfinite(v)][0] if np.isfinite(v).any() else 0.0
                moved = (scale * (v - v0) if scale is not None
                         else _sweep(signal["time_s"], v, v0, float(scenario["control_period_s"])))
                signal["values"] = (v0 + moved).tolist()
                signal["time_s"] = (np.asarray(signal["time_s"]) * stretch).tolist()
    scenario["duration_s"] = float(scenario["duration_s"]) * stretch
    if scenario["initial_rate"] or data.rig.sensors != "generic":  # an experiment run on the rig starts at rest,
        # its links straight, whatever the recording caught (moving, or a load held): at its joints' first readings
        scenario["initial"] = {c: v for c, v in scenario["initial"].items() if c in data.rig.position_channels()}
        scenario["initial_rate"] = scenario["initial_acceleration"] = {}
    scenario["controller_state"] = {}  # and its controller as it starts
    return scenario


def _sweep(time_s: list, values: np.ndarray, start: float, control_period_s: float) -> np.ndarray:
    """A logarithmic sine chirp (starting at 0) with the largest excursion of `values` from `start` as its
    amplitude (their unit), from SWEEP_CYCLES over the recording to SWEEP_TOP of the control rate (1/control_period_s)."""
    t = np.asarray(time_s, float) - time_s[0]
    span = float(t[-1]) if t.size > 1 and t[-1] > 0 else 1.0
    low, high = SWEEP_CYCLES / span, SWEEP_TOP / control_period_s
    excursion = float(np.nanmax(np.abs(values - start))) if np.isfinite(values).any() else 0.0
    return excursion * chirp(t, low, span, max(high, 2.0 * low), method="logarithmic", phi=-90.0)  # from 0, no jump


def _simulate(job: tuple[dict, Model]) -> dict | None:
    """Channels of one scenario under one model (worker process), None if it diverges."""
    scenario, model = job
    scenario = copy.deepcopy(scenario)
    scenario["effects"], scenario["parameters"] = list(model.effects), dict(model.parameters)
    try:
        rec = simulate(scenario, rig=held().rig).recording
    except SimulationError:
        return None
    return {"time": rec.time, **rec.channels}


def _difference(a: dict, b: dict, noise: dict[str, float]) -> float:
    """Mean over channels of the RMS difference of two predictions, in units of each channel's noise."""
    values = []
    for c, sigma in noise.items():
        if c in a and c in b and sigma > 0:
            d = (np.asarray(a[c]) - np.asarray(b[c])) / sigma
            d = d[np.isfinite(d)]
            if d.size:
                values.append(float(np.sqrt(np.mean(d**2))))
    return float(np.mean(values)) if values else 0.0


def propose_experiment(data: Data, chosen: Model, alternatives: list[dict], runner=None) -> dict:
    """The menu item that best separates the chosen model from every alternative (largest smallest
    difference, in noise units), with the predicted difference of each alternative."""
    from .runner import Runner

    models = [chosen] + [Model(a["model"]["effects"], a["model"]["parameters"]) for a in alternatives]
    menu = [(f"{data.names[i]} {label}", _variant(data, i, *sv)) for i in range(len(data.recordings))
            for label, sv in VARIANTS.items()]
    jobs = [(scenario, m) for _, scenario in menu for m in models]
    runner = runner or Runner(data, 1)
    predictions = runner.map(_simulate, jobs)
    best, best_score, best_diffs = None, -math.inf, []
    for k, (label, scenario) in enumerate(menu):
        preds = predictions[k * len(models):(k + 1) * len(models)]
        if any(p is None for p in preds):
            continue
        i = next(j for j in range(len(data.recordings)) if label.startswith(data.names[j]))
        diffs = [_difference(preds[0], p, data.noise[i]) for p in preds[1:]]
        if min(diffs) > best_score:
            best, best_score, best_diffs = (label, scenario, preds[0]), min(diffs), diffs
    if best is None:
        return {"scenario": None, "separates": [], "expected_difference": "every menu experiment diverged under some explanation"}
    label, scenario, predicted = best
    names = [f"{alternatives[0]['instead_of']}"] + [f"{a['effect']} at {a['where']}" for a in alternatives]
    weak = "" if best_score >= 1.0 else (
        "; no experiment on the menu separates them by the noise: run it several times (the noise of their mean falls "
        "as one over the root of the runs) or design a richer one")
    return {
        "scenario": "discriminate.toml", "experiment": label, "separates": names,
        "expected_difference": ", ".join(f"{n}: {d:.1f} x the noise" for n, d in zip(names[1:], best_diffs))
        + f" (RMS over the channels recorded, against {names[0]}); the recorded experiments themselves separate them by "
        "less than the noise" + weak,
        "drive": drive_demand(predicted, data.rig.channels),
        "scenario_dict": scenario,
    }


def drive_demand(prediction: dict, channels: dict) -> str:
    """How hard a predicted run drives the rig, in words: each recorded command channel's peak against its limit
    (its unit) and the share of the run spent at the limit; "" if no command channel with a limit moves."""
    parts = []
    for c, spec in channels.items():
        if spec.get("kind") == "command" and spec.get("limit") and c in prediction:
            v = np.abs(np.asarray(prediction[c], float))
            v = v[np.isfinite(v)]
            peak, unit = (float(v.max()) if v.size else 0.0), spec.get("unit", "")
            if peak > 0:  # a command that never moves (a locked joint's) says nothing
                at = 100.0 * float(np.mean(v >= 0.999 * spec["limit"]))
                parts.append(f"{c} peaks at {peak:.3g} {unit} of its {spec['limit']:.3g} {unit} limit, "
                             f"at the limit {at:.0f} % of the run")
    return "; ".join(parts)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, np.floating, np.integer)):
        return repr(float(v)) if isinstance(v, (float, np.floating)) else str(int(v))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def to_toml(scenario: dict, comment: str = "") -> str:
    """A scenario dict as a TOML scenario file (top-level keys; tables and lists inline)."""
    from ..scenario import DEFAULTS

    lines = [f"# {line}" for line in comment.splitlines()]
    for key, value in scenario.items():
        if value is None or key not in DEFAULTS or key in ("effects", "parameters"):
            continue  # derived keys are not scenario-file keys; the rig runs without our effects
        lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"
