"""Open loop: command channels as given functions of time (scenario signals or a replay)."""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np


class OpenLoop:
    """Returns {channel: f(t)} for each command channel; ignores the measurements."""

    def __init__(self, commands: Mapping[str, Callable[[float], float]]):
        self.commands = dict(commands)

    def reset(self) -> None:
        pass

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        return {channel: f(t) for channel, f in self.commands.items()}

    @classmethod
    def columns(cls, members: list["OpenLoop"], times: np.ndarray) -> "OpenLoopColumns | None":
        """The members' commands tabulated at the tick times `times` (s), for lockstep's columns."""
        if any(type(m) is not OpenLoop or set(m.commands) != set(members[0].commands) for m in members):
            return None
        ts = times.tolist()
        return OpenLoopColumns({c: np.array([[m.commands[c](t) for t in ts] for m in members], dtype=float).T
                                for c in members[0].commands})


class OpenLoopColumns:
    """OpenLoop of B members at once: call k returns row k of each channel's (ticks, B) table."""

    def __init__(self, tables: dict[str, np.ndarray]):
        self.tables, self.k = tables, 0

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        k, self.k = self.k, self.k + 1
        return {c: table[k] for c, table in self.tables.items()}
