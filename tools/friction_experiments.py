"""Thesis chapter 4 friction experiments on the simulated shoulder actuator bench.

    python tools/friction_experiments.py            # full runs (about 25 s), figures in docs/
    python tools/friction_experiments.py --quick    # shorter scan and fit (about 15 s)

Experiments (scenarios/*.toml, each commented with its thesis source):
  map         watflex_friction_map: PI velocity scan 0.61 -> 0.0004 rad/s (4.5.4, fig. 4.18-4.22),
              mean torque command vs mean speed over the second half of each hold, eq. 4.21
              fitted per direction (scipy least_squares, 4 parameters) against table 4.3.
  presliding  watflex_presliding: open-loop torque triangle 0.75 alpha0+, 2.4 N m/s, 4 periods,
              LuGre plant (fig. 4.17): loop width, against quasi-static LuGre.
  dwell       watflex_dwell: 10 s at rest, then a 0.2 N m/s ramp: break-away torque against
              (2 - e^-5) x (alpha0 + alpha1) (thesis 4.1.6; dwell_gain 1, dwell_time 2 s).
  pstep       watflex_p_step_compensated: P 5 N m/rad, 1 rad step at 1 s, qualified exponential
              compensation (4.5.5, fig. 4.27-4.28) against the ideal frictionless motor; also
              without compensation.
  inertia     the compensated step re-simulated with the bench's armature free, J fitted by
              minimize_scalar on the angle error (4.5.6, fig. 4.30).
The compensation experiments run last: they need controllers/friction_compensation.py
(--wait-s polls for it once a minute).

The functions are importable (tests/test_friction_experiments.py loads this file).
"""
from __future__ import annotations

import argparse
import copy
import importlib
import math
import sys
import time as wallclock
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from scipy.optimize import least_squares, minimize_scalar  # noqa: E402

from watflex_sim.plot import save_figure  # noqa: E402
from watflex_sim import metrics  # noqa: E402
from watflex_sim.engine import ControlLoop  # noqa: E402
from watflex_sim.params import CONTROL_PERIOD, WATFLEX, Friction  # noqa: E402
from watflex_sim.scenario import check, load_scenario  # noqa: E402

DOCS = ROOT / "docs"
JOINT = "shoulder"
TABLE_4_3 = {+1: WATFLEX.shoulder_friction[0], -1: WATFLEX.shoulder_friction[1]}  # rigs.md §2
J_S = WATFLEX.shoulder.inertia  # kg m^2, thesis 4.5.6 (the bench's armature)
COUNT = WATFLEX.encoder_step  # rad
PARAM_NAMES = ("alpha0", "alpha1", "alpha2", "v_s")
PARAM_UNITS = ("N m", "N m", "N m s/rad", "rad/s")
QUICK_SCAN = {"v_max": 0.61, "v_min": 0.0004, "n_speeds": 10, "hold_fast_s": 2.0, "hold_slow_s": 5.0}


# --- running a scenario ---------------------------------------------------------------------
@dataclass
class Run:
    """One simulated run: time (s), measured and recorded channels, the true joint angle (rad),
    and what the controller exposes (compensation torque N m, if any)."""

    time: np.ndarray
    channels: dict[str, np.ndarray]
    true_angle: np.ndarray
    compensation: np.ndarray | None
    controller: object
    inertia: float  # kg m^2, the joint's total inertia in the model (mass matrix)
    wall_s: float


def scenario(name: str, overrides: list[str] = (), edit=None) -> dict:
    """load_scenario(name, overrides), then `edit(dict)` (for tables --set cannot remove), checked."""
    s = load_scenario(name, list(overrides))
    if edit is not None:
        s = copy.deepcopy(s)
        edit(s)
        s = check(s)
    return s


def run(s: dict, armature: float | None = None, duration_s: float | None = None) -> Run:
    """Run scenario `s` through the project's ControlLoop; `armature` (kg m^2) replaces the
    shoulder's dof_armature before the first step (a MuJoCo model edit, for identification)."""
    s = copy.deepcopy(s)
    if duration_s is not None:
        s["duration_s"] = duration_s
    loop = ControlLoop(s)
    model, data = loop.model, loop.data
    dof = int(model.joint(JOINT).dofadr[0])
    qadr = int(model.joint(JOINT).qposadr[0])
    if armature is not None:
        model.dof_armature[dof] = armature
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    rows, q, comp = [], np.empty(loop.n_ticks), []
    has_comp = hasattr(loop.controller, "compensation")
    start = wallclock.perf_counter()
    with loop:
        for k in range(loop.n_ticks):
            obs, recorded = loop.tick(k)
            rows.append(obs | recorded)
            q[k] = data.qpos[qadr]
            if has_comp:
                comp.append(loop.controller.compensation)
    wall = wallclock.perf_counter() - start
    names = [c for c in rows[0] if isinstance(rows[0][c], float)]
    channels = {c: np.array([r.get(c, np.nan) for r in rows], float) for c in names}
    t = np.arange(loop.n_ticks) * CONTROL_PERIOD
    return Run(t, channels, q, np.array(comp) if has_comp else None, loop.controller,
               float(full[dof, dof]), wall)


