"""Write a diagnosis: report.json (recordings.md schema), before/after plots, a .rrd, the patched model."""
from __future__ import annotations

import json
import os
import uuid
from pathlib import Path

import mujoco
import numpy as np

from .effects import Patch, apply_effects, apply_parameters, knob_body_inertia
from .interrupts import staged
from .plot import plot_recording
from .recording import Recording
from .rigdesc import load_rig

MAX_PLOTS = 6  # recordings plotted (the first ones)


def parameter_values(rig: str, ratios: dict[str, float]) -> dict[str, dict]:
    """Refit parameters as ratio and, where the model holds it, value, unit and the quantity it is (e.g. EMPS
    mass in kg; the laser arm's `hub_inertia` scales the hub geom's mass, which sets the hub's inertia)."""
    description = load_rig(rig)
    spec = description.spec()
    model = spec.compile()
    out = {}
    for name, ratio in ratios.items():
        knob, target = description.parameter_knobs().get(name, (None, None))
        entry = {"ratio": ratio}
        if knob == "geom_mass":
            entry.update(value=float(spec.geom(target).mass) * ratio, unit="kg", quantity=f"mass of geom {target}")
            turning = geom_inertia_about_hinge(spec, model, target)
            if turning is not None:  # on a body that turns: the inertia that mass gives it, which is what the rig names
                entry.update(inertia=turning[1] * ratio, inertia_unit="kg m^2", inertia_about=f"joint {turning[0]}")
        elif knob == "damping":
            entry.update(value=float(model.dof_damping[model.joint(target).dofadr[0]]) * ratio, unit="N s/m or N m s/rad",
                         quantity=f"damping of joint {target}")
        elif knob == "armature":
            entry.update(value=float(model.dof_armature[model.joint(target).dofadr[0]]) * ratio, unit="kg m^2",
                         quantity=f"armature (reflected inertia) of joint {target}")
        out[name] = entry
    return out


def geom_inertia_about_hinge(spec: mujoco.MjSpec, model: mujoco.MjModel, geom: str) -> tuple[str, float] | None:
    """(hinge, the geom's own moment of inertia about that hinge's axis in kg m^2) where the geom's body turns on a
    hinge; None otherwise. `model` is `spec` compiled. The geom's share of its body's inertia is linear in its mass:
    the body's inertia about the axis (its principal inertia turned into the body frame, plus its mass times the
    squared distance of its centre of mass from the axis) with the geom's mass doubled (the `geom_mass` knob, x2),
    less that with the mass as it is."""
    def about_axis(m: mujoco.MjModel) -> tuple[str, float] | None:
        body = m.geom(geom).bodyid[0]
        hinges = [j for j in range(m.njnt) if m.jnt_bodyid[j] == body and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        if not hinges:
            return None
        axis, at = m.jnt_axis[hinges[0]], m.jnt_pos[hinges[0]]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, m.body_iquat[body])
        rot = rot.reshape(3, 3)
        inertia = rot @ np.diag(m.body_inertia[body]) @ rot.T
        d = m.body_ipos[body] - at
        return m.joint(hinges[0]).name, float(axis @ inertia @ axis + m.body_mass[body] * (d @ d - (d @ axis) ** 2))

    once = about_axis(model)
    if once is None:
        return None
    doubled, patch = spec.copy(), Patch()
    knob_body_inertia(patch, geom, 2.0)
    for edit in patch.spec_edits:
        edit(doubled)
    return once[0], about_axis(doubled.compile())[1] - once[1]


