"""pd_tip, pd_joint and cascade_p as instances of the generic laws (issue 15 item 3): the same
commands as the classes they replaced, kept here verbatim, on three shipped set-ups, 0.5 s each."""
from typing import Mapping, Sequence

import numpy as np
import pytest

from watflex_sim.controllers import PID, CascadeP, PDJoint, PDTip, StateFeedback
from watflex_sim.controllers.filters import Butterworth2
from watflex_sim.engine import ControlLoop
from watflex_sim.scenario import load_scenario


class OldPDTip:  # controllers/pd_tip.py before this change
    def __init__(self, kp=0.127, kd=0.0, period=1e-3):
        self.kp, self.kd, self.period = float(kp), float(kd), float(period)
        self.reset()

    def reset(self):
        self._previous = None

    def __call__(self, t, obs):
        e = obs["tip_sensor"]
        de = 0.0 if self._previous is None else (e - self._previous) / self.period
        self._previous = e
        return {"voltage_cmd": self.kp * e + self.kd * de}


class OldPDJoint:  # controllers/pd_joint.py before this change
    def __init__(self, joints: Sequence[str] = ("elbow",), kp=(60.0,), kd=(12.0,), filter_hz=10.0, period=1e-3):
        self.joints, self.kp, self.kd = list(joints), [float(k) for k in kp], [float(k) for k in kd]
        self.period = float(period)
        self.filters = [Butterworth2(filter_hz, 1.0 / period) for _ in self.joints]
        self.reset()

    def reset(self):
        self._previous = [None] * len(self.joints)
        for f in self.filters:
            f.reset()

    def __call__(self, t, obs: Mapping[str, float]):
        out = {}
        for i, j in enumerate(self.joints):
            theta = obs[f"{j}_angle"]
            prev = self._previous[i]
            rate = self.filters[i](0.0 if prev is None else (theta - prev) / self.period)
            self._previous[i] = theta
            out[f"{j}_torque_cmd"] = self.kp[i] * (obs[f"{j}_reference"] - theta) - self.kd[i] * rate
        return out


class OldCascadeP:  # controllers/cascade_p.py before this change
    def __init__(self, kp, kv, position="qm", reference="qg", command="vir", period=1e-3):
        self.kp, self.kv, self.period = float(kp), float(kv), float(period)
        self.position, self.reference, self.command = position, reference, command
        self.reset()

    def reset(self):
        self._history = []

    def __call__(self, t, obs):
        q = obs[self.position]
        self._history = (self._history + [q])[-3:]
        dq = (q - self._history[0]) / (2 * self.period) if len(self._history) == 3 else 0.0
        return {self.command: self.kp * self.kv * (obs[self.reference] - q) - self.kv * dq}


EMPS = """rig = "emps"
experiment = "emps_moves"
duration_s = 0.5
reference = { channel = "qg", kind = "triangle", amplitude = 0.02, slope = 0.2, periods = 2 }
[controller]
type = "cascade_p"
kp = 160.18
kv = 243.45
"""  # rigs/emps.toml's gains, as tests/test_rig_folder.py's scenario
CASES = {  # scenario, overrides (a derivative gain and a step inside 0.5 s), old class, new class
    "pd_tip": ("laser_arm_step", ["controller.kd=0.002"], OldPDTip, PDTip, PID),
    "pd_joint": ("watflex_elbow_step", ["reference.time_s=0.1"], OldPDJoint, PDJoint, StateFeedback),
    "cascade_p": ("emps.toml", [], OldCascadeP, CascadeP, PID),
}


def commands(scenario: dict, law=None) -> np.ndarray:
    """Recorded commands, one column per command channel, every tick of the run."""
    rows = []
    with ControlLoop(scenario) as loop:
        if law is not None:
            spec = {k: v for k, v in scenario["controller"].items() if k != "type"}
            loop.controller = law(**spec, period=loop.period)
            loop.controller.reset()
        channels = loop.rig.command_channels
        for k in range(loop.n_ticks):
            _, recorded = loop.tick(k)
            rows.append([recorded[c] for c in channels])
    return np.array(rows)


@pytest.mark.parametrize("name", CASES)
def test_the_registered_law_is_a_generic_law_with_the_old_commands(name, tmp_path):
    """Bit for bit (max abs difference 0): the generic laws evaluate the old expressions in the
    same floating-point order (negated gains and a 0 reference negate exactly, ki * 0 adds 0)."""
    base, over, old, new, generic = CASES[name]
    if name == "cascade_p":
        (tmp_path / base).write_text(EMPS)
        base = str(tmp_path / base)
    scenario = load_scenario(base, over + ["duration_s=0.5"])
    assert scenario["controller"]["type"] == name
    after = commands(scenario)
    with ControlLoop(scenario) as loop:
        assert isinstance(loop.controller, new) and isinstance(loop.controller, generic)
    before = commands(scenario, old)
    assert np.abs(after).max() > 0.01  # the loop did act
    assert np.abs(after - before).max() == 0.0
