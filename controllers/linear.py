"""A linear time-invariant law as data: a discrete state space or transfer functions on named channels.

A lab's own controller (an LQG's Kalman predictor and gain, an H-infinity design, a lead-lag, a notch) is
usually exported as matrices; this runs it as given. Each of the law's sample instants (every `period_s`,
a multiple of the rig's control period; the commands held between, as a Simulink rate transition does):

    y = C x + D u,    x <- A x + B u,    commands = y clipped at `limits`

with u the inputs in order: a channel's value, "rate:CHANNEL" its rate (state_feedback.RateFilter, run
every control period), or "" for 0. The state starts at zero (Simulink's default), or where a run starts at rest
away from the nominal pose (a recording cut from a longer run) as the law holds it at those readings (`settle`), and
can be set (controllers.base.StatefulController: "x0", "x1", ... in the law's own units).
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
from scipy import signal

from watflex_sim.params import CONTROL_PERIOD

from .state_feedback import RateFilter

DOMAINS = ("z", "s")  # discrete matrices / polynomials in z, or continuous ones in s (discretised here)


class Linear:
    """x <- A x + B u, y = C x + D u on named inputs (module docstring).

    commands: the command channels y drives, in order; inputs: u's entries (channel, "rate:CHANNEL" or "").
    A (n x n), B (n x inputs), C (commands x n), D (commands x inputs): row by row (a flat list is read row by
    row); or, for one command, `num` and `den`: one transfer function per input (a flat list where there is one
    input; one `den` shared by all), polynomials in descending powers (MATLAB's and scipy's order).
    domain: "z" (as given, at period_s) or "s" (continuous, discretised at period_s by scipy's cont2discrete
    `method`, "bilinear" = Tustin). period_s: the law's sample period (s; 0: the rig's `period`), a whole number
    of control periods. limits: one per command (command units; none: unlimited). rate_hz, rate_zeta,
    rate_method: the rates' filter (state_feedback.RateFilter).
    Raises ValueError for shapes that do not match, an improper transfer function or a period that is not a
    whole number of control periods.
    """

    def __init__(self, commands: Sequence[str], inputs: Sequence[str], A=None, B=None, C=None, D=None,
                 num=None, den=None, domain: str = "z", method: str = "bilinear", period_s: float = 0.0,
                 limits: Sequence[float] | None = None, rate_hz: float = 0.0, rate_zeta: float = 0.7071,
                 rate_method: str = "backward_diff", period: float = CONTROL_PERIOD):
        self.commands, self.inputs = list(commands), list(inputs)
        if not self.commands or not self.inputs:
            raise ValueError("linear needs at least one command and one input")
        if domain not in DOMAINS:
            raise ValueError(f"domain must be one of {', '.join(DOMAINS)}, got {domain!r}")
        self.period = float(period)
        sample = float(period_s) or self.period
        self.every = round(sample / self.period)
        if self.every < 1 or not math.isclose(self.every * self.period, sample, rel_tol=1e-9):
            raise ValueError(f"period_s {sample} s is not a whole number of control periods ({self.period} s)")
        if num is not None or den is not None:
            if any(m is not None for m in (A, B, C, D)):
                raise ValueError("give A, B, C, D or num, den, not both")
            A, B, C, D = _from_transfer(num, den, len(self.inputs), len(self.commands))
        elif D is None:
            raise ValueError("linear needs A, B, C, D (D alone for a static gain) or num, den")
        self.A, self.B, self.C, self.D = _shaped(A, B, C, D, len(self.inputs), len(self.commands))
        if domain == "s":
            if self.A.size:
                self.A, self.B, self.C, self.D, _ = signal.cont2discrete((self.A, self.B, self.C, self.D), sample,
                                                                         method=method)
        self.limits = np.full(len(self.commands), math.inf) if limits is None else np.asarray(limits, dtype=float)
        if self.limits.shape != (len(self.commands),):
            raise ValueError(f"limits must have one value per command ({len(self.commands)}), got {len(self.limits)}")
        self.rates = {s: RateFilter(float(rate_hz), float(rate_zeta), self.period, rate_method)
                      for s in self.inputs if s.startswith("rate:")}
        self._step = np.block([[self.C, self.D], [self.A, self.B]])  # [y; x+] = this @ [x; u], one product a sample
        self.reset()

    def reset(self) -> None:
        for f in self.rates.values():
            f.reset()
        self.x = np.zeros(self.A.shape[0])
        self.k = 0
        self.held = [0.0] * len(self.commands)

    def channels(self) -> set[str]:
        """The measured channels the law reads."""
        return {s.removeprefix("rate:") for s in self.inputs if s}

    def state(self) -> dict[str, float]:
        """The law's state x (its own units) by name "x0", "x1", ..."""
        return {f"x{i}": float(v) for i, v in enumerate(self.x)}

    def set_state(self, values: Mapping[str, float]) -> None:
        """Set entries of x by name (ValueError for a name the law does not have)."""
        unknown = set(values) - set(self.state())
        if unknown:
            raise ValueError(f"linear state has x0..x{len(self.x) - 1}, got {', '.join(sorted(unknown))}")
        for name, value in values.items():
            self.x[int(name[1:])] = float(value)

    def settle(self, obs: Mapping[str, float]) -> None:
        """x as the law holds it after long at these readings, at rest (rates 0): x = (I - A)^-1 B u, least squares
        where A has a pole at 1 (an integrator's state, which the readings do not fix, at its least norm)."""
        u = self._inputs(obs, dict.fromkeys(self.rates, 0.0))
        n = self.A.shape[0]
        self.x = np.linalg.lstsq(np.eye(n) - self.A, self.B @ u, rcond=None)[0] if n else self.x

    def _inputs(self, obs: Mapping[str, float], rates: Mapping[str, float]) -> list[float]:
        """u: each input's channel value, its rate (from `rates`), or 0 for ""."""
        return [rates[s] if s in rates else obs[s] if s else 0.0 for s in self.inputs]

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        rates = {s: f(obs[s[5:]]) for s, f in self.rates.items()}  # every control period, as the rig filters
        if self.k % self.every == 0:
            u = self._inputs(obs, rates)
            out = self._step @ np.concatenate((self.x, u))
            p = len(self.commands)
            self.held = [min(lim, max(-lim, y)) for y, lim in zip(out[:p].tolist(), self.limits.tolist())]
            self.x = out[p:]
        self.k += 1
        return dict(zip(self.commands, self.held))

    @classmethod
    def columns(cls, members: list["Linear"], times: np.ndarray) -> "LinearColumns | None":
        """The members' law on arrays (lockstep's columns), or None unless they share its matrices, inputs, commands
        and period and have not run yet."""
        first = members[0]
        if type(first).__call__ is not Linear.__call__ or any(
                type(m) is not type(first) or m.inputs != first.inputs or m.commands != first.commands
                or m.every != first.every or not np.array_equal(m._step, first._step) or m.k for m in members):
            return None
        rates = {s: RateFilter.columns([m.rates[s] for m in members]) for s in first.rates}
        return None if any(r is None for r in rates.values()) else LinearColumns(members, rates)


