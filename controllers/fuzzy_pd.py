"""Laser-arm fuzzy PD on the tip sensor (laser_arm_paper section 2.4, after Surdhar 1999).

The paper fixes the architecture only: 5 fuzzy sets on the error, 5 on its derivative,
5 output singletons, fired outputs aggregated by their sum, fired-weighted-average
defuzzification. Everything else here is **[choice]**, documented in `FuzzyPD`.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from watflex_sim.params import CONTROL_PERIOD

LABELS = ("NB", "NS", "ZE", "PS", "PB")  # negative big ... positive big

# [choice] Mac Vicar-Whelan diagonal rule table: RULES[i][j] is the index (0 = NB ... 4 = PB)
# of the output singleton for error set i and error-rate set j, i.e. clip(i + j - 2, 0, 4).
# Anti-symmetric (RULES[4-i][4-j] = 4 - RULES[i][j]), so with odd sets the surface is odd.
#            de:  NB  NS  ZE  PS  PB
RULES = ((0, 0, 0, 1, 2),  # e NB
         (0, 0, 1, 2, 3),  # e NS
         (0, 1, 2, 3, 4),  # e ZE
         (1, 2, 3, 4, 4),  # e PS
         (2, 3, 4, 4, 4))  # e PB


def memberships(x: float, centres: Sequence[float]) -> np.ndarray:
    """Degrees (0..1) of x in 5 triangular sets with the given increasing centres.

    Each set peaks (1) at its centre and falls linearly to 0 at its neighbours' centres; the
    outer two are shoulders, 1 beyond the outer centres. The degrees always sum to 1 and at most
    two neighbouring sets fire, so at a centre exactly one set has degree 1.
    """
    c = centres
    mu = np.zeros(len(c))
    if x <= c[0]:
        mu[0] = 1.0
    elif x >= c[-1]:
        mu[-1] = 1.0
    else:
        k = int(np.searchsorted(c, x, side="right")) - 1  # c[k] <= x < c[k+1]
        w = (x - c[k]) / (c[k + 1] - c[k])
        mu[k], mu[k + 1] = 1.0 - w, w
    return mu


class FuzzyPD:
    """u = u_scale * F(e / e_scale, de / de_scale)  (V), e the tip sensor (V), de = Δe/T (V/s).

    F, on the normalised universes [-1, 1] (inputs beyond are held at the shoulders):
      - 5 triangular sets per input (NB NS ZE PS PB), centres (-1, -c, 0, c, 1) with
        c = `e_inner` for the error, `de_inner` for its rate (defaults 0.5: evenly
        spaced), NB and PB shoulders;
      - 25 rules `rules` (default `RULES`, the diagonal table), output singletons
        `singletons` (default -1, -0.5, 0, 0.5, 1) for NB ... PB;
      - rule strength = product (default) or min of the two degrees (`inference`);
      - fired outputs aggregated by their sum per singleton, then the fired-weighted average
        Σ w_r s_r / Σ w_r (paper section 2.4).
    With the defaults and product inference the sets form a partition of unity, so F is the
    bilinear interpolation of the rule table: F = E + DE exactly on the 10 of 16 cells whose
    four rules are unsaturated (a band along E = -DE that holds |E|, |DE| <= 0.5), i.e. a
    linear PD of Kp = u_scale/e_scale (V/V) and Kd = u_scale/de_scale (V s/V) for small
    signals, whose output saturates smoothly at ±u_scale for large ones.

    Gains [choice], tuned on the nominal 0.7 kg, 2.5 mm step: e_scale 10 V (the sensor's
    range), de_scale 800 V/s, u_scale 2 V, i.e. small-signal Kp 0.2 V/V, Kd 0.0025 V s/V.
    Noise off, product inference: rise 0.053 s, overshoot 5.3 %, settling 0.166 s (paper
    table 12 simulation: rise 0.055 s, settling 0.1 s). Kd is held below the nominal model's
    stability limit at 0 kg (about 0.0037 V s/V at Kp 0.2: the rate of the non-collocated tip
    signal pumps the first flexible mode, 42 Hz in closed loop), so the same gains serve
    0 ... 1.6 kg; at 0 kg that mode still rings visibly for ~0.2 s.
    The rig saturates u at ±24 V and limits the current (rigs.md §1).
    period T in s; the first call has de = 0.
    """

    def __init__(self, e_scale: float = 10.0, de_scale: float = 800.0, u_scale: float = 2.0,
                 e_inner: float = 0.5, de_inner: float = 0.5, singletons: Sequence[float] = (-1.0, -0.5, 0.0, 0.5, 1.0),
                 rules: Sequence[Sequence[int]] = RULES, inference: str = "product",
                 period: float = CONTROL_PERIOD):
        self.e_scale, self.de_scale, self.u_scale = float(e_scale), float(de_scale), float(u_scale)
        self.period = float(period)
        if min(self.e_scale, self.de_scale, self.period) <= 0:
            raise ValueError("fuzzy_pd: e_scale, de_scale and period must be > 0")
        for name, inner in (("e_inner", e_inner), ("de_inner", de_inner)):
            if not 0.0 < float(inner) < 1.0:
                raise ValueError(f"fuzzy_pd: {name} must be in (0, 1), got {inner!r}")
        self.e_centres = np.array([-1.0, -float(e_inner), 0.0, float(e_inner), 1.0])
        self.de_centres = np.array([-1.0, -float(de_inner), 0.0, float(de_inner), 1.0])
        self.singletons = np.array(singletons, float)
        self.rules = np.array(rules, int)
        if self.singletons.shape != (5,) or self.rules.shape != (5, 5):
            raise ValueError("fuzzy_pd: need 5 singletons and a 5x5 rule table")
        if self.rules.min() < 0 or self.rules.max() > 4:
            raise ValueError("fuzzy_pd: rule entries are singleton indices 0..4")
        if inference not in ("product", "min"):
            raise ValueError(f"fuzzy_pd: inference must be 'product' or 'min', got {inference!r}")
        self.inference = inference
        self.reset()

    def reset(self) -> None:
        self._previous = None

    def surface(self, e_norm: float, de_norm: float) -> float:
        """F(E, DE) on the normalised universes, in units of u_scale (dimensionless)."""
        mu_e = memberships(e_norm, self.e_centres)
        mu_de = memberships(de_norm, self.de_centres)
        if self.inference == "product":
            w = np.outer(mu_e, mu_de)
        else:
            w = np.minimum.outer(mu_e, mu_de)
        fired = np.bincount(self.rules.ravel(), weights=w.ravel(), minlength=5)  # sum aggregation
        return float(fired @ self.singletons / fired.sum())

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        e = obs["tip_sensor"]
        de = 0.0 if self._previous is None else (e - self._previous) / self.period
        self._previous = e
        return {"voltage_cmd": self.u_scale * self.surface(e / self.e_scale, de / self.de_scale)}
