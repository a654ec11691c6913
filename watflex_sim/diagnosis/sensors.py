"""Sensor effects without simulating: which channels a controller feeds back, and the signature of a gain or an
offset on a channel none reads (screening.signatures uses it; a sensor effect on a channel fed back changes the motion
and is simulated like any other).
"""
from __future__ import annotations

import numpy as np

from ..recording import Recording
from .data import Data, STRIDE


class _Reads(dict):
    """A dict that notes which keys were read (the channels a controller feeds back)."""

    def __init__(self, *args):
        super().__init__(*args)
        self.read = set()

    def __getitem__(self, key):
        self.read.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.read.add(key)
        return super().get(key, default)


def fed_back(data: Data) -> set[str]:
    """Channels some recording's controller reads: a sensor effect there changes the motion."""
    from ..engine import ControlLoop
    from ..resim import scenario_from_recording

    channels = set()
    for rec in data.recordings:
        scenario = scenario_from_recording(rec, data.rig)
        scenario["duration_s"] = 0.002
        loop = ControlLoop(scenario, rig=data.rig)
        with loop:
            obs = _Reads(loop.rig.observe(loop.references[0]))
            loop.controller(0.0, obs)
        channels |= obs.read
    return channels


def _layout(data: Data, sims: list[Recording], channel: str, stride: int = STRIDE) -> tuple[np.ndarray, np.ndarray]:
    """(entries of the training residual vector that belong to `channel`, simulated value / spread there)."""
    mask, values = [], []
    for sim, chans, scale, train in zip(sims, data.channels, data.scale, data.train):
        idx = np.flatnonzero(train)[::stride]
        if not idx.size:
            continue
        for c in chans:
            mask.append(np.full(idx.size, c == channel))
            values.append(np.nan_to_num(sim.channels[c][idx] / scale[c]) if c == channel else np.zeros(idx.size))
    return np.concatenate(mask), np.concatenate(values)


def sensor_signature(data: Data, sims: list[Recording], effect: str, channel: str) -> dict[str, np.ndarray]:
    """Signature (training residual per unit of the parameter, in spread units) of `effect` (sensor_gain or
    sensor_offset) on a `channel` no controller reads, from the simulations `sims` alone."""
    mask, values = _layout(data, sims, channel)
    if effect == "sensor_offset":
        spread = {c: s for sc in data.scale for c, s in sc.items()}[channel]
        return {"offset": mask / spread}
    return {"ratio": values}
