"""Discretisation convergence and time-step stability of the flexible-beam chains.

Usage: python tools/convergence.py [--skip-stability] [--skip-effects]

Prints markdown tables (headless, a few tens of seconds on 2 cores):
1. error (%) of the first three clamped-free bending frequencies and of the static tip
   deflection vs. the number of segments N, for the laser beam (tip mass 0.15 kg) and Watflex
   link 2 (tip mass 8.1 kg), with hinges at segment midpoints (the project's scheme,
   watflex_sim.build.add_flexible_chain) and, for comparison, with hinges at element ends
   (N full segments, the first hinge at the root, k = EI/dx);
2. which physics time steps run 2 s of free vibration from a 1 cm static tip deflection
   without divergence, per integrator, for the nominal laser arm (hub free) and Watflex
   (both joints free), nominal damping, no input;
3. how the catalogue's extra-hinge effects (effects.backlash, effects.joint_compliance) converge with N: a closed-loop
   step (laser_arm_step at the hub, watflex_elbow_step at the elbow, `--duration` s, noise off, a physics step half
   the model's) simulated with the effect at N segments: its rms distance from the same at N = 30 in units of the
   effect's size there (the rms change it makes at N = 30), beside the nominal model's own distance; and the rms
   change the effect makes over the run's second half at N against that at N = 30 (its amplitude, whatever its
   phase: a backlash keeps a closed loop hunting, whose phase drifts with any difference while its amplitude
   converges).

Reference values: watflex_sim.beam_theory (clamped_free_frequencies, tip_deflection).
Modes come from the linearised chain: K = diag(hinge stiffness), M = mj_fullM on the chain
dofs, generalised eigenproblem K v = w^2 M v.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mujoco
import numpy as np
import scipy.linalg

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from watflex_sim.beam_theory import clamped_free_frequencies, tip_deflection  # noqa: E402
from watflex_sim.build import add_flexible_chain, chain_tip_x  # noqa: E402
from watflex_sim.engine import SimulationError, _check_state, _settle_bearings, energy, simulate  # noqa: E402
from watflex_sim.model import load_model  # noqa: E402
from watflex_sim.params import CONTROL_PERIOD, LASER_ARM, WATFLEX  # noqa: E402
from watflex_sim.scenario import load_scenario  # noqa: E402

MIDPOINT_N = (3, 5, 7, 9, 11, 12, 15, 21)  # segments, hinges at segment midpoints
END_HINGE_N = (5, 11, 21, 45, 90)  # segments, hinges at element ends
TIMESTEPS_MS = (0.05, 0.1, 0.2, 0.5, 1.0)  # physics time steps tried (ms)
INTEGRATORS = {
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "RK4": mujoco.mjtIntegrator.mjINT_RK4,
    "Euler": mujoco.mjtIntegrator.mjINT_EULER,
}
BEAMS = (  # (label, beam, tip mass kg)
    ("laser beam, tip 0.15 kg", LASER_ARM.beam, LASER_ARM.tip_sensor_mass),
    ("Watflex link 2, tip 8.1 kg", WATFLEX.link2, WATFLEX.end_effector_mass),
)


def _add_tip(body, x: float, tip_mass: float) -> None:
    """A point mass (kg, 0.1 mm sphere) and the site `tip` at x (m) along the body's x axis."""
    if tip_mass > 0:
        g = body.add_geom(name="tip_mass", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[1e-4, 0, 0], pos=[x, 0, 0])
        g.mass = tip_mass
        g.contype = g.conaffinity = 0
    body.add_site(name="tip", pos=[x, 0, 0])


def midpoint_cantilever(beam, n: int, tip_mass: float) -> mujoco.MjModel:
    """The project's chain (hinges at segment midpoints) clamped on a fixed body, no gravity."""
    spec = mujoco.MjSpec()
    spec.option.gravity = [0, 0, 0]
    tip = add_flexible_chain(spec.worldbody.add_body(name="clamp"), "beam", beam, n, 0.0)
    _add_tip(tip, chain_tip_x(beam, n), tip_mass)
    return spec.compile()


