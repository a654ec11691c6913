"""Several controllers side by side, each driving its own commands (a rig whose joints run different laws, or
at different rates: the lab's LQG at 10 ms on stage 1 beside Quanser's state feedback at 2 ms on stage 2).

As data: `type = "parallel"`, `parts = [{type = ..., ...}, ...]`, each part a controller table of its own
(engine.make_controller builds them); no two parts may drive the same command.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np


class Parallel:
    """Every part called each control period on the same measured channels; their commands merged."""

    def __init__(self, parts: Sequence):
        if not parts:
            raise ValueError("parallel needs at least one part")
        self.parts = list(parts)

    def reset(self) -> None:
        for part in self.parts:
            part.reset()

    def channels(self) -> set[str]:
        """The measured channels the parts read (those that say)."""
        return set().union(*(part.channels() for part in self.parts if hasattr(part, "channels")))

    def state(self) -> dict[str, float]:
        """The parts' states (controllers.base.StatefulController) as "PART:NAME", PART the part's index."""
        return {f"{i}:{name}": value for i, part in enumerate(self.parts) if hasattr(part, "state")
                for name, value in part.state().items()}

    def set_state(self, values: Mapping[str, float]) -> None:
        """Set the parts' states by "PART:NAME" (ValueError for a name no part has)."""
        unknown = set(values) - set(self.state())
        if unknown:
            raise ValueError(f"parallel state has {', '.join(self.state()) or 'nothing'}, "
                             f"got {', '.join(sorted(unknown))}")
        for i, part in enumerate(self.parts):
            mine = {name.partition(":")[2]: v for name, v in values.items() if name.partition(":")[0] == str(i)}
            if mine:
                part.set_state(mine)

    def settle(self, obs: Mapping[str, float]) -> None:
        """Each part that can (controllers.base.SettlingController) takes the state it holds at these readings."""
        for part in self.parts:
            if hasattr(part, "settle"):
                part.settle(obs)

    def __call__(self, t: float, obs: Mapping[str, float]) -> dict[str, float]:
        out: dict[str, float] = {}
        for part in self.parts:  # no two drive one command: engine.make_controller checks that once, when it builds
            out.update(part(t, obs))
        return out

    @classmethod
    def columns(cls, members: list["Parallel"], times: np.ndarray) -> "ParallelColumns | None":
        """Each part's column form over the members (lockstep's columns), or None where a part has none."""
        first = members[0]
        if any(type(m) is not type(first) or len(m.parts) != len(first.parts) for m in members):
            return None
        parts = []
        for j, part in enumerate(first.parts):
            group = [m.parts[j] for m in members]
            form = getattr(type(part), "columns", None)
            law = form(group, times) if form is not None and all(type(p) is type(part) for p in group) else None
            if law is None:
                return None
            parts.append(law)
        return ParallelColumns(parts)


class ParallelColumns:
    """Parallel of B members at once: each part's column form, their commands merged."""

    def __init__(self, parts: list):
        self.parts = parts

    def settle(self, obs: Mapping[str, np.ndarray], which: np.ndarray) -> None:
        for part in self.parts:
            if hasattr(part, "settle"):
                part.settle(obs, which)

    def __call__(self, t: float, obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for part in self.parts:
            out.update(part(t, obs))
        return out
