"""Open loop: command channels as given functions of time (scenario signals or a replay)."""
from __future__ import annotations

from typing import Callable, Mapping


class OpenLoop:
    """Returns {channel: f(t)} for each command channel; ignores the measurements."""

    def __init__(self, commands: Mapping[str, Callable[[float], float]]):
        self.commands = dict(commands)

    def reset(self) -> None:
        pass

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        return {channel: f(t) for channel, f in self.commands.items()}
