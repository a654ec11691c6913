"""An independent simulator of rigs.md, sharing no code with watflex_sim, for trying the diagnosis off home ground:
recordings of the same datasheet from a simulator that discretises, damps, integrates and handles friction its own
way, written as an outsider would (CSV and a minimal sidecar, by hand).

Usage: python tools/independent_sim.py laser_arm OUT_DIR [--payload KG ...] [--coulomb POS NEG] [--hidden-payload KG]
                                      [--seed N]
       python tools/independent_sim.py watflex_elbow OUT_DIR [--payload KG ...] [--friction-scale X]
                                      [--hidden-payload KG] [--delay MS] [--seed N]

Both: a finite-element Euler-Bernoulli beam (ELEMENTS Hermite cubic elements, w and w' at each node) clamped to a
rotating hub, small deflection (no centrifugal stiffening), modal damping ratio 0.01 on every clamped-beam mode (the
sheet's words taken literally), a point mass at the end (its rotary inertia neglected); the linear part integrated
exactly (matrix exponential) over SUBSTEP, the drive and friction chosen and held at each substep's start; friction
as Karnopp stick-slip: below STICK rad/s the hub sticks while the torque that holds it (its row with theta'' = 0) is
within the break-away level of the way it is pushed, the beam then vibrating on a held hub; a sliding hub whose speed
changes sign within a substep is stopped. Sensors are sampled at each 1 ms tick before the controller's new command.

laser_arm (rigs.md section 1): hub J_hub + N^2 J_e, viscous mu_arm + N^2 mu_e, tip mass 0.15 kg + payload; voltage
drive i = clip((u - K_E w)/R, +-1.9 A), 12.48 N m/A at the hub; PD on the tip sensor (K_p 0.127 V/V); e_V with
0.01 V rms noise then saturated at +-10 V, encoder 2 pi/(4 1024 80) rad, current monitor + 4 mA rms (sampled with
the new command); 2.5 mm steps at t = 0.1 s; optional gear Coulomb friction, the physics the nominal model leaves out.
watflex_elbow (rigs.md section 2, the single-link set-up, thesis 5.2.4): the elbow drives link 2 (rigid 0.14 m,
flexible 0.47 m, rigid 0.083 m to the 8.1 kg end effector + payload) from a fixed base; hub J_E 1.25 kg m^2; the
exponential friction of the table (Karnopp, break-away alpha0 + alpha1 of each direction), scaled by
--friction-scale (1: nominal); the elbow PD (60 N m/rad, 12 N m s/rad, the rate a backward difference through a
2nd-order 10 Hz Butterworth filter), its torque through the 12-bit converter over +-10 V (5.381 N m/V); encoder
2 pi/204800 rad; strain bridges 2A, 2B (eps = -(t/2) w'', V = eps/K, 2 mV rms then 12 bits over +-10 V); +-0.5 rad
steps at 0.5 s and the staircase 0 -> 0.1 -> 0.2 -> 0.1 -> 0 rad.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.linalg import eigh, expm
from scipy.signal import butter, lfilter

PERIOD, SUBSTEP, ELEMENTS, STICK = 1e-3, 5e-5, 12, 2e-4  # s, s, -, rad/s
ZETA = 0.01  # modal damping ratio of every bending mode; rigs.md sections 1, 2 [choice]


@dataclass(frozen=True)
class Link:
    """A flexible link on a hub: lengths in m from the axis, EI in N m^2, rho in kg/m, masses in kg."""
    root: float  # rigid part from the axis to the beam's root clamp
    length: float  # the flexible part
    EI: float
    rho: float
    tip_mass: float
    tip_offset: float  # rigid part from the beam's end to the point mass
    hub_inertia: float  # kg m^2, all rigid parts turning with the hub
    hub_viscous: float  # N m s/rad


@dataclass(frozen=True)
class Friction:
    """Sliding tau(v) = alpha0 + alpha1 exp(-(v/v_s)^2) + alpha2 |v| against the motion, sticking below alpha0 +
    alpha1; (positive direction, negative direction) each, N m, N m s/rad, rad/s."""
    alpha0: tuple[float, float]
    alpha1: tuple[float, float] = (0.0, 0.0)
    alpha2: tuple[float, float] = (0.0, 0.0)
    v_s: tuple[float, float] = (1.0, 1.0)

    def breakaway(self, side: int) -> float:
        """N m the joint holds at rest when pushed the positive (side 0) or negative (1) way."""
        return self.alpha0[side] + self.alpha1[side]

    def sliding(self, v: float) -> float:
        """N m against a motion at `v` rad/s."""
        s = 0 if v > 0 else 1
        return self.alpha0[s] + self.alpha1[s] * math.exp(-(v / self.v_s[s]) ** 2) + self.alpha2[s] * abs(v)


def matrices(link: Link) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass, damping and stiffness of [theta, w_1, w'_1, ..., w_n, w'_n] (SI units)."""
    h, n = link.length / ELEMENTS, 2 * ELEMENTS + 1
    M, K = np.zeros((n, n)), np.zeros((n, n))
    ke = link.EI / h**3 * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                                    [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    me = link.rho * h / 420 * np.array([[156, 22 * h, 54, -13 * h], [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                                        [54, 13 * h, 156, -22 * h], [-13 * h, -3 * h * h, -22 * h, 4 * h * h]])
    for e in range(ELEMENTS):
        x0 = link.root + e * h
        dofs = [2 * e - 1, 2 * e, 2 * e + 1, 2 * e + 2]  # node e's (w, w'), node e+1's; node 0 is clamped
        coupling = link.rho * (x0 * h * np.array([0.5, h / 12, 0.5, -h / 12])
                               + h * h * np.array([3 / 20, h / 30, 7 / 20, -h / 20]))  # int rho x N dx
        for a, da in enumerate(dofs):
            if da < 1:
                continue
            M[0, da] += coupling[a]
            M[da, 0] += coupling[a]
            for b, db in enumerate(dofs):
                if db >= 1:
                    M[da, db] += me[a, b]
                    K[da, db] += ke[a, b]
    end = link.root + link.length
    reach = end + link.tip_offset
    M[0, 0] += link.hub_inertia + link.rho * (end**3 - link.root**3) / 3 + link.tip_mass * reach**2
    g = np.zeros(n)  # the point mass's transverse displacement: w(L) + offset w'(L)
    g[n - 2], g[n - 1] = 1.0, link.tip_offset
    M[0, :] += link.tip_mass * reach * g
    M[:, 0] += link.tip_mass * reach * g
    M += link.tip_mass * np.outer(g, g)
    beam = slice(1, n)
    omega_sq, shapes = eigh(K[beam, beam], M[beam, beam])  # clamped-beam modes, mass-normalised
    C = np.zeros((n, n))
    Mb = M[beam, beam]
    C[beam, beam] = Mb @ shapes @ np.diag(2 * ZETA * np.sqrt(omega_sq)) @ shapes.T @ Mb
    C[0, 0] = link.hub_viscous
    return M, C, K


def curvature(link: Link, x: float, q: np.ndarray) -> float:
    """w''(x) in 1/m at `x` m from the beam's root, from the generalised coordinates `q`."""
    h = link.length / ELEMENTS
    e = min(int(x / h), ELEMENTS - 1)
    xi = x / h - e
    d = [q[i] if i >= 1 else 0.0 for i in (2 * e - 1, 2 * e, 2 * e + 1, 2 * e + 2)]
    shape = (-6 + 12 * xi, h * (-4 + 6 * xi), 6 - 12 * xi, h * (-2 + 6 * xi))
    return sum(s * v for s, v in zip(shape, d)) / h**2


def discretised(M, C, K, hub_damping: float, voltage_gain: float) -> tuple[np.ndarray, np.ndarray]:
    """(Ad, Bd) of x = [q, q'] over SUBSTEP, inputs [u in V, a torque at the hub in N m] held; `hub_damping` N m s/rad
    added at the hub, `voltage_gain` N m/V."""
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    C = C.copy()
    C[0, 0] += hub_damping
    inputs = np.zeros((n, 2))
    inputs[0] = voltage_gain, 1.0
    A = np.zeros((2 * n + 2, 2 * n + 2))
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n] = -Minv @ K
    A[n:2 * n, n:2 * n] = -Minv @ C
    A[n:2 * n, 2 * n:] = Minv @ inputs
    E = expm(A * SUBSTEP)
    return E[:2 * n, :2 * n], E[:2 * n, 2 * n:]


class Arm:
    """The discretised arm: its matrices, their SUBSTEP transitions, and the state [q, q'] stepped with a drive and
    the joint's friction."""

    def __init__(self, link: Link, friction: Friction | None, emf_damping: float = 0.0, voltage_gain: float = 0.0):
        self.friction, self.voltage_gain = friction, voltage_gain
        self.M, C, K = matrices(link)
        self.n = self.M.shape[0]
        self.driven = discretised(self.M, C, K, emf_damping, voltage_gain)  # a voltage drive with its back-EMF
        self.pushed = discretised(self.M, C, K, 0.0, 0.0)  # a torque drive (or the current at its limit)
        self.held = discretised(self.M[1:, 1:], C[1:, 1:], K[1:, 1:], 0.0, 0.0)[0]  # the beam on a hub held still
        self.beam_acceleration = -np.linalg.solve(self.M[1:, 1:], np.hstack([K[1:, 1:], C[1:, 1:]]))
        self.x = np.zeros(2 * self.n)

    def step(self, drive) -> None:
        """One SUBSTEP; drive(w) gives (u V through the voltage drive or None, a torque N m at the hub)."""
        x, n = self.x, self.n
        w = x[n]
        friction = 0.0  # N m on the hub, signed
        if self.friction is not None and abs(w) < STICK:  # the torque that holds it still
            beam = np.concatenate([x[1:n], x[n + 1:]])
            u, torque = drive(0.0)
            applied = torque + (self.voltage_gain * u if u is not None else 0.0)
            hold = float(self.M[0, 1:] @ (self.beam_acceleration @ beam)) - applied
            side = 0 if hold < 0 else 1  # pushed the positive way: friction holds it negative
            if abs(hold) <= self.friction.breakaway(side):
                beam = self.held @ beam
                self.x = np.concatenate([[x[0]], beam[:n - 1], [0.0], beam[n - 1:]])
                return
            friction = -self.friction.breakaway(side) if side == 0 else self.friction.breakaway(side)
        elif self.friction is not None:
            friction = -math.copysign(self.friction.sliding(w), w)
        u, torque = drive(w)
        if u is not None:
            new = self.driven[0] @ x + self.driven[1] @ (u, torque + friction)
        else:
            new = self.pushed[0] @ x + self.pushed[1] @ (0.0, torque + friction)
        if abs(w) >= STICK and new[n] * w < 0:
            new[n] = 0.0  # the friction stopped it within the substep
        self.x = new

    def period(self, drive) -> None:
        """One control period of substeps."""
        for _ in range(int(round(PERIOD / SUBSTEP))):
            self.step(drive)


def quantised(value: float, unit: float) -> float:
    """`value` rounded to a whole number of `unit`s."""
    return unit * math.floor(value / unit + 0.5)


# laser arm, rigs.md section 1 (paper tables 1, 2, 4)
LASER_L = 1.18  # m
K_E, R, TORQUE_PER_AMP, I_MAX, U_MAX = 20.53, 3.4, 0.6 * 80 * 0.26, 1.9, 24.0  # V s/rad, ohm, N m/A, A, V


def laser_step(payload: float, direction: int, duration: float, coulomb: tuple[float, float], seed: int,
               kp: float = 0.127) -> dict[str, np.ndarray]:
    """laser_arm_step: 2.5 mm at the tip at 0.1 s, `direction` +1 clockwise / -1; channels each 1 ms, SI units."""
    rng = np.random.default_rng(seed)
    link = Link(0.0, LASER_L, 8404.0, 0.75, 0.15 + payload, 0.0, 0.0194 + 0.768, 0.222 + 0.896)
    friction = Friction(tuple(coulomb)) if any(coulomb) else None
    arm = Arm(link, friction, TORQUE_PER_AMP * K_E / R, TORQUE_PER_AMP / R)
    n = arm.n
    encoder = 2 * math.pi / (4 * 1024 * 80)
    out = _channels(duration, ("reference", "hub_angle", "tip_sensor", "voltage_cmd", "motor_current"))
    for k, t in enumerate(out["time"]):
        theta_c = direction * 0.0025 / LASER_L if t >= 0.1 - 1e-12 else 0.0
        theta, tip_w, w = arm.x[0], arm.x[n - 2], arm.x[n]
        e = float(np.clip(3300.0 * (LASER_L * theta_c - LASER_L * theta - tip_w) + rng.normal(0, 0.01), -10, 10))
        u = float(np.clip(kp * e, -U_MAX, U_MAX))
        out["reference"][k], out["hub_angle"][k] = theta_c, quantised(theta, encoder)
        out["tip_sensor"][k], out["voltage_cmd"][k] = e, u
        out["motor_current"][k] = float(np.clip((u - K_E * w) / R, -I_MAX, I_MAX)) + rng.normal(0, 0.004)

        def drive(w, u=u):
            i = (u - K_E * w) / R
            return (u, 0.0) if abs(i) <= I_MAX else (None, TORQUE_PER_AMP * math.copysign(I_MAX, i))
        arm.period(drive)
    return out


# Watflex single-link set-up, rigs.md section 2 (thesis tables 3.2, 4.1, A.1, eq. 4.5, 5.4)
THICKNESS = 0.0048  # m, link 2
LINK2 = dict(root=0.14, length=0.47, EI=70e9 * 0.0382 * THICKNESS**3 / 12, rho=2700 * 0.0382 * THICKNESS,
             tip_offset=0.083, hub_inertia=1.25, hub_viscous=0.0)
ELBOW_FRICTION = Friction((4.9589, 5.4392), (0.5232, 0.5556), (1.2563, 0.8162), (0.0402, 0.0208))
GAUGES = {"strain_2A": (0.0175, 2.017e-4), "strain_2B": (0.235, 1.974e-4)}  # m from the root, strain per V
NEWTON_METRE_PER_VOLT = 0.4679 * 11.5  # amplifier gain x torque constant


def watflex_run(payload: float, steps: list[tuple[float, float]], duration: float, friction_scale: float,
                seed: int, delay_ticks: int = 0) -> dict[str, np.ndarray]:
    """The elbow PD on the single-link set-up, reference steps (time s, new value rad), each torque command applied
    `delay_ticks` periods after it was computed (and recorded); channels each 1 ms."""
    rng = np.random.default_rng(seed)
    link = Link(tip_mass=8.1 + payload, **LINK2)
    f = ELBOW_FRICTION
    friction = Friction(*(tuple(friction_scale * v for v in p) for p in (f.alpha0, f.alpha1, f.alpha2)), f.v_s)
    arm = Arm(link, friction)
    n, encoder, volt = arm.n, 2 * math.pi / 204800, 20.0 / 4096
    b, a = butter(2, 10.0, fs=1 / PERIOD)
    state = np.zeros(len(a) - 1)  # the filter at rest
    out = _channels(duration, ("elbow_reference", "elbow_angle", "elbow_torque_cmd", *GAUGES))
    before, commands = 0.0, []
    for k, t in enumerate(out["time"]):
        reference = ([0.0] + [v for ts, v in steps if t >= ts - 1e-12])[-1]
        angle = quantised(arm.x[0], encoder)
        rate, state = lfilter(b, a, [(angle - before) / PERIOD], zi=state)
        before = angle
        wanted = 60.0 * (reference - angle) - 12.0 * float(rate[0])
        code = min(max(round(wanted / NEWTON_METRE_PER_VOLT / volt), -2048), 2047)
        torque = code * volt * NEWTON_METRE_PER_VOLT
        out["elbow_reference"][k], out["elbow_angle"][k], out["elbow_torque_cmd"][k] = reference, angle, torque
        for channel, (x, strain_per_volt) in GAUGES.items():
            v = -(THICKNESS / 2) * curvature(link, x, arm.x[:n]) / strain_per_volt + rng.normal(0, 0.002)
            out[channel][k] = min(max(quantised(v, volt), -10.0), 10.0)
        commands.append(torque)
        applied = commands[k - delay_ticks] if k >= delay_ticks else 0.0
        arm.period(lambda w, applied=applied: (None, applied))
    return out


def _channels(duration: float, names) -> dict[str, np.ndarray]:
    """Zeroed channels `names` and their times, one sample each PERIOD over `duration` s."""
    ticks = int(round(duration / PERIOD)) + 1
    return {"time": np.arange(ticks) * PERIOD, **{c: np.zeros(ticks) for c in names}}


def write(out: dict[str, np.ndarray], directory: Path, name: str, described: dict) -> Path:
    """NAME.csv and its sidecar, `described` and the format (recordings.md section 1), in `directory`; returns the
    CSV's path."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.csv"
    columns = list(out)
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for row in zip(*(out[c] for c in columns)):
            writer.writerow([f"{v:.10g}" for v in row])
    said = {"format": "flexarm-recording/1", **described, "mode": "closed_loop",
            "notes": "tools/independent_sim.py: a finite-element beam, an independent simulator of rigs.md"}
    (directory / f"{name}.json").write_text(json.dumps(said, indent=2) + "\n")
    return path


def sidecar(rig: str, payload: float) -> dict:
    """What a recording of `rig` ("laser_arm" or "watflex_elbow") with `payload` kg declared says of its experiment."""
    if rig == "laser_arm":
        return {"rig": "laser_arm", "experiment": "laser_arm_step", "payload_kg": payload,
                "controller": {"type": "pd_tip", "kp": 0.127, "kd": 0.0}}
    return {"rig": "watflex", "experiment": "watflex_elbow_step", "payload_kg": payload,
            "locked_joints": {"shoulder": 0.0},
            "controller": {"type": "pd_joint", "joints": ["elbow"], "kp": [60.0], "kd": [12.0], "filter_hz": 10.0}}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("rig", choices=("laser_arm", "watflex_elbow"), help="which rig and set-up")
    parser.add_argument("out", type=Path, help="directory the recordings are written to")
    parser.add_argument("--payload", type=float, nargs="+", help="kg at the tip, the experiments once per payload "
                        "(default: laser arm 0.7 1.15, Watflex 0)")
    parser.add_argument("--coulomb", type=float, nargs=2, default=(0.0, 0.0), metavar=("POS", "NEG"),
                        help="laser arm: gear Coulomb friction at the hub, N m, clockwise and anticlockwise (default "
                        "none, as the nominal model; the source measured 2.778 0.926)")
    parser.add_argument("--friction-scale", type=float, default=1.0, help="Watflex: the elbow friction's levels "
                        "(alpha0, alpha1, alpha2) x this (default 1, the datasheet's)")
    parser.add_argument("--delay", type=int, default=0, help="Watflex: ms (whole control periods) between a torque "
                        "command and its reaching the joint (default 0)")
    parser.add_argument("--hidden-payload", type=float, default=0.0, help="kg more at the tip than the sidecars "
                        "declare (default 0): an experimenter's undeclared load")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    args = parser.parse_args(argv)
    payloads = args.payload or ([0.7, 1.15] if args.rig == "laser_arm" else [0.0])
    if min(*payloads, *args.coulomb, args.friction_scale, args.hidden_payload, args.delay) < 0:
        parser.error("payloads, friction levels, their scale and the delay must not be negative")
    for j, declared in enumerate(payloads):
        payload = declared + args.hidden_payload
        if args.rig == "laser_arm":
            runs = [(f"step_{word}_{declared:g}kg", lambda seed, d=d: laser_step(payload, d, 2.0, args.coulomb, seed))
                    for d, word in ((1, "positive"), (-1, "negative"))]
        else:
            runs = [(f"step_{word}_{declared:g}kg", lambda seed, s=s: watflex_run(payload, [(0.5, s)], 6.0,
                                                                                args.friction_scale, seed, args.delay))
                    for s, word in ((0.5, "positive"), (-0.5, "negative"))]
            stairs = [(2.0, 0.1), (4.0, 0.2), (6.0, 0.1), (8.0, 0.0)]
            runs.append((f"staircase_{declared:g}kg", lambda seed: watflex_run(payload, stairs, 10.0,
                                                                              args.friction_scale, seed, args.delay)))
        for i, (name, run) in enumerate(runs):
            out = run(args.seed + 100 * j + i)
            path = write(out, args.out, name, sidecar(args.rig, declared))
            print(f"{path}: {len(out['time'])} samples, last angle "
                  f"{out['hub_angle' if 'hub_angle' in out else 'elbow_angle'][-1]:.5f} rad")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
