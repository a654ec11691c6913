"""Cross-check of the project's LuGre joint friction against MuJoCo's native dcmotor LuGre.

Usage: python tools/lugre_crosscheck.py [--png docs/lugre_crosscheck.png] [--sigma0 259 10000]
                                        [--sigma1 10] [--timestep 5e-4] [--reference]

A lone hinge (inertia 1.25 kg m^2 as armature, like tests/test_joint_friction.py::lone_joint,
but frictionloss 0, implicitfast, the Watflex time step) driven by a `motor` actuator
`elbow_motor` (torque = ctrl), built twice:

(a) "project": the friction is watflex_sim.joint_friction.FrictionCallback with
    JointFriction(p, p, law="lugre", sigma0, sigma1), i.e. watflex_sim.friction.lugre_step
    (thesis eq. 4.20) applied as a passive torque;
(b) "native": the friction is a second actuator, a MuJoCo `dcmotor` with no input
    (ctrlspec = mjINPUT_NONE) carrying lugre = [sigma0, sigma1, alpha0, alpha0 + alpha1, v_s]
    and the viscous alpha2 as the actuator's `damping`. A stateless dcmotor always adds
    back-EMF damping K^2/R; with motorconst K = 1e-9 N m/A, R = 1 ohm it is 1e-18 N m s/rad,
    i.e. the dcmotor contributes nothing but its LuGre friction. The drive torque is the same
    `motor` actuator in both models, so (a) and (b) differ only in the friction.

The native LuGre (MuJoCo >= 3.7 dcmotor; doc/dcmotor/dcmotor.tex "Stateful Friction" and
"Low-Level Semantics", verified below by probe_native()) is symmetric (one parameter set for
both directions), Stribeck exponent fixed at 2, velocity = actuator_velocity (gear x joint
velocity; gear 1 here, so the joint), state z = one entry of mjData.act:
    force_k = -(sigma0 z_k + sigma1 zdot(z_k, w_k)) - sigma2 w_k,
    zdot(z, w) = w - sigma0 |w| z / g(w),  g(w) = tau_c + (tau_s - tau_c) exp(-(w/w_s)^2),
    z_{k+1} = exact zero-order-hold solution over the step at constant w_k,
with d(force)/dw = -sigma1 (and the damping -sigma2) taken implicitly by implicit/implicitfast.
The project's lugre_step uses the same z_{k+1} but the force at the *end* of the step,
F = sigma0 z_{k+1} + sigma1 (z_{k+1} - z_k)/dt + alpha2 w_k, all explicit (passive callback).
In pre-sliding (z_{k+1} ~ z_k + w_k dt) the two forces differ by sigma0 w_k dt: the native
bristle spring lags the joint by one step, which acts as a damping -sigma0 dt
(-0.13 N m s/rad at sigma0 = 259, -5 N m s/rad at 1e4, against sigma1 + alpha2 = 11.3).

Experiments (elbow positive-direction parameters, used for both directions):
(i) step: torque 1.5 (alpha0 + alpha1) from rest for 1 s;
(ii) pre-sliding: triangle torque 0 -> +A -> -A -> 0, A = 0.75 alpha0, slope 2.4 N m/s, two
     periods (thesis fig. 4.17); loop width = angle on the falling branch minus angle on the
     rising branch at zero torque, second period.
--reference adds a continuous-time solution (scipy Radau, rtol 1e-10) of the same ODE, to
show how far each discretisation is from it.
Prints a markdown table; writes a PNG of the loops (angle vs torque) for each sigma0.
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from watflex_sim.friction import stribeck_level  # noqa: E402
from watflex_sim.joint_friction import FrictionCallback, JointFriction  # noqa: E402
from watflex_sim.params import WATFLEX, Friction  # noqa: E402

INERTIA = 1.25  # kg m^2, the elbow's (tests/test_joint_friction.py::lone_joint)
SIGMA0S = (259.0, 1e4)  # N m/rad: thesis value, and a stiff bristle
SIGMA1 = 10.0  # N m s/rad
STEP_FACTOR = 1.5  # step torque / (alpha0 + alpha1)
STEP_SECONDS = 1.0
TRIANGLE_FACTOR = 0.75  # triangle amplitude / alpha0
TRIANGLE_SLOPE = 2.4  # N m/s
TRIANGLE_PERIODS = 2
NATIVE_K = 1e-9  # N m/A, dcmotor motor constant: back-EMF damping K^2/R = 1e-18 N m s/rad
NATIVE_R = 1.0  # ohm
ELBOW = WATFLEX.elbow_friction[0]  # positive-direction parameters


def native_lugre(p: Friction, sigma0: float, sigma1: float) -> list[float]:
    """dcmotor `lugre` attribute [sigma0, sigma1, tau_c, tau_s, w_s] for thesis parameters p."""
    return [sigma0, sigma1, p.alpha0, p.alpha0 + p.alpha1, p.v_s]


def build_hinge(native: JointFriction | None = None, timestep: float = WATFLEX.timestep,
                integrator: int = mujoco.mjtIntegrator.mjINT_IMPLICITFAST) -> mujoco.MjModel:
    """The lone hinge `elbow` with a torque actuator `elbow_motor` and no frictionloss.

    With `native` (a symmetric JointFriction), a passive dcmotor `elbow_lugre` carries its
    LuGre parameters (positive side) and alpha2 as actuator damping.
    """
    spec = mujoco.MjSpec()
    spec.option.timestep = timestep
    spec.option.integrator = integrator
    body = spec.worldbody.add_body(name="rotor")
    j = body.add_joint(name="elbow", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    j.armature = INERTIA
    j.frictionloss = 0.0
    g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0])
    g.mass = 1e-3
    spec.add_actuator(name="elbow_motor", target="elbow", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    if native is not None:
        if native.positive != native.negative:
            raise ValueError("the native LuGre is symmetric: give equal positive and negative parameters")
        a = spec.add_actuator(name="elbow_lugre", target="elbow", trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.set_to_dcmotor(motorconst=[NATIVE_K, 0.0], resistance=NATIVE_R,
                         lugre=native_lugre(native.positive, native.sigma0, native.sigma1),
                         ctrlspec=int(mujoco.mjtCtrlInput.mjINPUT_NONE))
        a.damping = [native.positive.alpha2, 0.0, 0.0]
    return spec.compile()


@dataclass
class Run:
    """Samples at t_k = k dt, before step k: time (s), angle (rad), speed (rad/s), drive torque (N m)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    u: np.ndarray