class LinearColumns:
    """Linear of B members at once, their values on arrays of shape (B,): each member's product the single law's
    (one matrix-vector product a member, so the same sums in the same order, bit for bit)."""

    def __init__(self, members: list[Linear], rates: dict[str, RateFilter]):
        first = members[0]
        self.commands, self.inputs, self.every, self.rates = first.commands, first.inputs, first.every, rates
        self.A, self.B, self._step = first.A, first.B, first._step
        self.limits = np.array([m.limits for m in members])  # (B, commands)
        self.x = np.array([m.x for m in members])  # (B, n)
        self.k = 0
        self.held = np.zeros((len(members), len(first.commands)))

    def _inputs(self, obs: Mapping[str, np.ndarray], rates: Mapping[str, np.ndarray]) -> np.ndarray:
        """u of every member, (B, inputs): Linear._inputs column by column."""
        u = np.zeros((len(self.x), len(self.inputs)))
        for j, s in enumerate(self.inputs):
            if s:
                u[:, j] = rates[s] if s in rates else obs[s]
        return u

    def settle(self, obs: Mapping[str, np.ndarray], which: np.ndarray) -> None:
        """Linear.settle for the members `which` (a mask) holds."""
        n = self.A.shape[0]
        u = self._inputs(obs, dict.fromkeys(self.rates, np.zeros(len(self.x))))
        for i in np.flatnonzero(which) if n else ():
            self.x[i] = np.linalg.lstsq(np.eye(n) - self.A, self.B @ u[i], rcond=None)[0]

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        rates = {s: f(obs[s[5:]]) for s, f in self.rates.items()}
        if self.k % self.every == 0:
            state = np.concatenate((self.x, self._inputs(obs, rates)), axis=1)
            out = np.array([self._step @ row for row in state])
            p = len(self.commands)
            self.held = np.minimum(self.limits, np.maximum(-self.limits, out[:, :p]))
            self.x = out[:, p:]
        self.k += 1
        return {c: self.held[:, j] for j, c in enumerate(self.commands)}


