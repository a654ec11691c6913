"""Interactive runs: the same 1 ms loop as `engine.simulate`, drawn in MuJoCo's passive viewer."""
from __future__ import annotations

import time

import mujoco.viewer

from .engine import ControlLoop
from .params import CONTROL_PERIOD

FRAME_EVERY = 16  # control periods between redraws (~60 frames per second)


def view(scenario: dict) -> None:
    """Run `scenario` at real time in the passive viewer until its duration or the window closes."""
    loop = ControlLoop(scenario)
    with loop, mujoco.viewer.launch_passive(loop.model, loop.data) as handle:
        start = time.perf_counter()
        for k in range(loop.n_ticks):
            if not handle.is_running():
                break
            loop.tick(k)
            if k % FRAME_EVERY == 0:
                handle.sync()
                lag = k * CONTROL_PERIOD - (time.perf_counter() - start)
                if lag > 0:
                    time.sleep(lag)
