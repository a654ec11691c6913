"""Linear state feedback on named channels, as data (issue 15 item 3)."""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
from scipy import signal

from watflex_sim.params import CONTROL_PERIOD

from .filters import Butterworth2


class RateFilter:
    """Rate of a sampled signal (signal units/s), hz in Hz, period T in s, by `method`:

    backward_diff, euler, bilinear, foh: H(s) = s wn^2 / (s^2 + 2 zeta wn s + wn^2) (a derivative
    through a 2nd-order low-pass) discretised by scipy's cont2discrete `method` (not zoh, which
    assumes a staircase input and gets a ramp's rate 2 % low at 40 Hz, 2 ms); with hz = 0 the
    plain difference.
    difference: (x(k) - x(k-1)) / T, unfiltered (hz, zeta unused).
    difference2: (x(k) - x(k-2)) / (2 T), the 2-tap estimate (EMPS drive); 0 for the first two samples.
    butterworth_difference: the difference through a 2nd-order Butterworth low-pass at hz
    (filters.Butterworth2; zeta unused).
    Starts at rest at the first sample (rate 0)."""

    METHODS = ("backward_diff", "euler", "bilinear", "foh", "difference", "difference2", "butterworth_difference")

    def __init__(self, hz: float, zeta: float, period: float, method: str = "backward_diff"):
        if method not in self.METHODS:
            raise ValueError(f"rate_method must be one of {', '.join(self.METHODS)}, got {method!r}")
        if method == "butterworth_difference" and not hz > 0:
            raise ValueError("rate_method 'butterworth_difference' needs rate_hz > 0")
        self.period = period
        self.taps = 2 if method == "difference2" else 1  # samples the difference spans
        self.smooth = Butterworth2(hz, 1.0 / period) if method == "butterworth_difference" else None
        self.plain = method in ("difference", "difference2", "butterworth_difference") or not hz
        if not self.plain:
            wn = 2 * math.pi * hz
            b, a, _ = signal.cont2discrete(([wn**2, 0.0], [1.0, 2 * zeta * wn, wn**2]), period, method=method)
            self.b = [float(x) / float(a[0]) for x in b[0]]
            self.a = [float(x) / float(a[0]) for x in a[1:]]
        self.reset()

    def reset(self) -> None:
        self.x: list[float] | None = None
        if not self.plain:
            self.y = [0.0] * len(self.a)
        if self.smooth:
            self.smooth.reset()

    @staticmethod
    def columns(members: list["RateFilter"]) -> "RateFilter | None":
        """The members as one filter on arrays of shape (B,) (their periods and coefficients as arrays, the same
        arithmetic), or None unless they share a form (method, taps, filter order) and have not run yet."""
        first = members[0]
        if not all(m.plain == first.plain and m.taps == first.taps and (m.smooth is None) == (first.smooth is None)
                   and (m.plain or (len(m.b), len(m.a)) == (len(first.b), len(first.a))) and m.x is None for m in members):
            return None
        out = RateFilter.__new__(RateFilter)
        out.plain, out.taps = first.plain, first.taps
        out.period = np.array([m.period for m in members])
        out.smooth = Butterworth2.columns([m.smooth for m in members]) if first.smooth else None
        if not first.plain:
            out.b = [np.array([m.b[i] for m in members]) for i in range(len(first.b))]
            out.a = [np.array([m.a[i] for m in members]) for i in range(len(first.a))]
        out.reset()
        return out

    def __call__(self, value: float) -> float:
        if self.plain:  # the last taps + 1 samples
            self.x = ([] if self.x is None else self.x)[-self.taps:] + [value]
            rate = (value - self.x[0]) / (self.taps * self.period) if len(self.x) > self.taps else 0.0
            return self.smooth(rate) if self.smooth else rate
        if self.x is None:  # at rest at the first value
            self.x = [value] * len(self.b)
        self.x = [value] + self.x[:-1]
        y = sum(b * x for b, x in zip(self.b, self.x)) - sum(a * y for a, y in zip(self.a, self.y))
        if self.y:
            self.y = [y] + self.y[:-1]
        return y