def simulate(friction: JointFriction, torque, seconds: float, native: bool,
             timestep: float = WATFLEX.timestep) -> Run:
    """Run the hinge from rest under torque(t) (N m) with the project's (native=False) or MuJoCo's LuGre."""
    model = build_hinge(friction if native else None, timestep)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    ctrl = int(model.actuator_ctrladr[model.actuator("elbow_motor").id])
    n = int(round(seconds / timestep))
    t, q, v, u = (np.empty(n + 1) for _ in range(4))

    def loop():
        for k in range(n + 1):
            t[k], q[k], v[k] = data.time, data.qpos[0], data.qvel[0]
            u[k] = torque(data.time)
            if k == n:
                break
            data.ctrl[ctrl] = u[k]
            mujoco.mj_step(model, data)

    if native:
        loop()
    else:
        with FrictionCallback(model, data, {"elbow": friction}):
            loop()
    return Run(t, q, v, u)


def step_torque(p: Friction = ELBOW):
    """Experiment (i): constant 1.5 (alpha0 + alpha1) (N m)."""
    level = STEP_FACTOR * (p.alpha0 + p.alpha1)
    return lambda t: level


def triangle_period(p: Friction = ELBOW) -> float:
    """Period (s) of the triangle of experiment (ii): 4 A / slope."""
    return 4 * TRIANGLE_FACTOR * p.alpha0 / TRIANGLE_SLOPE