def end_hinge_cantilever(beam, n: int, tip_mass: float) -> mujoco.MjModel:
    """Hinges at element ends: n full rigid segments of length dx = L/n, hinge i at (i-1) dx
    (the first at the clamp), stiffness EI/dx (N m/rad); the tip mass at x = L."""
    dx = beam.length / n
    spec = mujoco.MjSpec()
    spec.option.gravity = [0, 0, 0]
    body = spec.worldbody.add_body(name="clamp")
    pos = [0.0, 0, 0]
    for i in range(1, n + 1):
        body = body.add_body(name=f"beam_seg{i:02d}", pos=pos)
        j = body.add_joint(name=f"beam_j{i:02d}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
        j.stiffness = [beam.EI / dx, 0, 0]
        g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[dx / 2, beam.thickness / 2, beam.height / 2], pos=[dx / 2, 0, 0])
        g.mass = beam.mass_per_length * dx
        pos = [dx, 0, 0]
    _add_tip(body, dx, tip_mass)
    return spec.compile()


def chain_dofs(model: mujoco.MjModel, prefix: str) -> np.ndarray:
    """Dofs of the joints `{prefix}_jNN`, root to tip."""
    joints = sorted((model.joint(j).name, j) for j in range(model.njnt) if model.joint(j).name.startswith(f"{prefix}_j"))
    return np.array([model.jnt_dofadr[j] for _name, j in joints])


def chain_modes(model: mujoco.MjModel, dofs: np.ndarray, n_modes: int = 3) -> np.ndarray:
    """First natural frequencies (rad/s) of the linearised chain about the straight pose."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    stiffness = np.diag(model.jnt_stiffness[model.dof_jntid[dofs]])
    w2 = scipy.linalg.eigh(stiffness, mass[np.ix_(dofs, dofs)], eigvals_only=True)
    return np.sqrt(w2[:n_modes])


def static_tip(model: mujoco.MjModel, dofs: np.ndarray, force: float = 1.0) -> float:
    """Tip deflection (m) of the linear statics K q = J^T F for a force F (N) at the site `tip`."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, model.site("tip").id)
    q = jac[1, dofs] * force / model.jnt_stiffness[model.dof_jntid[dofs]]
    return float(jac[1, dofs] @ q)


def convergence_table(builder, counts) -> str:
    """Markdown table: N, then per beam the errors (%) of modes 1-3 and of the static deflection."""
    head = "| N |" + "".join(f" {label}: f1 | f2 | f3 | static |" for label, _b, _m in BEAMS)
    rule = "|---:|" + "---:|---:|---:|---:|" * len(BEAMS)
    rows = [head, rule]
    for n in counts:
        cells = [f"| {n} |"]
        for _label, beam, tip_mass in BEAMS:
            model = builder(beam, n, tip_mass)
            dofs = chain_dofs(model, "beam")
            err = (chain_modes(model, dofs) / clamped_free_frequencies(beam, tip_mass, 3) - 1) * 100
            err_static = (static_tip(model, dofs) / tip_deflection(beam, 1.0) - 1) * 100
            cells.append("".join(f" {e:+.3f} |" for e in err) + f" {err_static:+.3f} |")
        rows.append("".join(cells))
    refs = "; ".join(
        f"{label}: " + " / ".join(f"{f:.4g}" for f in clamped_free_frequencies(beam, m, 3) / (2 * np.pi)) + " Hz"
        for label, beam, m in BEAMS
    )
    return "\n".join(rows) + f"\n\nReference (beam_theory.clamped_free_frequencies): {refs}.\n"


# --- stability -------------------------------------------------------------------------------