class StateFeedback:
    """u = K (x_ref - x) per command channel, then its limit (command units) and optional filter.

    `states` names the state vector: a channel ("hub1"), or "rate:CHANNEL" for its rate by
    filtered difference (RateFilter at rate_hz, rate_zeta). `references` maps a state to the
    channel holding its reference (the others' references are 0). `gains` has one row per
    command channel in `commands`, one column per state (command unit per state unit).
    `limits` (optional, one per command) saturate the output; `command_filter_hz` low-passes it
    (1st order). `period` is the sample period (s): the rig's.
    """

    def __init__(self, commands: Sequence[str], states: Sequence[str], gains: Sequence[Sequence[float]],
                 references: Mapping[str, str] | None = None, rate_hz: float = 0.0, rate_zeta: float = 0.7071,
                 rate_method: str = "backward_diff",
                 limits: Sequence[float] | None = None, command_filter_hz: float = 0.0,
                 period: float = CONTROL_PERIOD):
        self.commands, self.states = list(commands), list(states)
        self.gains = [[float(k) for k in row] for row in gains]
        if len(self.gains) != len(self.commands) or any(len(row) != len(self.states) for row in self.gains):
            raise ValueError(f"gains must be {len(self.commands)} row(s) (commands) of {len(self.states)} (states)")
        self.references = dict(references or {})
        unknown = set(self.references) - set(self.states)
        if unknown:
            raise ValueError(f"references name state(s) not in states: {', '.join(sorted(unknown))}")
        self.limits = [math.inf] * len(self.commands) if limits is None else [float(x) for x in limits]
        if len(self.limits) != len(self.commands):
            raise ValueError("limits must have one value per command")
        self.period = float(period)
        self.rates = {s: RateFilter(float(rate_hz), float(rate_zeta), self.period, rate_method)
                      for s in self.states if s.startswith("rate:")}
        self.alpha = 1.0 - math.exp(-2 * math.pi * command_filter_hz * self.period) if command_filter_hz else 1.0
        self.reset()

    def reset(self) -> None:
        for f in self.rates.values():
            f.reset()
        self._out = None

    def channels(self) -> set[str]:
        """The measured channels the law reads."""
        return {s.removeprefix("rate:") for s in self.states} | set(self.references.values())

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        error = []
        for s in self.states:
            x = self.rates[s](obs[s[5:]]) if s in self.rates else obs[s]
            ref = obs[self.references[s]] if s in self.references else 0.0
            error.append(ref - x)
        u = [max(-lim, min(lim, sum(k * e for k, e in zip(row, error)))) for row, lim in zip(self.gains, self.limits)]
        if self.alpha < 1.0:
            u = u if self._out is None else [y + self.alpha * (v - y) for v, y in zip(u, self._out)]
            self._out = u
        return dict(zip(self.commands, u))

    @classmethod
    def columns(cls, members: list["StateFeedback"], times: np.ndarray) -> "StateFeedbackColumns | None":
        """The members' law on arrays (lockstep's columns), or None unless they share its form."""
        first = members[0]
        if type(first).__call__ is not StateFeedback.__call__ or any(
                type(m) is not type(first) or m.commands != first.commands or m.states != first.states
                or m.references != first.references or (m.alpha < 1.0) != (first.alpha < 1.0) or m._out is not None
                for m in members):
            return None
        rates = {s: RateFilter.columns([m.rates[s] for m in members]) for s in first.rates}
        return None if any(r is None for r in rates.values()) else StateFeedbackColumns(members, rates)


class StateFeedbackColumns:
    """StateFeedback of B members at once, on arrays of shape (B,): the same arithmetic, member by member."""

    def __init__(self, members: list[StateFeedback], rates: dict[str, RateFilter]):
        first = members[0]
        self.commands, self.states, self.references, self.rates = first.commands, first.states, first.references, rates
        self.gains = [[np.array([m.gains[r][c] for m in members]) for c in range(len(first.states))]
                      for r in range(len(first.commands))]
        self.limits = [np.array([m.limits[r] for m in members]) for r in range(len(first.commands))]
        self.alpha = np.array([m.alpha for m in members])
        self.filtered = first.alpha < 1.0
        self._out = None

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        error = []
        for s in self.states:
            x = self.rates[s](obs[s[5:]]) if s in self.rates else obs[s]
            ref = obs[self.references[s]] if s in self.references else 0.0
            error.append(ref - x)
        u = [np.maximum(-lim, np.minimum(lim, sum(k * e for k, e in zip(row, error))))
             for row, lim in zip(self.gains, self.limits)]
        if self.filtered:
            u = u if self._out is None else [y + self.alpha * (v - y) for v, y in zip(u, self._out)]
            self._out = u
        return dict(zip(self.commands, u))