def triangle_torque(p: Friction = ELBOW):
    """Experiment (ii): 0 -> +A -> -A -> 0 at +-2.4 N m/s, A = 0.75 alpha0 (N m)."""
    amplitude, period = TRIANGLE_FACTOR * p.alpha0, triangle_period(p)

    def u(t: float) -> float:
        s = (t / period) % 1.0
        return amplitude * (4 * s if s < 0.25 else 2 - 4 * s if s < 0.75 else 4 * s - 4)

    return u


def triangle_kinks(p: Friction = ELBOW, periods: int = TRIANGLE_PERIODS) -> list[float]:
    """Corners of the triangle (s): every quarter period, from 0 to the end."""
    quarter = triangle_period(p) / 4
    return [k * quarter for k in range(4 * periods + 1)]


def loop_width(run: Run, period: float) -> float:
    """Angle (rad) on the falling branch minus the rising branch at zero torque, second period.

    Zero torque is crossed rising at t = P and 2 P and falling at 1.5 P; the rising angle is
    the mean of the two (they differ only by the loop's drift).
    """
    at = lambda time: float(np.interp(time, run.t, run.q))  # noqa: E731
    return at(1.5 * period) - 0.5 * (at(period) + at(2 * period))


def reference(friction: JointFriction, torque, kinks: list[float], samples: np.ndarray) -> Run:
    """Continuous-time solution of J q'' = u - F, LuGre eq. 4.20 (scipy Radau), sampled at `samples` (s).

    Integrated piecewise between `kinks` (s, the input's corners; the last one is extended to
    the last sample), so the solver never steps across a corner of the input.
    """
    from scipy.integrate import solve_ivp

    s0, s1 = friction.sigma0, friction.sigma1

    def rhs(time, y):
        q, v, z = y
        side = friction.positive if v >= 0 else friction.negative
        zdot = v - s0 * abs(v) * z / stribeck_level(abs(v), side)
        force = s0 * z + s1 * zdot + side.alpha2 * v
        return [v, (torque(time) - force) / (INERTIA + 4e-8), zdot]

    kinks = sorted(kinks)
    kinks[-1] = max(kinks[-1], float(samples[-1]))
    y = [0.0, 0.0, 0.0]
    q, v = np.empty(len(samples)), np.empty(len(samples))
    for a, b in zip(kinks[:-1], kinks[1:]):
        sol = solve_ivp(rhs, (a, b), y, method="Radau", rtol=1e-10, atol=1e-13, dense_output=True, max_step=1e-2)
        inside = (samples >= a) & (samples <= b)  # a corner sample is set by both pieces: same value
        q[inside], v[inside] = sol.sol(samples[inside])[:2]
        y = sol.y[:, -1]
    return Run(samples, q, v, np.array([torque(x) for x in samples]))


def probe_native(sigma0: float = 259.0, sigma1: float = SIGMA1, p: Friction = ELBOW) -> dict:
    """Check the native definition on one state: force, act update and implicit derivative.

    Returns the largest deviations of mjData from the formulas in this module's docstring
    (force in N m, z in rad, derivative in N m s/rad); all should be at rounding level.
    """
    friction = JointFriction(p, p, law="lugre", sigma0=sigma0, sigma1=sigma1)
    model = build_hinge(friction)
    lug = model.actuator("elbow_lugre").id
    data = mujoco.MjData(model)
    dt = model.opt.timestep
    worst = {"force": 0.0, "z_next": 0.0, "implicit_derivative": 0.0}
    for z, w in ((0.005, 0.02), (-0.003, -0.05), (0.02, 0.5), (0.01, 0.0)):
        mujoco.mj_resetData(model, data)
        data.act[model.actuator_actadr[lug]] = z
        data.qvel[0] = w
        mujoco.mj_forward(model, data)
        force = data.actuator_force[lug] + data.qfrc_damper[0]
        g = stribeck_level(abs(w), p)
        zdot = w - sigma0 * abs(w) * z / g
        a = -sigma0 * abs(w) / g
        z_next = math.exp(a * dt) * z + (math.expm1(a * dt) / a * w if a else w * dt)
        worst["force"] = max(worst["force"], abs(force + sigma0 * z + sigma1 * zdot + p.alpha2 * w))
        mujoco.mj_step(model, data)
        worst["z_next"] = max(worst["z_next"], abs(data.act[model.actuator_actadr[lug]] - z_next))
        if w:  # (M + dt D) dv = dt f  ->  D = (M - dt f / dv) / dt, expected sigma1 + alpha2
            m0 = model.dof_M0[0]
            d_implicit = (dt * force / (data.qvel[0] - w) - m0) / dt
            worst["implicit_derivative"] = max(worst["implicit_derivative"], abs(d_implicit - (sigma1 + p.alpha2)))
    return worst


