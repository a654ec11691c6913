"""The controller interface every controller of the project implements."""
from __future__ import annotations

from typing import Mapping, Protocol


class Controller(Protocol):
    """Runs once per control period (1 ms) on measured channels only.

    `obs` holds the rig's measured channels at time t (recordings.md names and units,
    references included); the return value maps command channels (`voltage_cmd`,
    `shoulder_torque_cmd`, ...) to values before the rig's saturation and converters.
    """

    def reset(self) -> None: ...

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]: ...


class StatefulController(Controller, Protocol):
    """A controller with a state its inputs' recent past does not fix (an integral, an observer's estimate), which it
    can report and be set to (named values, SI units): a run that starts where a recording starts sets it to what
    the recording's first commands say it was (resim._controller_start, scenario key `controller_state`)."""

    def state(self) -> dict[str, float]: ...

    def set_state(self, values: Mapping[str, float]) -> None: ...


class SettlingController(Controller, Protocol):
    """A controller with a state it would hold after long at constant readings (an observer's estimate, a filter's
    memory): a run that starts at rest away from the nominal pose, as a recording cut from a longer run does, starts it
    so (engine.ControlLoop) instead of at its reset."""

    def settle(self, obs: Mapping[str, float]) -> None: ...

