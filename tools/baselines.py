"""The two baselines the diagnosis is compared with in the benchmark (issue: "Baselines").

(a) `refit_only`: refit the rig's nominal parameters within tolerance by least squares (what a
    mujoco.sysid-style fit gives). It cannot name missing physics: its effect is always None.
(b) `sindy_residual`: on top of (a), sparse regression (pysindy's STLSQ) of the output residual
    (measured - simulated, each channel divided by its spread as diagnose does) on a library of
    functions of the *simulated* motion and commands; the largest surviving term names an effect.

Both fit on the training samples of `diagnose.prepare` and are judged on the held-out ones with
`diagnose.fit_scores` (NRMSE, mean over channels). Usage: python tools/baselines.py REC.csv [...]
"""
from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402
from scipy.signal import savgol_filter  # noqa: E402

from watflex_sim import diagnosis as diagnose  # noqa: E402
from watflex_sim.params import LASER_ARM  # noqa: E402
from watflex_sim.recording import Recording, read_recording  # noqa: E402

try:
    from pysindy.optimizers import STLSQ
except ImportError:  # the optional `benchmark` extra
    STLSQ = None

SMOOTH_S = 0.021  # s, Savitzky-Golay window (cubic) for the simulated velocity and acceleration
DELAY_S = 0.005  # s, the shift of the delay term u(t - DELAY_S) - u(t)
DEADBAND = 0.02  # sign(v) is 0 below this fraction of the peak simulated speed (rest is not a direction)
V_STRIBECK = 0.1  # v_s of the Stribeck term, as a fraction of the peak simulated speed
SPANNED = 0.9999  # a term the earlier ones explain to this R^2 (training samples) is dropped

EFFECT = {"1": "actuator_offset", "q": "joint_compliance", "v": "viscous_friction",
          "sign(v)": "coulomb_friction", "sign(v)[v>0]": "coulomb_friction", "sign(v)[v<0]": "coulomb_friction",
          "exp(-|v|/vs)sign(v)": "stribeck_friction", "sin(q)": "position_dependent_friction",
          "cos(q)": "position_dependent_friction", "tip_acc": "payload"}


def refit_only(recordings: list[Recording], names: list[str]) -> dict:
    """Baseline (a): nominal re-simulation, then the rig's parameters refit within tolerance.

    Returns effect None, NRMSE (dimensionless) before/after on held-out and training samples,
    the refit ratios to nominal and the wall time (s)."""
    start = time.perf_counter()
    data = diagnose.prepare(recordings, names)
    nominal = diagnose.simulate_all(data, diagnose.Model())
    model = diagnose.refit_parameters(data, diagnose.Model())
    sims = diagnose.simulate_all(data, model)
    score = lambda s, part: diagnose.fit_scores(data, s, part)["nrmse"]  # noqa: E731
    if score(sims, "held_out") > score(nominal, "held_out"):  # as the diagnosis: a refit (fitted in noise
        model, sims = diagnose.Model(), nominal  # units) must not make validation worse, here in NRMSE
    return {"effect": None,
            "held_out": {"before": score(nominal, "held_out"), "after": score(sims, "held_out")},
            "train": {"before": score(nominal, "train"), "after": score(sims, "train")},
            "refit_parameters": dict(model.parameters), "seconds": time.perf_counter() - start}


def _library(rec: Recording, sim: Recording, rig, motion: str, v_peak: float) -> dict[str, np.ndarray]:
    """Candidate terms (name -> samples) from the simulated motion channel q (rad or m), its
    velocity v, the simulated commands u and the simulated tip's acceleration."""
    t = rec.time
    dt = float(np.median(np.diff(t)))
    q = sim.channels[motion]
    v = _smooth(q, dt, 1)
    moving = np.abs(v) > DEADBAND * v_peak
    sign = np.sign(v) * moving
    terms = {"1": np.ones_like(t), "q": q, "v": v, "sign(v)": sign,
             "sign(v)[v>0]": sign * (v > 0), "sign(v)[v<0]": sign * (v < 0),
             "exp(-|v|/vs)sign(v)": np.exp(-np.abs(v) / (V_STRIBECK * v_peak)) * sign}
    for c in rig.of_kind("command"):
        if c in sim.channels:
            u = sim.channels[c]
            terms[c] = u
            terms[f"{c}(t-{DELAY_S * 1e3:g}ms)-{c}"] = np.interp(t - DELAY_S, t, u) - u
    terms["sin(q)"], terms["cos(q)"] = np.sin(q), np.cos(q)
    terms["tip_acc"] = _smooth(_tip(sim, rig, motion), dt, 2)
    return terms