@dataclass
class Comparison:
    """Max differences native - project of one experiment at one sigma0."""

    experiment: str
    sigma0: float
    dq: float  # rad
    dv: float  # rad/s
    q_scale: float  # rad, max |q| of the project run
    v_scale: float  # rad/s
    width_project: float = float("nan")  # rad
    width_native: float = float("nan")
    width_reference: float = float("nan")
    dq_ref_project: float = float("nan")  # rad, max |q - q_reference|
    dq_ref_native: float = float("nan")


def compare(experiment: str, sigma0: float, sigma1: float = SIGMA1, p: Friction = ELBOW,
            timestep: float = WATFLEX.timestep, with_reference: bool = False,
            native_sigma1: float | None = None) -> tuple[Comparison, Run, Run]:
    """Run one experiment ("step" or "presliding") with both frictions; return the comparison and both runs.

    `native_sigma1` (default sigma1) sets the native model's bristle damping alone, e.g.
    sigma1 + sigma0 dt to cancel its one-step spring lag.
    """
    friction = JointFriction(p, p, law="lugre", sigma0=sigma0, sigma1=sigma1)
    native = JointFriction(p, p, law="lugre", sigma0=sigma0, sigma1=sigma1 if native_sigma1 is None else native_sigma1)
    if experiment == "step":
        torque, seconds, kinks = step_torque(p), STEP_SECONDS, [0.0, STEP_SECONDS]
    elif experiment == "presliding":
        torque, seconds, kinks = triangle_torque(p), TRIANGLE_PERIODS * triangle_period(p), triangle_kinks(p)
    else:
        raise ValueError(f"unknown experiment {experiment!r}")
    ours = simulate(friction, torque, seconds, native=False, timestep=timestep)
    theirs = simulate(native, torque, seconds, native=True, timestep=timestep)
    label = experiment if native_sigma1 is None else f"{experiment}, native sigma1 = {native_sigma1:g}"
    c = Comparison(label, sigma0, float(np.abs(theirs.q - ours.q).max()), float(np.abs(theirs.v - ours.v).max()),
                   float(np.abs(ours.q).max()), float(np.abs(ours.v).max()))
    if experiment == "presliding":
        c.width_project = loop_width(ours, triangle_period(p))
        c.width_native = loop_width(theirs, triangle_period(p))
    if with_reference:
        ref = reference(friction, torque, kinks, ours.t)
        c.dq_ref_project = float(np.abs(ours.q - ref.q).max())
        c.dq_ref_native = float(np.abs(theirs.q - ref.q).max())
        if experiment == "presliding":
            c.width_reference = loop_width(ref, triangle_period(p))
    return c, ours, theirs


def table(rows: list[Comparison], with_reference: bool) -> str:
    """Markdown table of the comparisons."""
    head = ("| experiment | sigma0 (N m/rad) | max abs dq (rad) | dq / max abs q | max abs dv (rad/s) | dv / max abs v "
            "| loop width project (rad) | native (rad) | rel. diff |")
    sep = "|---|---|---|---|---|---|---|---|---|"
    if with_reference:
        head += " reference width (rad) | max abs q-q_ref project (rad) | native (rad) |"
        sep += "---|---|---|"
    lines = [head, sep]
    for c in rows:
        rel = (c.width_native - c.width_project) / c.width_project if c.width_project == c.width_project else float("nan")
        line = (f"| {c.experiment} | {c.sigma0:g} | {c.dq:.2e} | {c.dq / c.q_scale:.1e} | {c.dv:.2e} | "
                f"{c.dv / c.v_scale:.1e} | {c.width_project:.3e} | {c.width_native:.3e} | {rel:+.1e} |")
        if with_reference:
            line += f" {c.width_reference:.3e} | {c.dq_ref_project:.1e} | {c.dq_ref_native:.1e} |"
        lines.append(line.replace("nan", "–").replace("+–", "–"))
    return "\n".join(lines)