def _deflect(model: mujoco.MjModel, data: mujoco.MjData, prefixes, tip_m: float = 0.01) -> None:
    """Chains into the static shape of a load at the site `tip` (joints held), tip moved tip_m (m)."""
    dofs = np.concatenate([chain_dofs(model, p) for p in prefixes])
    mujoco.mj_forward(model, data)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, model.site("tip").id)
    q = jac[1, dofs] / model.jnt_stiffness[model.dof_jntid[dofs]]
    data.qpos[model.jnt_qposadr[model.dof_jntid[dofs]]] += q * tip_m / (jac[1, dofs] @ q)
    mujoco.mj_forward(model, data)


def free_vibration(rig: str, timestep: float, integrator, seconds: float = 2.0) -> str:
    """'stable' or 'unstable (t = ...)': nominal model, joints free, no input, from a 1 cm static
    tip deflection. Divergence = engine._check_state's criterion (MuJoCo warning, non-finite
    state, |qvel| > 1e4) checked every control period, or energy above its initial value."""
    prefixes = ("beam",) if rig == "laser_arm" else ("link1", "link2")
    model = load_model(rig, timestep=timestep)
    model.opt.integrator = integrator
    model.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    try:
        _settle_bearings(model, data)
        _check_state(model, data, 0.0)
    except SimulationError:
        return "unstable (settling)"
    if not np.isfinite(data.qpos).all():
        return "unstable (settling)"
    _deflect(model, data, prefixes)
    e0 = energy(model, data)
    chunk = max(1, int(round(CONTROL_PERIOD / timestep)))
    for k in range(int(round(seconds / (chunk * timestep)))):
        mujoco.mj_step(model, data, nstep=chunk)
        try:
            _check_state(model, data, data.time)
        except SimulationError:
            return f"unstable (t = {data.time:.3f} s)"
    if energy(model, data) > e0 + 1e-9 * abs(e0):
        return "unstable (energy grew)"
    return "stable"


def stability_table() -> str:
    """Markdown table of free_vibration over rigs x integrators x TIMESTEPS_MS.

    MuJoCo's divergence warnings are expected here: they are counted in data.warning (which
    _check_state reads) and not printed or written to MUJOCO_LOG.TXT while the table runs.
    """
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda _message: None)
    try:
        return _stability_rows()
    finally:
        mujoco.set_mju_user_warning(previous)


def _stability_rows() -> str:
    head = "| rig | integrator |" + "".join(f" {dt:g} ms |" for dt in TIMESTEPS_MS)
    rows = [head, "|---|---|" + "---|" * len(TIMESTEPS_MS)]
    for rig, label in (("laser_arm", "laser_arm (hub free)"), ("watflex", "watflex (both joints free)")):
        for name, integrator in INTEGRATORS.items():
            cells = [free_vibration(rig, dt * 1e-3, integrator) for dt in TIMESTEPS_MS]
            rows.append(f"| {label} | {name} |" + "".join(f" {c} |" for c in cells))
    nominal = f"Nominal: laser_arm {LASER_ARM.timestep * 1e3:g} ms, watflex {WATFLEX.timestep * 1e3:g} ms, implicitfast."
    return "\n".join(rows) + "\n\n" + nominal + "\n"


# --- the extra-hinge effects ------------------------------------------------------------------

EFFECT_N = (6, 12, 60)  # segments compared with EFFECT_REFERENCE_N
EFFECT_REFERENCE_N = 30
EFFECT_CASES = (  # (scenario, joint, channels compared, effects)
    ("laser_arm_step", "hub", ("tip_sensor", "motor_current"),
     ({"effect": "backlash", "width": 7e-5}, {"effect": "backlash", "width": 3e-4},
      {"effect": "joint_compliance", "stiffness": 5e3})),
    ("watflex_elbow_step", "elbow", ("elbow_angle", "strain_2A"),
     ({"effect": "backlash", "width": 7e-5}, {"effect": "backlash", "width": 4e-3},
      {"effect": "joint_compliance", "stiffness": 5e3})),
)


