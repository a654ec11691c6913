"""Per-sample discrete filters for controllers (coefficients from scipy.signal)."""
from __future__ import annotations

import numpy as np
from scipy import signal


class Butterworth2:
    """2nd-order low-pass Butterworth run one sample at a time (direct form II transposed).

    cutoff_hz and rate_hz in Hz; the state starts at rest at the first input.
    """

    def __init__(self, cutoff_hz: float, rate_hz: float):
        b, a = signal.butter(2, cutoff_hz, fs=rate_hz)
        self.b0, self.b1, self.b2 = (float(x) for x in b)
        self.a1, self.a2 = float(a[1]), float(a[2])
        self.reset()

    def reset(self) -> None:
        self.z1 = self.z2 = None

    @classmethod
    def columns(cls, members: list["Butterworth2"]) -> "Butterworth2":
        """The members as one filter on arrays of shape (B,): their coefficients as arrays, the same arithmetic."""
        out = cls.__new__(cls)
        for name in ("b0", "b1", "b2", "a1", "a2"):
            setattr(out, name, np.array([getattr(m, name) for m in members]))
        out.reset()
        return out

    def __call__(self, x: float) -> float:
        if self.z1 is None:  # steady state for a constant input x
            self.z1 = x * (1.0 - self.b0)
            self.z2 = x * (self.b2 - self.a2)
        y = self.b0 * x + self.z1
        self.z1 = self.b1 * x - self.a1 * y + self.z2
        self.z2 = self.b2 * x - self.a2 * y
        return y