def _tip(sim: Recording, rig, motion: str) -> np.ndarray:
    """The tip's position the rig shows: the laser arm's tip angle (rad) from reference and tip
    sensor, the Watflex end effector's angle about the shoulder (rad), else the motion channel."""
    ch = sim.channels
    if rig.name == "laser_arm" and {"reference", "tip_sensor"} <= set(ch):
        return ch["reference"] - ch["tip_sensor"] / (LASER_ARM.sensor_gain * LASER_ARM.beam.length)
    if {"tip_x", "tip_y"} <= set(ch):
        return np.unwrap(np.arctan2(ch["tip_y"], ch["tip_x"]))
    return ch[motion]


def _smooth(x: np.ndarray, dt: float, deriv: int) -> np.ndarray:
    """Savitzky-Golay derivative of order `deriv` (unit/s^deriv), cubic over SMOOTH_S; missing
    samples (a camera's frames) interpolated first."""
    ok = np.isfinite(x)
    if not ok.all():
        x = np.interp(np.arange(x.size), np.flatnonzero(ok), x[ok])
    n = x.size if x.size % 2 else x.size - 1
    window = min(max(5, int(round(SMOOTH_S / dt)) | 1), n)
    return savgol_filter(x, window, min(3, window - 1), deriv=deriv, delta=dt)


