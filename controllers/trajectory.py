"""Cubic point-to-point trajectories (thesis 5.1.3, eq. 5.13), in joint or Cartesian coordinates.

Each coordinate moves from rest to rest: x(t) = x0 + e (3 s^2 - 2 s^3), s = (t - t0)/T in [0, 1],
so x(t0) = x0, x(t0 + T) = x0 + e and the velocity is zero at both ends (the thesis writes
it from x0 = 0: c0 = c1 = 0, c2 = 3e/T^2, c3 = -2e/T^3). Before t0 the trajectory holds x0,
after t0 + T it holds the end point. Units are the caller's (rad or m; t in s).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np


class CubicTrajectory:
    """One rest-to-rest move of any dimension from `start` to `end` in `duration_s` from `start_s`.

    Raises ValueError for a non-positive duration or start and end of different sizes.
    """

    def __init__(self, start: Sequence[float], end: Sequence[float], duration_s: float, start_s: float = 0.0):
        self.start = np.atleast_1d(np.asarray(start, float))
        self.end = np.atleast_1d(np.asarray(end, float))
        if self.start.shape != self.end.shape:
            raise ValueError(f"trajectory: start {self.start.tolist()} and end {self.end.tolist()} differ in size")
        if not duration_s > 0:
            raise ValueError(f"trajectory: duration must be > 0 s, got {duration_s}")
        self.T, self.t0 = float(duration_s), float(start_s)
        e = self.end - self.start
        # eq. 5.13 coefficients per coordinate (c0 = x0 here, c1 = 0)
        self.c2 = 3.0 * e / self.T**2
        self.c3 = -2.0 * e / self.T**3

    def _tau(self, t: float) -> float:
        return min(max(t - self.t0, 0.0), self.T)

    def position(self, t: float) -> np.ndarray:
        """Position at time t (s)."""
        s = self._tau(t)
        return self.start + self.c2 * s**2 + self.c3 * s**3

    def velocity(self, t: float) -> np.ndarray:
        """Velocity (unit/s) at time t; zero outside the move."""
        if t <= self.t0 or t >= self.t0 + self.T:
            return np.zeros_like(self.start)
        s = t - self.t0
        return 2.0 * self.c2 * s + 3.0 * self.c3 * s**2

    def acceleration(self, t: float) -> np.ndarray:
        """Acceleration (unit/s^2) at time t; zero outside the move (it jumps at both ends)."""
        if t < self.t0 or t > self.t0 + self.T:
            return np.zeros_like(self.start)
        s = t - self.t0
        return 2.0 * self.c2 + 6.0 * self.c3 * s


class MoveSequence:
    """Rest-to-rest cubic moves through `points`, move i starting at `start_s[i]` and lasting
    `duration_s[i]` (s); each move starts where the previous one ended. The first move starts
    from `origin`, which may be given later (`set_origin`, e.g. the measured position at the
    first control period). Raises ValueError if the moves overlap or the lists differ in length.
    """

    def __init__(self, points: Sequence[Sequence[float]], start_s: Sequence[float],
                 duration_s: Sequence[float], origin: Sequence[float] | None = None):
        if not (len(points) == len(start_s) == len(duration_s)) or not points:
            raise ValueError("trajectory: 'points', 'start_s' and 'duration_s' must be non-empty lists of equal length")
        for i in range(1, len(points)):
            if start_s[i] < start_s[i - 1] + duration_s[i - 1]:
                raise ValueError(f"trajectory: move {i} starts at {start_s[i]} s before move {i - 1} ends")
        self.points = [np.asarray(p, float) for p in points]
        self.start_s, self.duration_s = [float(t) for t in start_s], [float(t) for t in duration_s]
        self.moves: list[CubicTrajectory] = []
        if origin is not None:
            self.set_origin(origin)

    def set_origin(self, origin: Sequence[float]) -> None:
        """Build the moves from `origin` (the position before the first move)."""
        previous, self.moves = np.asarray(origin, float), []
        for p, t0, T in zip(self.points, self.start_s, self.duration_s):
            self.moves.append(CubicTrajectory(previous, p, T, t0))
            previous = p

    def _move(self, t: float) -> CubicTrajectory:
        if not self.moves:
            raise RuntimeError("trajectory: origin not set (call set_origin first)")
        i = int(np.searchsorted(self.start_s, t, side="right")) - 1
        return self.moves[max(i, 0)]

    def position(self, t: float) -> np.ndarray:
        return self._move(t).position(t)

    def velocity(self, t: float) -> np.ndarray:
        return self._move(t).velocity(t)