def plot(loops: list[tuple[float, Run, Run]], path: Path) -> None:
    """PNG: one panel per sigma0, angle vs drive torque for both implementations."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(loops), figsize=(5.5 * len(loops), 4.2), squeeze=False)
    for ax, (sigma0, ours, theirs) in zip(axes[0], loops):
        ax.plot(ours.u, ours.q * 1e3, lw=2.2, color="tab:blue", label="project (lugre_step callback)")
        ax.plot(theirs.u, theirs.q * 1e3, lw=1.0, ls="--", color="tab:red", label="MuJoCo dcmotor lugre")
        ax.set_xlabel("drive torque (N m)")
        ax.set_ylabel("angle (mrad)")
        ax.set_title(f"pre-sliding, sigma0 = {sigma0:g} N m/rad, sigma1 = {SIGMA1:g}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    fig.suptitle("LuGre pre-sliding hysteresis, lone elbow hinge (J = 1.25 kg m^2, dt = "
                 f"{(loops[0][1].t[1] - loops[0][1].t[0]) * 1e3:g} ms), triangle {TRIANGLE_FACTOR} alpha0 at "
                 f"{TRIANGLE_SLOPE} N m/s", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="See the module docstring for the native model's definition.")
    ap.add_argument("--png", type=Path, default=Path("docs/lugre_crosscheck.png"),
                    help="where to write the hysteresis-loop figure (default: docs/lugre_crosscheck.png)")
    ap.add_argument("--sigma0", type=float, nargs="+", default=list(SIGMA0S), help="bristle stiffnesses (N m/rad)")
    ap.add_argument("--sigma1", type=float, default=SIGMA1, help="bristle damping (N m s/rad), default 10")
    ap.add_argument("--timestep", type=float, default=WATFLEX.timestep, help="physics time step (s), default 5e-4")
    ap.add_argument("--reference", action="store_true", help="also integrate the continuous ODE (scipy Radau)")
    ap.add_argument("--no-png", action="store_true", help="skip the figure")
    ap.add_argument("--no-compensated", action="store_true",
                    help="skip the extra pre-sliding rows with the native sigma1 raised by sigma0 dt")
    args = ap.parse_args(argv)

    worst = probe_native(args.sigma0[0], args.sigma1)
    print("native definition check (deviation from the documented formulas): "
          + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    p = ELBOW
    print(f"elbow positive-direction parameters (both directions): alpha0 {p.alpha0} N m, alpha1 {p.alpha1} N m, "
          f"alpha2 {p.alpha2} N m s/rad, v_s {p.v_s} rad/s; sigma1 {args.sigma1} N m s/rad; dt {args.timestep} s\n")
    rows, loops = [], []
    for sigma0 in args.sigma0:
        for experiment in ("step", "presliding"):
            c, ours, theirs = compare(experiment, sigma0, args.sigma1, timestep=args.timestep,
                                      with_reference=args.reference)
            rows.append(c)
            if experiment == "presliding":
                loops.append((sigma0, ours, theirs))
        if not args.no_compensated:  # the native spring lag cancelled: sigma1 + sigma0 dt in the native model
            c, _, _ = compare("presliding", sigma0, args.sigma1, timestep=args.timestep, with_reference=args.reference,
                              native_sigma1=args.sigma1 + sigma0 * args.timestep)
            rows.append(c)
    print(table(rows, args.reference))
    if not args.no_png:
        plot(loops, args.png)
        print(f"\nwrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