def sindy_residual(recordings: list[Recording], names: list[str], threshold: float = 0.02,
                   parameters: dict | None = None) -> dict:
    """Baseline (b): STLSQ regression of the scaled output residual on the term library.

    `threshold`: smallest RMS contribution a term keeps, as a fraction of a channel's spread
    (columns are scaled to unit RMS on the training samples, so this is STLSQ's threshold).
    `parameters`: refit ratios from `refit_only` to reuse; None refits them here.
    Named effect: that of the term with the largest contribution (root-sum-square over channels);
    the constant term is `sensor_offset` (at that channel) if it is the only term on one measured
    channel and appears on no other, else `actuator_offset`. Other effects are placed at the
    motion joint. Coefficients are in channel unit per term unit; NRMSE dimensionless; seconds wall.
    """
    if STLSQ is None:
        raise ImportError("the SINDy baseline needs pysindy: pip install -e '.[benchmark]'")
    start = time.perf_counter()
    data = diagnose.prepare(recordings, names)
    model = diagnose.Model(parameters=dict(parameters)) if parameters is not None else \
        diagnose.refit_parameters(data, diagnose.Model())
    sims = diagnose.simulate_all(data, model)
    if sims is None:
        raise RuntimeError("the refit nominal model diverges on these recordings")
    rig = data.rig
    motion = diagnose.motion_channel(recordings[0], rig)
    if motion is None:
        raise ValueError(f"no measured joint position of rig {rig.name} in the recordings: the library needs one")
    chans = [c for c in data.channels[0] if all(c in cs for cs in data.channels)]
    dt = [float(np.median(np.diff(r.time))) for r in recordings]
    v_peak = max(float(np.max(np.abs(_smooth(s.channels[motion], h, 1)))) for s, h in zip(sims, dt)) or 1.0
    libs = [_library(r, s, rig, motion, v_peak) for r, s in zip(recordings, sims)]
    X = np.vstack([np.column_stack(list(lib.values())) for lib in libs])
    Y = np.vstack([np.column_stack([(r.channels[c] - s.channels[c]) / sc[c] for c in chans])
                   for r, s, sc in zip(recordings, sims, data.scale)])
    train = np.concatenate(data.train)
    names_all = list(libs[0])
    rms = np.sqrt(np.mean(X[train] ** 2, axis=0))
    keep = []  # drop dead terms and terms the earlier ones already span (the data cannot tell them apart)
    for k in range(X.shape[1]):
        if rms[k] <= 0:
            continue
        col = X[train, k] / rms[k]
        if keep:
            base = X[train][:, keep] / rms[keep]
            fit = base @ np.linalg.lstsq(base, col, rcond=None)[0]
            if 1 - np.mean((col - fit) ** 2) / np.mean(col**2) > SPANNED:
                continue
        keep.append(k)
    Z = X[:, keep] / rms[keep]
    beta = np.zeros((len(chans), len(keep)))  # one fit per channel: STLSQ drops a sample (row) with any NaN target
    for j in range(len(chans)):
        rows = train & np.isfinite(Y[:, j])
        with warnings.catch_warnings():  # "eliminated all coefficients" is a result here (effect None), not a fault
            warnings.filterwarnings("ignore", message="Sparsity parameter is too big")
            beta[j] = STLSQ(threshold=threshold).fit(Z[rows], Y[rows, j]).coef_.ravel()
    pred = Z @ beta.T
    corrected = []
    for i, (r, s, sc) in enumerate(zip(recordings, sims, data.scale)):
        rows = slice(sum(x.size for x in data.train[:i]), sum(x.size for x in data.train[: i + 1]))
        ch = dict(s.channels)
        for j, c in enumerate(chans):
            ch[c] = s.channels[c] + pred[rows, j] * sc[c]
        corrected.append(Recording(s.time, ch, s.meta))
    terms = {}
    for col, k in enumerate(keep):
        if not np.any(beta[:, col]):
            continue
        name = names_all[k]
        # channel unit per term unit, with the first recording's spread
        per_channel = {c: float(beta[j, col] * data.scale[0][c] / rms[k]) for j, c in enumerate(chans) if beta[j, col]}
        terms[name] = {"effect": _effect(name, per_channel, chans, beta, rig), "rms": float(np.linalg.norm(beta[:, col])),
                       "coefficients": per_channel}
    by_effect = {}  # RMS (fraction of spread, root-sum-square over channels) of each effect's terms together
    for e in {t["effect"] for t in terms.values()}:
        cols = [col for col, k in enumerate(keep) if names_all[k] in terms and terms[names_all[k]]["effect"] == e]
        by_effect[e] = float(np.sqrt(np.sum(np.mean((Z[train][:, cols] @ beta[:, cols].T) ** 2, axis=0))))
    best = max(terms, key=lambda n: terms[n]["rms"], default=None)
    effect = terms[best]["effect"] if best else None
    joint = rig.channels[motion].get("joint") or motion.removesuffix("_angle")
    score = lambda s, part: diagnose.fit_scores(data, s, part)["nrmse"]  # noqa: E731
    return {"effect": effect,
            "where": next(iter(terms[best]["coefficients"])) if effect == "sensor_offset" else joint,
            "terms": terms, "by_effect": by_effect, "dropped": [n for k, n in enumerate(names_all) if k not in keep],
            "held_out": {"before": score(sims, "held_out"), "after": score(corrected, "held_out")},
            "train": {"before": score(sims, "train"), "after": score(corrected, "train")},
            "seconds": time.perf_counter() - start}


def _effect(name: str, per_channel: dict, chans: list[str], beta: np.ndarray, rig) -> str:
    """Catalogue effect of a library term (the constant by the rule in `sindy_residual`)."""
    if "(t-" in name:
        return "delay"
    if name in rig.of_kind("command"):
        return "actuator_gain"
    if name == "1" and len(per_channel) == 1:
        c = next(iter(per_channel))
        alone = np.count_nonzero(beta[chans.index(c)]) == 1
        if alone and rig.channels[c]["kind"] == "measured":
            return "sensor_offset"
    return EFFECT[name]


def main(argv: list[str] | None = None) -> int:
    """Run both baselines on recordings and print one JSON object."""
    paths = (argv if argv is not None else sys.argv[1:])
    if not paths:
        print("usage: python tools/baselines.py REC.csv [REC2.csv ...]", file=sys.stderr)
        return 2
    recordings, names = [read_recording(p) for p in paths], [Path(p).name for p in paths]
    refit = refit_only(recordings, names)
    out = {"refit_only": refit}
    try:
        out["sindy_residual"] = sindy_residual(recordings, names, parameters=refit["refit_parameters"])
    except ImportError as exc:
        out["sindy_residual"] = {"error": str(exc)}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
