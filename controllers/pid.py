"""PID on named channels, as data (issue 15 item 3)."""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from watflex_sim.params import CONTROL_PERIOD

from .state_feedback import RateFilter


class PID:
    """u = kp e + ki integral(e) - kd d(position)/dt - kl deflection, e = reference - position.

    Channels by name: `command`, `position`, `reference` ("" for a reference of 0), and optionally `deflection` (a link's
    deflection channel, gain kl). The rate is the filtered difference of `position` (RateFilter
    at rate_hz, rate_zeta, rate_method). The output is clipped to +-limit (command units; the integral stops
    while clipped) and optionally low-passed (command_filter_hz, 1st order). period in s.
    """

    def __init__(self, command: str, position: str, reference: str, kp: float, ki: float = 0.0,
                 kd: float = 0.0, deflection: str = "", kl: float = 0.0, rate_hz: float = 0.0,
                 rate_zeta: float = 0.7071, rate_method: str = "backward_diff", limit: float = math.inf, command_filter_hz: float = 0.0,
                 period: float = CONTROL_PERIOD):
        self.command, self.position, self.reference, self.deflection = command, position, reference, deflection
        self.kp, self.ki, self.kd, self.kl, self.limit = float(kp), float(ki), float(kd), float(kl), float(limit)
        self.period = float(period)
        self.rate = RateFilter(float(rate_hz), float(rate_zeta), self.period, rate_method)
        self.alpha = 1.0 - math.exp(-2 * math.pi * command_filter_hz * self.period) if command_filter_hz else 1.0
        self.reset()

    def reset(self) -> None:
        self.rate.reset()
        self.integral, self._out = 0.0, None

    def channels(self) -> set[str]:
        """The measured channels the law reads."""
        return {self.position} | {c for c in (self.reference, self.deflection) if c}

    def state(self) -> dict[str, float]:
        """The integral of the error (position unit x s) where the law has an integral term (ki != 0), else {}."""
        return {"integral": self.integral} if self.ki else {}

    def set_state(self, values: Mapping[str, float]) -> None:
        """Set the state `state` names (ValueError for any other name)."""
        if set(values) - set(self.state()):
            raise ValueError(f"pid state has {', '.join(self.state()) or 'nothing'} (ki = {self.ki}), "
                             f"got {', '.join(values)}")
        self.integral = float(values.get("integral", self.integral))

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        q = obs[self.position]
        e = (obs[self.reference] if self.reference else 0.0) - q
        u = self.kp * e + self.ki * self.integral - self.kd * self.rate(q)
        if self.deflection:
            u -= self.kl * obs[self.deflection]
        clipped = max(-self.limit, min(self.limit, u))
        if clipped == u:  # anti-windup: integrate only while not saturated
            self.integral += e * self.period
        if self.alpha < 1.0:
            clipped = clipped if self._out is None else self._out + self.alpha * (clipped - self._out)
            self._out = clipped
        return {self.command: clipped}

    @classmethod
    def columns(cls, members: list["PID"], times: np.ndarray) -> "PIDColumns | None":
        """The members' law on arrays (lockstep's columns), or None unless they share its form."""
        first = members[0]
        names = ("command", "position", "reference", "deflection")
        if any(type(m).__call__ is not PID.__call__ or any(getattr(m, n) != getattr(first, n) for n in names)
                or (m.alpha < 1.0) != (first.alpha < 1.0) or m._out is not None or m.integral != 0.0 for m in members):
            return None
        rate = RateFilter.columns([m.rate for m in members])
        return None if rate is None else PIDColumns(members, rate)


class PIDColumns:
    """PID of B members at once, on arrays of shape (B,): the same arithmetic, member by member."""

    def __init__(self, members: list[PID], rate: RateFilter):
        first = members[0]
        self.command, self.position, self.reference, self.deflection = (first.command, first.position,
                                                                         first.reference, first.deflection)
        for name in ("kp", "ki", "kd", "kl", "limit", "period", "alpha"):
            setattr(self, name, np.array([getattr(m, name) for m in members]))
        self.rate, self.filtered = rate, first.alpha < 1.0
        self.integral, self._out = np.zeros(len(members)), None

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        q = obs[self.position]
        e = (obs[self.reference] if self.reference else 0.0) - q
        u = self.kp * e + self.ki * self.integral - self.kd * self.rate(q)
        if self.deflection:
            u = u - self.kl * obs[self.deflection]
        clipped = np.maximum(-self.limit, np.minimum(self.limit, u))
        self.integral = np.where(clipped == u, self.integral + e * self.period, self.integral)
        if self.filtered:
            clipped = clipped if self._out is None else self._out + self.alpha * (clipped - self._out)
            self._out = clipped
        return {self.command: clipped}