# --- 1. friction-velocity map (thesis 4.5.4) ---------------------------------------------------
def tau_ss(v: np.ndarray, alpha0: float, alpha1: float, alpha2: float, v_s: float) -> np.ndarray:
    """Steady-state friction magnitude of one direction, eq. 4.21, at speed |v| (rad/s), N m."""
    v = np.abs(v)
    return alpha0 + alpha1 * np.exp(-((v / v_s) ** 2)) + alpha2 * v


def map_points(r: Run) -> np.ndarray:
    """Rows (desired speed, mean speed rad/s, mean torque N m, torque std N m, samples) per hold.

    Mean speed = least-squares slope of the encoder angle over the second half of the hold
    (thesis: 'the means of all input torque and output speed values'); mean torque = mean of
    the recorded command, i.e. after the 12-bit converter, whose codes the PI dithers between.
    """
    ctrl = r.controller
    index = ctrl.window_index(r.time)
    angle, torque = r.channels[f"{JOINT}_angle"], r.channels[f"{JOINT}_torque_cmd"]
    out = []
    for i, (v_d, _t0, _t1) in enumerate(ctrl.windows()):
        m = index == i
        if m.sum() < 10:
            continue
        slope = np.polyfit(r.time[m] - r.time[m].mean(), angle[m], 1)[0]
        out.append((v_d, slope, torque[m].mean(), torque[m].std(), m.sum()))
    return np.array(out)


def fit_direction(speed: np.ndarray, torque: np.ndarray) -> dict:
    """Fit eq. 4.21 to one direction's points (|v| rad/s, |tau| N m) with least_squares.

    Start by inspection of the map (as the thesis did for fminsearch): alpha0 the lowest torque,
    alpha1 the rise from there to the slowest point, alpha2 the slope of the two fastest points,
    v_S where the excess has fallen to half. Returns x, 1-sigma standard errors (from the
    Jacobian and the residual variance), residual rms (N m) and the condition number.
    """
    order = np.argsort(speed)
    v, f = speed[order], torque[order]
    alpha2 = (f[-1] - f[-2]) / (v[-1] - v[-2])
    alpha0 = max(float(np.min(f - alpha2 * v)), 0.1)
    alpha1 = max(float(f[0] - alpha0), 0.01)
    excess = f - alpha2 * v - alpha0
    half = np.flatnonzero(excess < alpha1 / 2)
    v_s = float(v[half[0]]) if half.size else float(np.median(v))
    x0 = np.array([alpha0, alpha1, alpha2, v_s])
    res = least_squares(lambda x: tau_ss(v, *x) - f, x0, bounds=([0, 0, 0, 1e-5], [100, 50, 100, 10]),
                        x_scale=np.abs(x0), xtol=1e-12, ftol=1e-12)
    dof = max(len(v) - 4, 1)
    s2 = float(res.fun @ res.fun) / dof
    jtj = res.jac.T @ res.jac
    try:
        cov = np.linalg.inv(jtj) * s2
        err = np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        err = np.full(4, np.nan)
    scale = np.abs(res.x)
    cond = float(np.linalg.cond(jtj * np.outer(scale, scale)))
    return {"x": res.x, "stderr": err, "rms": math.sqrt(s2), "cond": cond, "x0": x0, "n": len(v)}


def friction_map(quick: bool = False, scan: dict | None = None) -> dict:
    """Run the scan (the scenario's, or QUICK_SCAN / `scan`), fit each direction, compare with table 4.3."""
    scan = scan or (QUICK_SCAN if quick else None)

    def edit(s):
        if scan is not None:
            s["controller"]["scan"] = dict(scan)
        from watflex_sim.controllers import CONTROLLERS

        spec = {k: v for k, v in s["controller"].items() if k != "type"}
        s["duration_s"] = CONTROLLERS["pi_velocity"](**spec).duration_s

    r = run(scenario("watflex_friction_map", edit=edit))
    pts = map_points(r)
    fits = {}
    for sign in (+1, -1):
        sel = np.sign(pts[:, 0]) == sign
        fit = fit_direction(sign * pts[sel, 1], sign * pts[sel, 2])
        truth = np.array([getattr(TABLE_4_3[sign], n) for n in PARAM_NAMES])
        fit["truth"] = truth
        fit["error_pct"] = 100 * (fit["x"] - truth) / truth
        fits[sign] = fit
    angle = r.channels[f"{JOINT}_angle"]
    return {"run": r, "points": pts, "fits": fits, "duration_s": float(r.time[-1] + CONTROL_PERIOD),
            "angle_range": (float(angle.min()), float(angle.max())), "holds": len(r.controller.schedule)}


