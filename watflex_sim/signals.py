"""Reference and open-loop command signals of the scenarios, as functions of time (s)."""
from __future__ import annotations

from typing import Callable

import numpy as np

from .model import ConfigError
from .params import CONTROL_PERIOD


def _number(spec: dict, key: str, default=None) -> float:
    value = spec.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"signal {spec.get('kind')!r}: {key!r} must be a number, got {value!r}")
    return float(value)


def make_signal(spec: dict, sign: float = 1.0, scale: float = 1.0) -> Callable[[float], float]:
    """A function t (s) -> value from a scenario table; `f.table(times)`, where present, gives the values
    at an array of times at once (the same numbers).

    Kinds: `step` (amplitude, time_s), `staircase` (levels, times_s: value levels[i] from
    times_s[i] on, 0 before), `triangle` (amplitude, slope per second, periods, start_s: a
    symmetric triangle starting at 0 and rising first), `constant` (value). `sign` (+1/-1)
    flips the direction; `scale` converts units (e.g. tip arc length -> rad).
    Raises ConfigError on an unknown kind or malformed numbers.
    """
    kind = spec.get("kind")
    k = sign * scale
    if kind == "step":
        amplitude, t0 = k * _number(spec, "amplitude"), _number(spec, "time_s", 0.0)

        def step(t: float) -> float:
            return amplitude if t >= t0 else 0.0

        step.table = lambda ts: np.where(ts >= t0, amplitude, 0.0)
        return step
    if kind == "staircase":
        levels, times = spec.get("levels"), spec.get("times_s")
        if not isinstance(levels, list) or not isinstance(times, list) or len(levels) != len(times) or not levels:
            raise ConfigError("signal 'staircase': 'levels' and 'times_s' must be lists of equal, non-zero length")
        levels_a = k * np.asarray(levels, dtype=float)
        times_a = np.asarray(times, dtype=float)
        if np.any(np.diff(times_a) <= 0):
            raise ConfigError("signal 'staircase': 'times_s' must increase")

        def staircase(t: float) -> float:
            i = int(np.searchsorted(times_a, t, side="right"))
            return float(levels_a[i - 1]) if i > 0 else 0.0

        staircase.table = lambda ts: np.where(ts >= times_a[0], levels_a[np.searchsorted(times_a, ts, side="right") - 1], 0.0)
        return staircase
    if kind == "triangle":
        amplitude, slope = _number(spec, "amplitude"), _number(spec, "slope")
        periods, t0 = _number(spec, "periods", 1.0), _number(spec, "start_s", 0.0)
        if amplitude <= 0 or slope <= 0:
            raise ConfigError("signal 'triangle': amplitude and slope must be > 0")
        quarter = amplitude / slope  # s
        period = 4 * quarter

        def triangle(t: float) -> float:
            s = t - t0
            if s < 0 or s >= periods * period:
                return 0.0
            phase = (s + quarter) % period  # 0 at the negative peak
            up = phase < 2 * quarter
            value = -amplitude + slope * phase if up else 3 * amplitude - slope * phase
            return k * value

        return triangle
    if kind == "samples":  # a recorded signal, held from one sample to the next (zero-order hold);
        # a sample stamped up to half a control period late still counts for that period (logged
        # time stamps jitter: EMPS's 0.00100002 s is the sample of the 1 ms period)
        times = np.asarray(spec.get("time_s", []), dtype=float)
        values = np.asarray(spec.get("values", []), dtype=float)
        if times.size == 0 or times.size != values.size:
            raise ConfigError("signal 'samples': 'time_s' and 'values' must be equal, non-empty lists")
        finite = np.isfinite(values)
        times, values = times[finite], k * values[finite]

        def held(t: float) -> float:
            i = int(np.searchsorted(times, t + 0.5 * CONTROL_PERIOD, side="right")) - 1
            return float(values[max(i, 0)])

        held.table = lambda ts: values[np.maximum(np.searchsorted(times, ts + 0.5 * CONTROL_PERIOD, side="right") - 1, 0)]
        return held
    if kind == "constant":
        value = k * _number(spec, "value")

        def constant(t: float) -> float:
            return value

        constant.table = lambda ts: np.full(np.shape(ts), value, dtype=float)
        return constant
    raise ConfigError(f"unknown signal kind {kind!r} (known: step, staircase, triangle, constant, samples)")

