"""Gain-scheduled PI velocity control of one Watflex joint for the friction map (thesis 4.5.4).

Thesis fig. 4.18-4.19: the joint is driven through a schedule of constant speeds (0.61 ->
0.0004 rad/s, both directions, 1 ms sampling, +-3 turns of cable); each speed is held for a
while, the first half of each hold lets the motion settle and the means over the second half
give one point (mean torque command, mean speed) of the static friction-velocity map. The
P and I gains follow the desired speed and change only when it changes (fig. 4.19 b, c).
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from watflex_sim.params import CONTROL_PERIOD, WATFLEX

from .filters import Butterworth2

TURN = 2 * math.pi  # rad


def log_scan(v_max: float = 0.61, v_min: float = 4e-4, n_speeds: int = 20, hold_fast_s: float = 3.0,
             hold_slow_s: float = 8.0, turns_limit: float = 3.0) -> list[list[float]]:
    """A scan schedule [[speed rad/s, hold s], ...] of `n_speeds` log-spaced speeds per direction.

    Each direction is scanned fast -> slow, so a hold starts from a faster one or, after a
    reversal, at the fastest speed of its sweep, where the gains are highest (the integral must
    then swing the torque across both friction levels, ~18 N m). The hold grows log-linearly from
    `hold_fast_s` (s) at `v_max` to `hold_slow_s` (s) at `v_min`. The speeds of one direction are
    cut into sweeps whose travel stays below `turns_limit` turns, and sweeps alternate in
    direction (+, -, +, -, ...), so the joint stays within +-`turns_limit` turns of its start
    (thesis 4.5.4: the shoulder's cables allow 3 turns either way).
    Defaults: watflex_friction_map (220 s). Raises ValueError for speeds out of order,
    non-positive holds or a single hold that would travel too far.
    """
    if not 0 < v_min < v_max or n_speeds < 2 or min(hold_fast_s, hold_slow_s) <= 0:
        raise ValueError("log_scan needs 0 < v_min < v_max, n_speeds >= 2 and holds > 0 s")
    speeds = np.geomspace(v_max, v_min, n_speeds)
    x = np.log(v_max / speeds) / np.log(v_max / v_min)  # 0 at v_max, 1 at v_min
    holds = hold_fast_s + (hold_slow_s - hold_fast_s) * x
    limit = turns_limit * TURN
    sweeps: list[list[tuple[float, float]]] = [[]]
    travel = 0.0
    for v, h in zip(speeds, holds):
        if v * h > limit:
            raise ValueError(f"a {h:g} s hold at {v:g} rad/s travels beyond {turns_limit:g} turns")
        if travel + v * h > limit:
            sweeps.append([])
            travel = 0.0
        sweeps[-1].append((float(v), float(h)))
        travel += v * h
    schedule = []
    for sweep in sweeps:  # + then - over the same holds: back to the start after each pair
        for sign in (1.0, -1.0):
            schedule += [[sign * v, h] for v, h in sweep]
    return schedule


class PIVelocity:
    """tau = P(v_d) (v_d - v_hat) + integral of I(v_d) (v_d - v) dt  (N m), v_d from the schedule.

    joint: the Watflex joint ("shoulder" or "elbow"); reads `{joint}_angle` (rad, encoder),
    writes `{joint}_torque_cmd` (N m).
    schedule: [[speed rad/s, hold s], ...] run from t = `start_s` (s); before it and after its
    end the desired speed is 0 (with the first hold's gains). Or `scan`: keyword arguments of `log_scan` (v_max, v_min,
    n_speeds, hold_fast_s, hold_slow_s, turns_limit) to generate it. Default: `log_scan()`.
    Speed: v_hat is the encoder's backward difference (rad/s) through a 2nd-order Butterworth
    whose cutoff follows the speed (below). The integral uses the raw backward difference,
    i.e. the encoder angle itself (the sum of the differences telescopes to the angle change),
    so it carries no filter lag and resolves the slowest speeds to one count.
    Gain law (our own, smooth and increasing in |v_d|; the thesis fitted 3rd/4th-order
    polynomials through hand-tuned points, fig. 4.19 b, c):
      r   = |v_d| / encoder step                     counts/s reaching the encoder
      x   = r / (counts_per_window f_max)
      f_c = f_max x / (1 + x)                        filter cutoff (Hz): f_max at speed, and at
                                                     low speed about r / counts_per_window, i.e.
                                                     the filter averages over a few counts (at
                                                     0.0004 rad/s: 13 counts/s, f_c = 1.5 Hz)
      w   = 2 pi f_c / bandwidth_ratio               closed-loop bandwidth (rad/s), below the filter
      I   = inertia w^2                              N m/rad (on the angle error)
      P   = 2 zeta inertia w + p_extra               N m s/rad
    so the loop J s^2 + (P + c) s + I (c the local slope of the friction map) has natural
    frequency w and damping zeta when c = 0; p_extra (N m s/rad) covers the negative slope of
    the Stribeck curve (up to about 30 N m s/rad near v_S/sqrt(2) at the shoulder, rigs.md §2
    table). Gains and cutoff change only when the desired speed changes (thesis 4.5.4). The
    integral is held within +-`torque_limit` (N m, anti-windup; default the joint's converter
    range). Raises ValueError for an unknown joint or a malformed schedule.
    """

    def __init__(self, joint: str = "shoulder", schedule: Sequence[Sequence[float]] | None = None,
                 scan: Mapping[str, float] | None = None, start_s: float = 0.0,
                 inertia: float | None = None, zeta: float = 0.7,
                 p_extra: float = 40.0, counts_per_window: float = 8.0,
                 f_max: float = 20.0, bandwidth_ratio: float = 4.0, torque_limit: float | None = None,
                 period: float = CONTROL_PERIOD):
        if joint not in ("shoulder", "elbow"):
            raise ValueError(f"pi_velocity: joint must be 'shoulder' or 'elbow', got {joint!r}")
        act = getattr(WATFLEX, joint)
        self.joint = joint
        if schedule is not None and scan is not None:
            raise ValueError("pi_velocity: give either 'schedule' or 'scan', not both")
        if schedule is None:
            try:
                schedule = log_scan(**dict(scan or {}))
            except TypeError as exc:
                raise ValueError(f"pi_velocity.scan: {exc}") from None
        self.schedule = [(float(v), float(h)) for v, h in schedule]
        if not self.schedule or any(h <= 0 for _, h in self.schedule):
            raise ValueError("pi_velocity: schedule must be a non-empty list of [speed rad/s, hold s > 0]")
        self.start_s, self.period = float(start_s), float(period)
        self.inertia = float(act.inertia if inertia is None else inertia)  # kg m^2, for the gain law
        self.zeta, self.p_extra = float(zeta), float(p_extra)
        self.counts_per_window, self.f_max = float(counts_per_window), float(f_max)
        self.bandwidth_ratio = float(bandwidth_ratio)
        self.torque_limit = float(act.torque_limit if torque_limit is None else torque_limit)
        self.encoder_step = WATFLEX.encoder_step
        self.ends = self.start_s + np.cumsum([h for _, h in self.schedule])  # s, end of each hold
        self.reset()

    # --- the gain law -------------------------------------------------------------------
    def gains(self, speed: float) -> tuple[float, float, float]:
        """(P in N m s/rad, I in N m/rad, filter cutoff in Hz) for a desired speed (rad/s)."""
        x = abs(speed) / self.encoder_step / (self.counts_per_window * self.f_max)
        cutoff = self.f_max * x / (1.0 + x)
        w = 2 * math.pi * cutoff / self.bandwidth_ratio
        return 2 * self.zeta * self.inertia * w + self.p_extra, self.inertia * w * w, cutoff

    # --- schedule -------------------------------------------------------------------------
    def hold_index(self, t: float) -> int:
        """Index of the hold running at t (s); -1 before the schedule, len(schedule) after it."""
        if t < self.start_s:
            return -1
        return int(np.searchsorted(self.ends, t, side="right"))

    def desired_speed(self, t: float) -> float:
        """Desired speed (rad/s) at t (s)."""
        i = self.hold_index(t)
        return self.schedule[i][0] if 0 <= i < len(self.schedule) else 0.0

    def windows(self) -> list[tuple[float, float, float]]:
        """(speed rad/s, start s, end s) of the second half of each hold: where the map is averaged."""
        out = []
        for (v, h), end in zip(self.schedule, self.ends):
            out.append((v, float(end - h / 2), float(end)))
        return out

    def window_index(self, time: np.ndarray) -> np.ndarray:
        """For each time (s): the hold whose second half contains it, else -1."""
        time = np.asarray(time, float)
        idx = np.full(time.shape, -1, dtype=int)
        for i, (_, t0, t1) in enumerate(self.windows()):
            idx[(time >= t0) & (time < t1)] = i
        return idx

    @property
    def duration_s(self) -> float:
        """End of the schedule (s)."""
        return float(self.ends[-1])

    # --- controller interface -------------------------------------------------------------
    def reset(self) -> None:
        self._theta_prev = None
        self._index = None
        self._integral = 0.0  # N m
        self._p = 0.0
        self._i = 0.0
        self._filter = None
        self._v_hat = 0.0
        self._v_prev_desired = 0.0  # rad/s, desired speed over the period just ended

    def _switch(self, index: int, speed: float) -> None:
        """Apply the gains and filter cutoff of a new desired speed (the filter keeps its output)."""
        self._index = index
        self._p, self._i, cutoff = self.gains(speed if speed else self.schedule[0][0])
        self._filter = Butterworth2(cutoff, 1.0 / self.period)
        self._filter(self._v_hat)  # start the new filter in steady state at the current estimate

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        theta = obs[f"{self.joint}_angle"]
        index = self.hold_index(t)
        v_d = self.desired_speed(t)
        if index != self._index:
            self._switch(index, v_d)
        if self._theta_prev is None:
            dtheta = 0.0
        else:
            dtheta = theta - self._theta_prev
        self._theta_prev = theta
        self._v_hat = self._filter(dtheta / self.period)
        # integral of the speed error over the last period: desired travel minus encoder travel
        self._integral += self._i * (self._v_prev_desired * self.period - dtheta)
        self._integral = min(max(self._integral, -self.torque_limit), self.torque_limit)
        self._v_prev_desired = v_d
        tau = self._p * (v_d - self._v_hat) + self._integral
        return {f"{self.joint}_torque_cmd": tau}