# --- 2. pre-sliding (thesis 4.5.1, fig. 4.17) ---------------------------------------------------
def lugre_quasi_static(torque: np.ndarray, sigma0: float, positive: Friction, negative: Friction) -> np.ndarray:
    """Angle (rad) of a quasi-static LuGre joint (eq. 4.20 with J theta'' = 0, z' and v tiny) under
    the torque sequence `torque` (N m), from z = 0: F = sigma0 z = tau and
    d theta = d tau / (sigma0 (1 - s tau / g_s)), s = sgn(d tau), g_s = alpha0 + alpha1 of that side."""
    theta = np.zeros(len(torque))
    g = {+1: positive.alpha0 + positive.alpha1, -1: negative.alpha0 + negative.alpha1}
    for k in range(1, len(torque)):
        d = torque[k] - torque[k - 1]
        if d == 0:
            theta[k] = theta[k - 1]
            continue
        s = 1 if d > 0 else -1
        # exact integral of 1/(sigma0 (1 - s tau/g)) from tau[k-1] to tau[k]
        theta[k] = theta[k - 1] + s * g[s] / sigma0 * math.log((g[s] - s * torque[k - 1]) / (g[s] - s * torque[k]))
    return theta


def loop_measures(time: np.ndarray, angle: np.ndarray, torque: np.ndarray, period: float) -> dict:
    """Per full cycle after the virgin loading (from each positive peak at P/4 + k P to the next):
    width = range of the angle (rad), opening = falling minus rising branch where |torque| < 0.2 N m
    (rad); both averaged over the cycles."""
    widths, openings = [], []
    dtq = np.gradient(torque)
    k = 0
    while period / 4 + (k + 1) * period <= time[-1] + 1e-9:
        m = (time >= period / 4 + k * period) & (time < period / 4 + (k + 1) * period)
        a, near = angle[m], np.abs(torque[m]) < 0.2
        widths.append(a.max() - a.min())
        rising, falling = near & (dtq[m] > 0), near & (dtq[m] < 0)
        if rising.any() and falling.any():
            openings.append(a[falling].mean() - a[rising].mean())
        k += 1
    return {"width": float(np.mean(widths)) if widths else math.nan,
            "opening": float(np.mean(openings)) if openings else math.nan, "cycles": len(widths)}


def presliding(overrides: list[str] = ()) -> dict:
    """Open-loop triangle on the LuGre bench: measured (encoder) and true loop, and the quasi-static model."""
    s = scenario("watflex_presliding", overrides)
    r = run(s)
    law = s["joint_friction"][JOINT]
    sigma0 = float(law["sigma0"])
    torque = r.channels[f"{JOINT}_torque_cmd"]
    cmd = s["command"][0]
    period = 4 * cmd["amplitude"] / cmd["slope"]  # s
    model = lugre_quasi_static(torque, sigma0, *TABLE_4_3.values())
    enc = r.channels[f"{JOINT}_angle"]
    return {
        "run": r, "sigma0": sigma0, "sigma1": float(law.get("sigma1", 10.0)), "period": period,
        "amplitude": cmd["amplitude"], "model": model,
        "encoder": loop_measures(r.time, enc, torque, period),
        "true": loop_measures(r.time, r.true_angle, torque, period),
        "quasi_static": loop_measures(r.time, model, torque, period),
        "drift_per_period": float(np.polyfit(r.time, r.true_angle, 1)[0] * period),
    }


# --- 3. dwell time (thesis 4.1.6) ----------------------------------------------------------------
def dwell(overrides: list[str] = ()) -> dict:
    """Break-away after a rest: the first sample one encoder count away from the rest angle."""
    s = scenario("watflex_dwell", overrides)
    r = run(s)
    law = s["joint_friction"][JOINT]
    gain, tau_d = float(law["dwell_gain"]), float(law["dwell_time"])
    angle, torque = r.channels[f"{JOINT}_angle"], r.channels[f"{JOINT}_torque_cmd"]
    moved = np.flatnonzero(np.abs(angle - angle[0]) >= COUNT - 1e-12)
    nominal = TABLE_4_3[+1].alpha0 + TABLE_4_3[+1].alpha1
    out = {"run": r, "nominal": nominal, "gain": gain, "dwell_time": tau_d,
           "expected_10s": nominal * (1 + gain * (1 - math.exp(-10.0 / tau_d)))}
    if moved.size == 0:
        out.update(breakaway=math.nan, t_break=math.nan, law_at_rest=math.nan)
        return out
    k = int(moved[0])
    out["t_break"] = float(r.time[k])  # s at rest before it moved (the run starts at rest)
    out["breakaway"] = float(torque[k - 1])  # N m applied over the period in which it moved
    below = np.flatnonzero(torque[:k] < torque[k - 1])
    out["held"] = float(torque[below[-1]]) if below.size else math.nan  # N m, the last lower level, held
    out["law_at_rest"] = nominal * (1 + gain * (1 - math.exp(-out["t_break"] / tau_d)))
    return out


