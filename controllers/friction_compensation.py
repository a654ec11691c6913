"""Friction compensation around any controller (thesis 4.4, figs. 4.11-4.16, section 4.5.5).

The wrapped controller's torque command tau (N m) for one joint becomes tau + tau_f, tau_f the
compensation of the chosen scheme; every other channel passes through unchanged. Velocity v
(rad/s) is the encoder's backward difference through a 2nd-order Butterworth at `filter_hz`
(the thesis' 10 Hz filter, section 4.5.5), as in PDJoint. Friction parameters per direction
are params.Friction (alpha0, alpha1 in N m, alpha2 in N m s/rad, v_s in rad/s).

Schemes (tau the inner torque, dir(x) picks the positive/negative parameter set by sgn x):
  coulomb_ff       fig. 4.11/4.12a  tau_f = alpha0_dir(tau) sgn(tau)
  finite_slope_ff  fig. 4.12b       tau_f = alpha0_dir(tau) clip(tau / dv, -1, 1): a finite
                                    slope alpha0/dv around zero input; `dv` (N m) is the
                                    input torque where the map reaches the Coulomb level
  ff_velocity_fb   fig. 4.13        tau_f = alpha0_dir(tau) sgn(tau)                 (part 1)
                                          + [alpha1 exp(-(v/v_s)^2) sgn(v)] (1 - exp(-|v| k_s))
                                          + alpha2 v, parameters of dir(v)            (part 2)
                                    (the Stribeck part slope-limited by eq. 4.24 against chatter)
  velocity_fb      fig. 4.14        tau_f = slope_limited(v)        (eq. 4.6 x eq. 4.24)
  qualified        fig. 4.15-4.16   gamma = min(k_gamma |v|, 1)                      (eq. 4.18)
                                    v~ = gamma v + (1 - gamma) k_tau clip(tau, -delta, delta)
                                                                                     (eq. 4.19)
                                    tau_f = slope_limited(v~)       (section 4.5.5)
"""
from __future__ import annotations

import dataclasses
import math
from typing import Mapping

import numpy as np

from watflex_sim.friction import slope_limited, slope_limited_columns
from watflex_sim.params import CONTROL_PERIOD, Friction

from .filters import Butterworth2

SCHEMES = ("coulomb_ff", "finite_slope_ff", "ff_velocity_fb", "velocity_fb", "qualified")
NUMBERS = ("k_s", "k_gamma", "k_tau", "delta", "dv", "filter_hz", "period")


def _sgn(x: float) -> float:
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


class FrictionCompensation:
    """`inner`'s command with the friction compensation of `scheme` added to `{joint}_torque_cmd`.

    k_s (s/rad) slope factor of eq. 4.24; k_gamma (s/rad), k_tau (rad/(N m s)), delta (N m) the
    qualified-feedback constants of eq. 4.18-4.19 (rigs.md §2: 100, 1, 0.01); dv (N m) the
    input torque where the finite-slope map saturates; filter_hz (Hz) the velocity filter;
    period (s) the control period. A missing inner torque counts as 0 N m.
    After each call `compensation` (N m) and `velocity` (rad/s, filtered) hold the last values.
    Raises ValueError for an unknown scheme.
    """

    def __init__(self, inner, joint: str, scheme: str, positive: Friction, negative: Friction,
                 k_s: float = 300.0, k_gamma: float = 100.0, k_tau: float = 1.0, delta: float = 0.01,
                 dv: float = 0.01, filter_hz: float = 10.0, period: float = CONTROL_PERIOD):
        if scheme not in SCHEMES:
            raise ValueError(f"unknown friction compensation scheme {scheme!r} (known: {', '.join(SCHEMES)})")
        self.inner, self.joint, self.scheme = inner, joint, scheme
        self.positive, self.negative = positive, negative
        self.k_s, self.k_gamma, self.k_tau = float(k_s), float(k_gamma), float(k_tau)
        self.delta, self.dv, self.period = float(delta), float(dv), float(period)
        self.filter = Butterworth2(filter_hz, 1.0 / self.period)
        self.channel = f"{joint}_torque_cmd"
        self.reset()

    def reset(self) -> None:
        self.inner.reset()
        self.filter.reset()
        self._previous = None
        self.compensation = 0.0
        self.velocity = 0.0

    def state(self) -> dict[str, float]:
        """The compensated controller's state (StatefulController); {} where it has none (the compensation's own
        velocity filter follows the encoder's recent past)."""
        return self.inner.state() if hasattr(self.inner, "state") else {}

    def set_state(self, values: Mapping[str, float]) -> None:
        if values:
            if not hasattr(self.inner, "set_state"):
                raise ValueError(f"{type(self.inner).__name__} has no state to set")
            self.inner.set_state(values)

    def _side(self, x: float) -> Friction:
        return self.positive if x > 0 else self.negative

    def torque(self, tau: float, v: float) -> float:
        """Compensation torque tau_f (N m) for inner torque tau (N m) and velocity v (rad/s)."""
        scheme = self.scheme
        if scheme == "coulomb_ff":
            return self._side(tau).alpha0 * _sgn(tau)
        if scheme == "finite_slope_ff":
            return self._side(tau).alpha0 * max(-1.0, min(1.0, tau / self.dv))
        if scheme == "ff_velocity_fb":
            p = self._side(v)
            stribeck = p.alpha1 * math.exp(-((v / p.v_s) ** 2)) * _sgn(v) * (1.0 - math.exp(-abs(v) * self.k_s))
            return self._side(tau).alpha0 * _sgn(tau) + stribeck + p.alpha2 * v
        if scheme == "velocity_fb":
            return slope_limited(v, self.positive, self.negative, self.k_s)
        gamma = min(self.k_gamma * abs(v), 1.0)  # qualified, eq. 4.18-4.19
        v_tilde = gamma * v + (1.0 - gamma) * self.k_tau * max(-self.delta, min(self.delta, tau))
        return slope_limited(v_tilde, self.positive, self.negative, self.k_s)

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        out = dict(self.inner(t, obs))
        theta = obs[f"{self.joint}_angle"]
        prev = self._previous
        self.velocity = self.filter(0.0 if prev is None else (theta - prev) / self.period)
        self._previous = theta
        tau = float(out.get(self.channel, 0.0))
        self.compensation = self.torque(tau, self.velocity)
        out[self.channel] = tau + self.compensation
        return out

    @classmethod
    def columns(cls, members: list["FrictionCompensation"], times: np.ndarray) -> "FrictionCompensationColumns | None":
        """The members' compensation on arrays around their inner controllers' column form (lockstep's columns), or
        None unless they share joint and scheme, their inner controllers have a column form, and none has run."""
        first = members[0]
        if any(type(m).__call__ is not FrictionCompensation.__call__ or m.joint != first.joint or m.scheme != first.scheme
               or type(m.inner) is not type(first.inner) or m._previous is not None or m.filter.z1 is not None
               for m in members):
            return None
        form = getattr(type(first.inner), "columns", None)
        inner = form([m.inner for m in members], times) if form is not None else None
        return None if inner is None else FrictionCompensationColumns(members, inner)