def patched_spec(rig: str, patch_spec: dict) -> mujoco.MjSpec:
    """The nominal model with the found physics' model changes and refit parameters applied.

    Friction found on a joint is written as its frictionloss (the break-away level); laws, sensor
    and actuator changes live in patch.json, which `watflex-sim run --patch` applies."""
    description = load_rig(rig)
    spec = description.spec()
    patch = Patch()
    apply_parameters(patch, patch_spec.get("parameters", {}), description.parameter_knobs())
    apply_effects(patch, patch_spec.get("effects", []))
    for edit in patch.spec_edits:
        edit(spec)
    for joint, changes in patch.friction_add.items():
        j = spec.joint(joint)
        if j is not None:
            j.frictionloss += max(changes.get(("positive", "alpha0"), 0.0), changes.get(("negative", "alpha0"), 0.0))
    return spec


def _atomic_write(path: Path, text: str) -> None:
    """Write through a temporary file created with mode 0666 & ~umask (as open() does), then rename."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_report(report: dict, recordings: list[Recording], directory: Path, rrd: bool = True) -> Path:
    """Write everything into `directory` (created); returns the report.json path.

    Files are written into a staging directory inside it and moved into place together at the
    end (interrupts.staged), so an error or Ctrl-C leaves the previous contents, never a part."""
    directory = Path(directory)
    sims = report.pop("sims")
    recordings = sims.get("measured", recordings)  # in the report's (canonical) order
    try:
        with staged(directory) as stage:
            _write_report(report, sims, recordings, stage, directory, rrd)
    finally:
        report["sims"] = sims
    return directory / "report.json"


def _write_report(report: dict, sims: dict, recordings: list[Recording], stage: Path, directory: Path,
                  rrd: bool) -> None:
    out = dict(report)
    out["refit_parameters"] = parameter_values(report["rig"], report["refit_parameters"])
    figures = []
    for i, (rec, name) in enumerate(zip(recordings, report["recordings"])):
        if i >= MAX_PLOTS:
            break
        png = stage / f"fit_{Path(name).stem}.png"
        plot_recording(rec, png, {"nominal model": sims["nominal"][i], "diagnosed model": sims["final"][i]},
                       title=f"{name}: measured (solid), nominal model (dashed), diagnosed model (dotted)")
        figures.append(png.name)
    out["figures"] = figures
    if rrd:
        from .rerun_log import log_run

        channels, units, time = {}, {}, recordings[0].time - recordings[0].time[0]
        first, unit_of = recordings[0], recordings[0].units()
        for label, rec in (("measured", first), ("nominal", sims["nominal"][0]), ("diagnosed", sims["final"][0])):
            for c, v in rec.channels.items():
                channels[f"{c}.{label}"] = np.interp(time, rec.time - rec.time[0], v)
                units[f"{c}.{label}"] = unit_of.get(c, "")
        log_run(time, channels, units, rrd_path=stage / "diagnosis.rrd", recording_name=f"diagnosis {report['recordings'][0]}")
        out["rrd"] = "diagnosis.rrd"
    proposal = out.get("proposed_experiment")
    if proposal and proposal.get("scenario_dict"):
        from .diagnosis.experiment import to_toml

        scenario = proposal.pop("scenario_dict")
        comment = (f"Proposed by `watflex-sim diagnose`: the experiment that best separates {', '.join(proposal['separates'])}.\n"
                   f"Predicted difference: {proposal['expected_difference']}.\n"
                   + (f"Predicted drive: {proposal['drive']}.\n" if proposal.get("drive") else "")
                   + "Run it on the rig (the reference below), "
                   "or simulate it: watflex-sim run THIS_FILE --out DIR")
        _atomic_write(directory / "discriminate.toml", to_toml(scenario, comment))
        proposal["scenario"] = str(directory / "discriminate.toml")
        out["proposed_experiment"] = proposal
    spec = patched_spec(report["rig"], report["patch"])
    _atomic_write(stage / "patched_model.xml", spec.to_xml())
    _atomic_write(stage / "patch.json", json.dumps(report["patch"], indent=2) + "\n")
    out["patched_model"] = str(directory / "patched_model.xml")
    _atomic_write(stage / "report.json", json.dumps(_strict(out), indent=2, default=float, allow_nan=False) + "\n")


def _strict(value):
    """`value` with NaN and infinities as null (strict JSON readers reject NaN)."""
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value

def summary(report: dict) -> str:
    """The human summary printed by `watflex-sim diagnose`."""
    lines = [f"rig {report['rig']}: {len(report['recordings'])} recording(s)",
             f"nominal model: NRMSE {report['fit_before']['nrmse']:.4f}, correlation {report['fit_before']['correlation']:.4f}"]
    for w in report["mismatch"][:3]:
        lines.append(f"  mismatch: {w['channel']} in {w['recording']} {w['t_start']:.2f}-{w['t_end']:.2f} s "
                     f"({w['regime']}), {w['score']:.2f} of its spread")
    if report["refit_parameters"]:
        lines.append("refit within tolerance: " + ", ".join(f"{k} x{v:.4f}" for k, v in report["refit_parameters"].items()))
    lines.append(f"verdict: {report['verdict'].replace('_', ' ')} - {report['verdict_reason']}")
    for i, f in enumerate(report["findings"], 1):
        lines.append(f"finding {i}: {f['effect']} at {f['where']} ({f['direction']}): {f['explanation']}")
        for k, (lo, hi) in f.get("intervals", {}).items():
            lines.append(f"  {k}: {f['parameters'][k]:.4g} {f['units'].get(k, '')}, 95 % interval [{lo:.4g}, {hi:.4g}]")
        lines.append(f"  evidence: {f['evidence']}")
    for a in report.get("alternatives", []):
        lines.append(f"alternative to {a['instead_of']}: {a['effect']} at {a['where']} - {a['why_not_chosen']}")
    proposal = report.get("proposed_experiment")
    if proposal and proposal.get("scenario"):
        lines.append(f"experiment that would decide: {proposal['experiment']} ({proposal['expected_difference']}); "
                     f"scenario {proposal['scenario']}" + (f"; predicted drive: {proposal['drive']}" if proposal.get("drive") else ""))
    if report["verdict"] == "unexplained":
        for w in report["residual"]["where"][:3]:
            lines.append(f"  residual left: {w['channel']} in {w['recording']} {w['t_start']:.2f}-{w['t_end']:.2f} s "
                         f"({w['regime']}), {w['noise_ratio']:.1f} x its noise, dominant {w['frequency_hz']:.1f} Hz")
        for b in report["residual"]["parameters_at_bounds"]:
            lines.append(f"  at its tolerance bound: {b['parameter']} x{b['ratio']:.4f} (tolerance +-{100 * b['tolerance']:.0f} %)")
    for r in report.get("rejected", []):
        if r.get("train_gain", 0) > 0 and r.get("held_out_gain", 0) > 0:
            lines.append(f"below the bar: {r['effect']} at {r['where']} improves training by {100 * r['train_gain']:.1f} % "
                         f"and validation by {100 * r['held_out_gain']:.1f} %: {r['why']}")
    ho = report["held_out"]
    lines.append(f"validation NRMSE {ho['before']['nrmse']:.4f} -> {ho['after']['nrmse']:.4f}, "
                 f"{ho['before']['noise_ratio']:.2f} -> {ho['after']['noise_ratio']:.2f} x the noise ({ho['how']})")
    lines.append(f"all data: NRMSE {report['fit_before']['nrmse']:.4f} -> {report['fit_after']['nrmse']:.4f}, "
                 f"correlation {report['fit_before']['correlation']:.4f} -> {report['fit_after']['correlation']:.4f}")
    noise = report.get("noise", {})
    if noise.get("fidelity", 1.0) != 1.0:
        lines.append(f"simulated {noise['fidelity']:g} x as fine as the rig's model (segments, step): within "
                     f"{noise['coarse_error']:.2f} x the noise of its own on every channel")
    if report.get("timing"):
        lines.append("time: " + ", ".join(f"{k} {v['seconds']:.0f} s ({v['jobs']} jobs)" for k, v in report["timing"].items()))
    return "\n".join(lines)