# --- 4. compensated P step (thesis 4.5.5) -----------------------------------------------------
def wait_for_compensation(wait_s: float, poll_s: float = 60.0) -> bool:
    """True once controllers.friction_compensation imports (polled every `poll_s` s up to `wait_s`)."""
    deadline = wallclock.monotonic() + wait_s
    while True:
        try:
            module = importlib.import_module("controllers.friction_compensation")
            importlib.reload(module)
            return hasattr(module, "wrap_compensation")
        except Exception as exc:  # missing or half-written by its author
            if wallclock.monotonic() >= deadline:
                print(f"controllers/friction_compensation.py not usable ({exc}); skipping the compensated experiments")
                return False
            print(f"waiting for controllers/friction_compensation.py ({exc}) ...", flush=True)
            wallclock.sleep(poll_s)


def _no_compensation(s: dict) -> None:
    s["controller"].pop("compensation", None)


def _ideal(s: dict) -> None:
    s["controller"].pop("compensation", None)
    s["friction"] = "none"


def p_step(duration_s: float | None = None, fast_filter_hz: float = 20.0) -> dict:
    """Compensated (thesis 10 Hz filter and `fast_filter_hz`), uncompensated and ideal P steps."""
    name = "watflex_p_step_compensated"
    runs = {
        "ideal": run(scenario(name, edit=_ideal), duration_s=duration_s),
        "compensated": run(scenario(name), duration_s=duration_s),
        f"compensated, {fast_filter_hz:g} Hz filter": run(
            scenario(name, [f"controller.compensation.filter_hz={fast_filter_hz}"]), duration_s=duration_s),
        "uncompensated": run(scenario(name, edit=_no_compensation), duration_s=duration_s),
    }
    ideal = runs["ideal"].channels[f"{JOINT}_angle"]
    out = {"runs": runs, "rows": {}}
    for label, r in runs.items():
        a = r.channels[f"{JOINT}_angle"]
        corr = metrics.correlation(ideal, a) if np.ptp(a) > 0 else math.nan  # undefined if it never moved
        out["rows"][label] = {"correlation": corr, "nrmse": metrics.nrmse(ideal, a),
                              "period": oscillation_period(r.time, a), "moved": float(np.ptp(a))}
    return out


def oscillation_period(t: np.ndarray, angle: np.ndarray, level: float = 1.0) -> float:
    """Mean time (s) between upward crossings of `level` (rad); NaN with fewer than two."""
    up = np.flatnonzero((angle[:-1] < level) & (angle[1:] >= level))
    return float(np.mean(np.diff(t[up]))) if up.size >= 2 else math.nan


# --- 5. inertia (thesis 4.5.6) ----------------------------------------------------------------
def identify_inertia(measured: Run | None = None, duration_s: float | None = None, bounds=(2.0, 5.0),
                     xatol: float = 1e-3, name: str = "watflex_inertia_step") -> dict:
    """Fit the shoulder armature J (kg m^2) so that scenario `name` re-simulated with it matches
    the `measured` encoder angle (mean square over the first `duration_s` s, or all), by bounded
    minimize_scalar (J within `bounds`, kg m^2; `xatol` kg m^2). `measured` defaults to a run of
    the scenario itself with the model's J_S.

    Also the thesis' own assumption (fig. 4.10): an ideal motor J theta'' = P (theta_ref - theta),
    i.e. theta = 1 - cos(sqrt(P/J) (t - t_step)), fitted to the same record.
    """
    s = scenario(name)
    if measured is None:
        measured = run(s, duration_s=duration_s)
    n = len(measured.time) if duration_s is None else int(round(duration_s / CONTROL_PERIOD))
    target = measured.channels[f"{JOINT}_angle"][:n]
    evaluations = []

    def cost(j: float) -> float:
        r = run(s, armature=j, duration_s=n * CONTROL_PERIOD)
        c = float(np.mean((r.channels[f"{JOINT}_angle"] - target) ** 2))
        evaluations.append((j, c))
        return c

    res = minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": xatol})
    best = run(s, armature=float(res.x), duration_s=n * CONTROL_PERIOD)

    ref = s["reference"][0]
    kp, t_step, step = s["controller"]["kp"][0], ref["time_s"], ref["amplitude"]
    t = measured.time[:n]

    def ideal_angle(j: float) -> np.ndarray:
        return np.where(t >= t_step, step * (1 - np.cos(np.sqrt(kp / j) * np.clip(t - t_step, 0, None))), 0.0)

    ideal = minimize_scalar(lambda j: float(np.mean((ideal_angle(j) - target) ** 2)), bounds=bounds,
                            method="bounded", options={"xatol": 1e-5})
    return {
        "J": float(res.x), "rms": math.sqrt(res.fun), "evaluations": evaluations, "best": best,
        "J_ideal": float(ideal.x), "ideal_rms": math.sqrt(ideal.fun), "ideal_angle": ideal_angle(float(ideal.x)),
        "truth": J_S, "n": n, "bounds": tuple(bounds), "measured": measured,
    }