class FrictionCompensationColumns:
    """FrictionCompensation of B members at once, on arrays of shape (B,): the same arithmetic, member by member
    (the slope-limited schemes on arrays; the feed-forward ones through each member's own `torque`)."""

    def __init__(self, members: list[FrictionCompensation], inner):
        first = members[0]
        self.members, self.inner = members, inner
        self.joint, self.channel, self.scheme = first.joint, first.channel, first.scheme
        self.filter = first.filter.columns([m.filter for m in members])
        for name in ("k_s", "k_gamma", "k_tau", "delta", "period"):
            setattr(self, name, np.array([getattr(m, name) for m in members], dtype=float))
        fields = [f.name for f in dataclasses.fields(first.positive)]
        self.positive, self.negative = ({f: np.array([getattr(getattr(m, side), f) for m in members], dtype=float)
                                         for f in fields} for side in ("positive", "negative"))
        self._previous = None

    def torque(self, tau: np.ndarray, v: np.ndarray) -> np.ndarray:
        """FrictionCompensation.torque of each member (N m)."""
        if self.scheme == "velocity_fb":
            return slope_limited_columns(v, self.positive, self.negative, self.k_s)
        if self.scheme == "qualified":
            gamma = np.minimum(self.k_gamma * np.abs(v), 1.0)
            v_tilde = gamma * v + (1.0 - gamma) * self.k_tau * np.maximum(-self.delta, np.minimum(self.delta, tau))
            return slope_limited_columns(v_tilde, self.positive, self.negative, self.k_s)
        return np.array([m.torque(a, b) for m, a, b in zip(self.members, tau.tolist(), v.tolist())])

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = dict(self.inner(t, obs))
        theta = obs[f"{self.joint}_angle"]
        prev = self._previous
        velocity = self.filter(np.zeros(len(self.period)) if prev is None else (theta - prev) / self.period)
        self._previous = theta
        tau = np.asarray(out.get(self.channel, np.zeros(len(self.period))), dtype=float)
        out[self.channel] = tau + self.torque(tau, velocity)
        return out


def wrap_compensation(inner, spec: Mapping, rig_params) -> FrictionCompensation:
    """`inner` wrapped by the scenario's [controller.compensation] table `spec`.

    spec: scheme and joint (required), optional numbers (k_s, k_gamma, k_tau, delta, dv,
    filter_hz, period; units as FrictionCompensation) and optional `positive` / `negative`
    tables of Friction fields overriding the rig's nominal friction of that joint
    (rig_params.<joint>_friction, rigs.md §2). Raises ValueError on a missing or unknown
    scheme, joint or field, or a non-numeric number.
    """
    spec = dict(spec)
    for key in ("scheme", "joint"):
        if key not in spec:
            raise ValueError(f"compensation: missing '{key}' (schemes: {', '.join(SCHEMES)})")
    scheme, joint = spec.pop("scheme"), spec.pop("joint")
    if scheme not in SCHEMES:
        raise ValueError(f"compensation: unknown scheme {scheme!r} (known: {', '.join(SCHEMES)})")
    nominal = getattr(rig_params, f"{joint}_friction", None) if isinstance(joint, str) else None
    sides = {}
    for i, side in enumerate(("positive", "negative")):
        given = spec.pop(side, None)
        if given is not None and not isinstance(given, Mapping):
            raise ValueError(f"compensation.{side} must be a table of {', '.join(f.name for f in dataclasses.fields(Friction))}")
        try:
            if nominal is not None:
                sides[side] = dataclasses.replace(nominal[i], **(given or {}))
            elif given is not None:
                sides[side] = Friction(**given)
            else:
                raise ValueError(f"compensation: unknown joint {joint!r} (no nominal friction on this rig; "
                                 f"give positive and negative in full)")
        except TypeError as exc:
            raise ValueError(f"compensation.{side}: {exc}") from None
    unknown = set(spec) - set(NUMBERS)
    if unknown:
        raise ValueError(f"compensation: unknown field(s) {', '.join(sorted(unknown))} "
                         f"(known: scheme, joint, positive, negative, {', '.join(NUMBERS)})")
    for key, value in spec.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"compensation.{key} must be a number, got {value!r}")
    return FrictionCompensation(inner, joint, scheme, sides["positive"], sides["negative"], **spec)