def _step(name: str, effects: list[dict], n: int, duration: float) -> dict[str, np.ndarray]:
    """Channels of `duration` s of the experiment `name`, noise off, n segments, half the model's physics step."""
    scenario = load_scenario(name, ["noise=false", f"duration_s={duration}"])
    scenario.update(effects=effects, n_segments=n, timestep=load_model(scenario["rig"]).opt.timestep / 2)
    return simulate(scenario).recording.channels


def effect_convergence_table(duration: float) -> str:
    """Markdown table: per effect and channel, its size at EFFECT_REFERENCE_N, the distance at each EFFECT_N (nominal,
    with the effect) and the second half's change at each EFFECT_N against EFFECT_REFERENCE_N's."""
    rms = lambda a, b: float(np.sqrt(np.nanmean((np.asarray(a) - np.asarray(b)) ** 2)))  # noqa: E731
    cols = lambda what: " | ".join(f"{what} N = {n}" for n in EFFECT_N)  # noqa: E731
    ratio = lambda a, b: f"{a / b:.3f}" if b > 0 else "-"  # noqa: E731  (- : the effect does not move the channel)
    rows = [f"| experiment ({duration:g} s) | effect | channel | size at N = 30 | {cols('nominal')} | {cols('effect')} "
            f"| {cols('2nd half')} |", "|---|---|---|---:|" + "---:|" * (3 * len(EFFECT_N))]
    for name, joint, channels, effects in EFFECT_CASES:
        every = (EFFECT_REFERENCE_N, *EFFECT_N)
        nominal = {n: _step(name, [], n, duration) for n in every}
        for effect in effects:
            with_it = {n: _step(name, [{**effect, "where": joint}], n, duration) for n in every}
            for c in channels:
                ref, size = with_it[EFFECT_REFERENCE_N][c], rms(with_it[EFFECT_REFERENCE_N][c], nominal[EFFECT_REFERENCE_N][c])
                half = len(ref) // 2
                late = {n: rms(with_it[n][c][half:], nominal[n][c][half:]) for n in every}
                label = ", ".join(f"{k} {v:g}" for k, v in effect.items() if k != "effect")
                rows.append(f"| {name} | {effect['effect']} ({label}) | {c} | {size:.3g} | "
                            + " | ".join(ratio(rms(nominal[n][c], nominal[EFFECT_REFERENCE_N][c]), size) for n in EFFECT_N) + " | "
                            + " | ".join(ratio(rms(with_it[n][c], ref), size) for n in EFFECT_N) + " | "
                            + " | ".join(ratio(late[n], late[EFFECT_REFERENCE_N]) for n in EFFECT_N) + " |")
    return ("\n".join(rows) + "\n\nDistances in units of the effect's size at N = 30 (the rms change it makes there); "
            "2nd half: the rms change the effect makes over the run's second half at N over that at N = 30.\n")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-stability", action="store_true", help="skip the time-step stability table")
    parser.add_argument("--skip-effects", action="store_true", help="skip the extra-hinge effects' table (~20 s at 1.5 s)")
    parser.add_argument("--duration", type=float, default=1.5, help="seconds of each step in the effects' table (default 1.5)")
    args = parser.parse_args()
    if not args.duration > 0:
        parser.error(f"--duration must be > 0 s, got {args.duration}")
    print("## Bending modes and static tip deflection: error (%) vs segments N\n")
    print("### Hinges at segment midpoints (our scheme, add_flexible_chain)\n")
    print(convergence_table(midpoint_cantilever, MIDPOINT_N))
    print("### Hinges at element ends (first hinge at the root, k = EI/dx)\n")
    print(convergence_table(end_hinge_cantilever, END_HINGE_N))
    if not args.skip_stability:
        print("## Free vibration for 2 s from a 1 cm tip deflection, nominal damping, no input\n")
        print(stability_table())
    if not args.skip_effects:
        print("## The extra-hinge effects in a closed-loop step: distance from N = 30 vs segments N\n")
        print(effect_convergence_table(args.duration))
    return 0


if __name__ == "__main__":
    sys.exit(main())