# --- figures --------------------------------------------------------------------------------
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure_map(result: dict, path: Path) -> Path:
    plt = _plt()
    pts, fits, r = result["points"], result["fits"], result["run"]
    fig, axes = plt.subplots(2, 2, figsize=(13, 9), gridspec_kw={"height_ratios": [1.3, 1]})
    (ax, az), (av, ag) = axes
    v_lin, v_log = np.linspace(1e-5, 0.65, 2000), np.geomspace(2e-4, 0.8, 400)
    for sign, colour in ((+1, "C0"), (-1, "C3")):
        sel = np.sign(pts[:, 0]) == sign
        table = [getattr(TABLE_4_3[sign], n) for n in PARAM_NAMES]
        side = "positive" if sign > 0 else "negative"
        plant = "table 4.3 (the plant)" if sign > 0 else None
        ax.plot(sign * v_lin, sign * tau_ss(v_lin, *table), "k--", lw=1, label=plant)
        ax.plot(sign * v_lin, sign * tau_ss(v_lin, *fits[sign]["x"]), "-", color=colour, lw=1, alpha=0.7,
                label=f"eq. 4.21 fitted, {side}")
        ax.plot(pts[sel, 1], pts[sel, 2], "o", color=colour, ms=4, label=f"measured, {side}")
        az.plot(v_log, tau_ss(v_log, *table), "k--", lw=1, label=plant)
        az.plot(v_log, tau_ss(v_log, *fits[sign]["x"]), "-", color=colour, lw=1, alpha=0.7,
                label=f"eq. 4.21 fitted, {side}")
        az.plot(sign * pts[sel, 1], sign * pts[sel, 2], "o", color=colour, ms=4, label=f"measured, {side}")
    ax.set_xlabel("angular velocity (rad/s)")
    ax.set_ylabel("friction torque = mean torque command (N m)")
    ax.set_title("static friction-velocity map (thesis fig. 4.20)")
    ax.legend(fontsize=8, loc="upper left")
    az.set_xscale("log")
    az.set_xlabel("|angular velocity| (rad/s)")
    az.set_ylabel("|friction torque| (N m)")
    az.set_title("both directions on a log speed axis (figs. 4.21-4.22)")
    az.legend(fontsize=8, loc="upper center")
    # the scan itself (fig. 4.19): desired and measured speed, scheduled gains
    ctrl, t = r.controller, r.time
    desired = np.array([ctrl.desired_speed(x) for x in t])
    angle = r.channels[f"{JOINT}_angle"]
    n = 500  # samples: speed measured over 0.5 s (0.0004 rad/s = 6.5 counts)
    v_meas = (angle[n:] - angle[:-n]) / (n * CONTROL_PERIOD)
    av.plot(t[n // 2:-n // 2], v_meas, color="C1", lw=0.8, label="measured (encoder, 0.5 s differences)")
    av.plot(t, desired, "k", lw=1, label="desired")
    for _, t0, t1 in ctrl.windows():
        av.axvspan(t0, t1, color="0.85", lw=0)
    av.set_yscale("symlog", linthresh=3e-4)
    av.set_xlabel("time (s)")
    av.set_ylabel("speed (rad/s), symlog")
    av.set_title("velocity trajectory (fig. 4.19a); grey: second halves, averaged", fontsize=10)
    av.legend(fontsize=8, loc="lower left")
    gains = np.array([ctrl.gains(v) for v in desired])
    ag.plot(t, gains[:, 0], "C0", label="P (N m s/rad)")
    ag.plot(t, gains[:, 1], "C2", label="I (N m/rad)")
    ag.plot(t, gains[:, 2], "C4", label="velocity filter cutoff (Hz)")
    ag.set_yscale("log")
    ag.set_xlabel("time (s)")
    ag.set_ylabel("gain")
    ag.set_title("scheduled P and I gains (fig. 4.19b, c) and filter cutoff", fontsize=10)
    ag.legend(fontsize=8, loc="lower left")
    for a in axes.flat:
        a.grid(alpha=0.3, which="both")
    fig.suptitle(f"shoulder bench, PI velocity scan: {result['holds']} holds, {result['duration_s']:.0f} s simulated")
    return save_figure(fig, path, dpi=100)


def figure_presliding(result: dict, path: Path) -> Path:
    plt = _plt()
    r = result["run"]
    torque = r.channels[f"{JOINT}_torque_cmd"]
    enc = r.channels[f"{JOINT}_angle"]
    fig, (ax, at) = plt.subplots(1, 2, figsize=(12, 4.8), gridspec_kw={"width_ratios": [1.2, 1]})
    ax.plot(enc * 1e4, torque, "-", color="C0", lw=1.2, label="measured (encoder, 1 count = %.2g rad)" % COUNT)
    ax.plot(r.true_angle * 1e4, torque, "-", color="C1", lw=0.8, label="joint angle in the simulation")
    ax.plot(result["model"] * 1e4, torque, "k--", lw=0.8, label="quasi-static LuGre, eq. 4.20")
    ax.set_xlabel("displacement (1e-4 rad)")
    ax.set_ylabel("torque input (N m)")
    ax.set_title(f"pre-sliding, sigma0 = {result['sigma0']:.3g} N m/rad (thesis fig. 4.17)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    at.plot(r.time, enc * 1e4, color="C0", lw=1.2, label="measured (encoder)")
    at.plot(r.time, r.true_angle * 1e4, color="C1", lw=0.8, label="simulated joint angle")
    at.plot(r.time, result["model"] * 1e4, "k--", lw=0.8, label="quasi-static LuGre")
    at.set_xlabel("time (s)")
    at.set_ylabel("displacement (1e-4 rad)")
    at2 = at.twinx()
    at2.plot(r.time, torque, color="0.6", lw=0.6)
    at2.set_ylabel("torque input (N m), grey")
    at.legend(fontsize=8, loc="lower left")
    at.grid(alpha=0.3)
    return save_figure(fig, path, dpi=110)


def figure_p_step(result: dict, path: Path) -> Path:
    plt = _plt()
    runs = result["runs"]
    fig, (ax, af) = plt.subplots(2, 1, figsize=(10, 7), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    ideal = runs["ideal"]
    ax.plot(ideal.time, ideal.channels[f"{JOINT}_reference"], "k-.", lw=0.8, label="desired angle")
    ax.plot(ideal.time, ideal.channels[f"{JOINT}_angle"], "k--", lw=1.2, label="ideal motor (no friction)")
    styles = {"compensated": ("C0", 1.4), "uncompensated": ("C3", 1.2)}
    for label, r in runs.items():
        if label == "ideal":
            continue
        colour, lw = styles.get(label, ("C2", 0.9))
        row = result["rows"][label]
        corr = "undefined (no motion)" if math.isnan(row["correlation"]) else f"{row['correlation']:.3f}"
        name = "compensated, thesis 10 Hz filter" if label == "compensated" else label
        ax.plot(r.time, r.channels[f"{JOINT}_angle"], color=colour, lw=lw,
                label=f"{name}: r = {corr}, NRMSE = {row['nrmse']:.2f}")
        if r.compensation is not None:
            af.plot(r.time, r.compensation, color=colour, lw=0.8, label=name)
    ax.set_ylabel("angle (rad)")
    ax.set_title("shoulder bench, P 5 N m/rad, 1 rad step: qualified exponential compensation (thesis fig. 4.27)")
    ax.grid(alpha=0.3)
    ax.set_ylim(-0.1, 2.85)
    ax.legend(fontsize=8, loc="upper center", ncol=2)
    af.set_ylabel("compensation torque (N m)")
    af.set_xlabel("time (s)")
    af.set_title("estimated friction torque (thesis fig. 4.28)", fontsize=9)
    af.grid(alpha=0.3)
    af.legend(fontsize=8, loc="lower right")
    return save_figure(fig, path, dpi=110)


def figure_inertia(result: dict, measured: Run, path: Path) -> Path:
    plt = _plt()
    n = result["n"]
    t = measured.time[:n]
    angle = measured.channels[f"{JOINT}_angle"][:n]
    fig = plt.figure(figsize=(12, 6.5))
    grid = fig.add_gridspec(2, 2, width_ratios=[2, 1], height_ratios=[2, 1])
    ax, ae, ac = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[1, 0]), fig.add_subplot(grid[:, 1])
    ax.sharex(ae)
    fitted = result["best"].channels[f"{JOINT}_angle"]
    ax.plot(t, measured.channels[f"{JOINT}_reference"][:n], "k-.", lw=0.8, label="step input")
    ax.plot(t, angle, "C0", lw=2.0, label="measured (compensated step)")
    ax.plot(t, fitted, "C1--", lw=1.2, label=f"re-simulated bench, fitted J = {result['J']:.4f} kg m^2")
    ax.plot(t, result["ideal_angle"], "C2:", lw=1.2, label=f"ideal motor fit, J = {result['J_ideal']:.3f} kg m^2")
    ax.set_ylabel("angle (rad)")
    ax.set_title("inertia identification (thesis 4.5.6, fig. 4.30)")
    ax.set_ylim(-0.1, 2.75)
    ax.legend(fontsize=8, loc="upper center", ncol=2)
    ae.plot(t, (fitted - angle) * 1e3, "C1", lw=1, label="re-simulated - measured")
    ae.plot(t, (result["ideal_angle"] - angle) * 1e3, "C2", lw=1, label="ideal motor - measured")
    ae.set_xlabel("time (s)")
    ae.set_ylabel("error (mrad)")
    ae.legend(fontsize=8, loc="lower left")
    ev = np.array(sorted(result["evaluations"]))
    ac.semilogy(ev[:, 0], np.sqrt(ev[:, 1]) + 1e-9, "o-", ms=3, label="re-simulations")
    ac.axvline(result["truth"], color="k", ls="--", lw=0.8, label=f"J_S = {result['truth']} kg m^2 (the model's)")
    ac.set_xlabel("armature J (kg m^2)")
    ac.set_ylabel("rms angle error (rad)")
    ac.set_title("cost at the evaluated J (minimize_scalar, bounded)", fontsize=9)
    ac.legend(fontsize=8)
    for a in (ax, ae, ac):
        a.grid(alpha=0.3, which="both")
    return save_figure(fig, path, dpi=110)


def figure_dwell(result: dict, path: Path) -> Path:
    plt = _plt()
    r = result["run"]
    t, torque = r.time, r.channels[f"{JOINT}_torque_cmd"]
    level = result["nominal"] * (1 + result["gain"] * (1 - np.exp(-t / result["dwell_time"])))
    fig, (ax, az) = plt.subplots(2, 1, figsize=(10, 7.5))
    for a in (ax, az):
        a.plot(t, torque, "C0", lw=1.4, label="torque input (after the converter)")
        a.plot(t, level, "C1", lw=1, label="break-away of the law after t at rest (the model)")
        a.axhline(result["nominal"], color="k", ls=":", lw=1,
                  label=f"nominal break-away alpha0 + alpha1 = {result['nominal']:.3f} N m")
        a.axhline(result["expected_10s"], color="C2", ls="--", lw=1,
                  label=f"after 10 s at rest: (2 - e^-5) x nominal = {result['expected_10s']:.3f} N m")
        if not math.isnan(result["breakaway"]):
            a.plot(result["t_break"], result["breakaway"], "rv", ms=9,
                   label=f"measured break-away {result['breakaway']:.3f} N m at t = {result['t_break']:.2f} s")
        a.set_ylabel("torque (N m)")
        a.grid(alpha=0.3)
    ax.set_title("dwell-time dependent break-away, shoulder bench (thesis 4.1.6, fig. 4.5)")
    ax.set_ylim(-1, result["expected_10s"] * 1.15)
    ax.legend(fontsize=8, loc="center left")
    ax.set_xlabel("time (s)")
    if not math.isnan(result["breakaway"]):
        az.set_xlim(result["t_break"] - 2.5, result["t_break"] + 1.0)
        az.set_ylim(result["expected_10s"] - 0.4, result["expected_10s"] + 0.3)
    az.set_xlabel("time (s)")
    az.set_title("zoom on the break-away; angle in grey (right axis)", fontsize=10)
    aa = az.twinx()
    aa.plot(t, (r.channels[f"{JOINT}_angle"] - r.channels[f"{JOINT}_angle"][0]) / COUNT, color="0.5", lw=1)
    aa.set_ylabel("angle (encoder counts)")
    aa.set_ylim(-1, 10)
    return save_figure(fig, path, dpi=110)


# --- command line ------------------------------------------------------------------------------
def _print_map(result: dict) -> None:
    print(f"\n1. Friction-velocity map (thesis 4.5.4, eq. 4.21, table 4.3): {result['holds']} holds, "
          f"{result['duration_s']:.0f} s simulated, angle within [{result['angle_range'][0]:.2f}, "
          f"{result['angle_range'][1]:.2f}] rad (limit +-{3 * 2 * math.pi:.2f})")
    print(f"   {'dir':>3} {'param':>7} {'unit':>10} {'fitted':>10} {'+-1 sigma':>10} {'table 4.3':>10} {'error %':>8}")
    for sign, fit in result["fits"].items():
        for i, (name, unit) in enumerate(zip(PARAM_NAMES, PARAM_UNITS)):
            print(f"   {'+' if sign > 0 else '-':>3} {name:>7} {unit:>10} {fit['x'][i]:10.5f} {fit['stderr'][i]:10.2g} "
                  f"{fit['truth'][i]:10.4f} {fit['error_pct'][i]:+8.3f}")
        print(f"       residual rms {fit['rms'] * 1e3:.2f} mN m over {fit['n']} points, "
              f"scaled condition number {fit['cond']:.3g}")
    worst = max(abs(e) for fit in result["fits"].values() for e in fit["error_pct"])
    print(f"   largest error {worst:.3f} % (target 3 %): {'PASS' if worst < 3 else 'FAIL'}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] + " Prints a results table; "
                                     "writes PNG figures (friction_map, presliding, p_step_compensated, "
                                     "inertia_step, dwell).")
    parser.add_argument("--quick", action="store_true",
                        help="shorter scan (10 speeds per direction, holds 2-5 s: 70 s simulated) and an inertia "
                             "fit over the first 12 s of the step")
    parser.add_argument("--only", nargs="+", choices=["map", "presliding", "dwell", "pstep", "inertia"],
                        help="run only these experiments")
    parser.add_argument("--out", type=Path, default=DOCS, help="directory for the PNG figures (default docs/)")
    parser.add_argument("--no-figures", action="store_true", help="print the table only")
    parser.add_argument("--wait-s", type=float, default=0.0,
                        help="seconds (s) to wait, polling once a minute, for controllers/friction_compensation.py")
    args = parser.parse_args(argv)
    todo = set(args.only or ["map", "presliding", "dwell", "pstep", "inertia"])
    figures = []
    if not args.no_figures:
        args.out.mkdir(parents=True, exist_ok=True)
    start = wallclock.perf_counter()

    if "map" in todo:
        result = friction_map(args.quick)
        _print_map(result)
        if not args.no_figures:
            figures.append(figure_map(result, args.out / "friction_map.png"))

    if "presliding" in todo:
        result = presliding()
        e, tr, qs = result["encoder"], result["true"], result["quasi_static"]
        print(f"\n2. Pre-sliding (thesis fig. 4.17): LuGre sigma0 = {result['sigma0']:.3g} N m/rad, "
              f"sigma1 = {result['sigma1']:g} N m s/rad, triangle +-{result['amplitude']:.3f} N m at 2.4 N m/s, "
              f"4 periods of {result['period']:.2f} s")
        print(f"   per cycle, mean of {e['cycles']} after the first loading")
        print(f"   {'':24} {'loop width (rad)':>17} {'opening at 0 N m (rad)':>23}")
        for label, m in (("measured (encoder)", e), ("simulated joint angle", tr), ("quasi-static LuGre", qs)):
            print(f"   {label:24} {m['width']:17.3e} {m['opening']:23.3e}")
        print(f"   thesis fig. 4.17: about 1.4e-4 rad; drift {result['drift_per_period']:+.2e} rad per period "
              f"(LuGre with unequal break-away per direction); one encoder count = {COUNT:.3e} rad")
        if not args.no_figures:
            figures.append(figure_presliding(result, args.out / "presliding.png"))

    if "dwell" in todo:
        result = dwell()
        print("\n3. Dwell time (thesis 4.1.6; dwell_gain 1, dwell_time 2 s): 10 s at rest, then 0.2 N m/s")
        rows = [
            ("nominal break-away alpha0 + alpha1", result["nominal"], ""),
            ("expected after 10 s: (2 - e^-5) x nominal", result["expected_10s"], ""),
            ("measured break-away (first count moved)", result["breakaway"],
             f"at t = {result['t_break']:.3f} s: {100 * (result['breakaway'] / result['expected_10s'] - 1):+.2f} % vs "
             f"expected, {result['breakaway'] / result['nominal']:.3f} x nominal"),
            ("the level before (no count moved)", result["held"], "ramp resolution: one converter code"),
            (f"the law after {result['t_break']:.2f} s at rest", result["law_at_rest"],
             f"measured {100 * (result['breakaway'] / result['law_at_rest'] - 1):+.2f} %"),
        ]
        for label, value, note in rows:
            print(f"   {label:42} {value:8.4f} N m  {note}")
        if not args.no_figures:
            figures.append(figure_dwell(result, args.out / "dwell.png"))

    compensation = bool(todo & {"pstep", "inertia"}) and wait_for_compensation(args.wait_s)
    if "pstep" in todo and compensation:
        pstep = p_step()
        print("\n4. Compensated P step (thesis 4.5.5, fig. 4.27): P 5 N m/rad, 1 rad at 1 s, 25 s; "
              "qualified exponential compensation k_gamma 100 s/rad, k_tau 1 rad/(N m s), delta 0.01 N m, "
              "k_S 300 s/rad")
        print(f"   {'vs the ideal frictionless motor':44} {'correlation':>11} {'NRMSE':>7} {'period (s)':>10}")
        for label, row in pstep["rows"].items():
            corr = "  undefined" if math.isnan(row["correlation"]) else f"{row['correlation']:11.4f}"
            name = {"compensated": "compensated (thesis: 10 Hz velocity filter)"}.get(label, label)
            extra = "  (never moved: 5 N m < break-away 9.42 N m)" if row["moved"] == 0 else ""
            print(f"   {name:44} {corr} {row['nrmse']:7.3f} {row['period']:10.3f}{extra}")
        print(f"   ideal period 2 pi sqrt(J_S / P) = {2 * math.pi * math.sqrt(J_S / 5.0):.3f} s")
        if not args.no_figures:
            figures.append(figure_p_step(pstep, args.out / "p_step_compensated.png"))

    if "inertia" in todo and compensation:
        result = identify_inertia(duration_s=12.0 if args.quick else None)
        err = 100 * (result["J"] / result["truth"] - 1)
        print(f"\n5. Inertia (thesis 4.5.6): watflex_inertia_step re-simulated with the armature free, "
              f"{result['n'] * CONTROL_PERIOD:.0f} s fitted, {len(result['evaluations'])} simulations")
        print(f"   fitted J = {result['J']:.4f} kg m^2 (model J_S = {result['truth']}: {err:+.3f} %), "
              f"rms angle error {result['rms']:.2e} rad")
        print(f"   thesis' ideal-motor assumption (1 - cos(sqrt(P/J) t)): J = {result['J_ideal']:.4f} kg m^2 "
              f"({100 * (result['J_ideal'] / result['truth'] - 1):+.2f} %), rms {result['ideal_rms']:.3f} rad")
        if not args.no_figures:
            figures.append(figure_inertia(result, result["measured"], args.out / "inertia_step.png"))

    print(f"\n{wallclock.perf_counter() - start:.1f} s wall")
    for path in figures:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