def _shaped(A, B, C, D, m: int, p: int) -> tuple[np.ndarray, ...]:
    """A, B, C, D as arrays (n x n, n x m, p x n, p x m) from nested or flat lists; ValueError naming what is off."""
    A = np.asarray([] if A is None else A, dtype=float)
    n = math.isqrt(A.size)
    if n * n != A.size:
        raise ValueError(f"A must be square (n x n), got {A.size} values")
    out = [A.reshape(n, n)]
    for name, matrix, rows, cols in (("B", B, n, m), ("C", C, p, n), ("D", D, p, m)):
        array = np.asarray([] if matrix is None else matrix, dtype=float)  # B, C may be left out where n = 0
        if array.size != rows * cols:
            raise ValueError(f"{name} must be {rows} x {cols} (A is {n} x {n}, {m} input(s), {p} command(s)), "
                             f"got {array.size} values")
        out.append(array.reshape(rows, cols))
    return tuple(out)


def _from_transfer(num, den, m: int, p: int) -> tuple[np.ndarray, ...]:
    """One command's transfer functions, one per input, as one state space (each input's block in turn)."""
    if p != 1:
        raise ValueError("num, den describe one command; give A, B, C, D for several")
    nums = [num] if m == 1 and num and not isinstance(num[0], (list, tuple)) else list(num or [])
    dens = [den] * m if den and not isinstance(den[0], (list, tuple)) else list(den or [])
    if len(nums) != m or len(dens) != m:
        raise ValueError(f"num and den need one polynomial per input ({m}), got {len(nums)} and {len(dens)}")
    blocks = []
    for b, a in zip(nums, dens):
        if len(np.trim_zeros(np.asarray(b, dtype=float), "f")) > len(np.trim_zeros(np.asarray(a, dtype=float), "f")):
            raise ValueError(f"transfer function {b} / {a} is improper (numerator of higher degree)")
        blocks.append(signal.tf2ss(b, a))
    n = sum(block[0].shape[0] for block in blocks)
    A, B, C, D = np.zeros((n, n)), np.zeros((n, m)), np.zeros((1, n)), np.zeros((1, m))
    at = 0
    for j, (a, b, c, d) in enumerate(blocks):
        k = a.shape[0]
        A[at:at + k, at:at + k], B[at:at + k, j], C[0, at:at + k], D[0, j] = a, b[:, 0], c[0], d[0, 0]
        at += k
    return A, B, C, D
