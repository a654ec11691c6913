"""dm_control interface: the rigs as `control.Environment`s stepped every 1 ms.

`load(rig)` builds a reference-step task from the rig's step scenario
(`scenarios/laser_arm_step.toml`, `scenarios/watflex_elbow_step.toml`): the physics is
the project's model (`model.load_model`), the observations are the project's sensors
(`rigs.LaserArmRig.observe`, `rigs.WatflexRig.observe`) and the actions go through the
rig's amplifier or converter (`Rig.actuate`), so an agent sees exactly what a controller
in `engine.simulate` sees.
"""
from __future__ import annotations

import collections

import numpy as np
from dm_control import mujoco
from dm_control.mujoco import wrapper
from dm_control.rl import control
from dm_control.suite import base
from dm_control.utils import rewards
from dm_env import specs

from .engine import _settle_bearings
from .model import ConfigError, load_model, rig_params
from .params import CONTROL_PERIOD
from .rigdesc import load_rig
from .scenario import load_scenario

_SCENARIO = {"laser_arm": "laser_arm_step", "watflex": "watflex_elbow_step"}
_JOINTS = ("hub", "shoulder", "elbow")
# actuator name -> the rig's command channel (recordings.md names)
_COMMAND = {"motor": "voltage_cmd", "shoulder_motor": "shoulder_torque_cmd", "elbow_motor": "elbow_torque_cmd"}
# reward: measured error within +-bound scores 1, falling to 0.1 at `margin` beyond it [ours]
_REWARD = {"laser_arm": (1e-4, 2.5e-3),  # m of tip error (tip sensor / 3.3 V/mm)
           "watflex": (0.01, 0.5)}  # rad of elbow error


class FlexArmPhysics(mujoco.Physics):
    """A rig's MuJoCo model with named read-outs (rad, m). Build with `from_rig`."""

    @classmethod
    def from_rig(cls, rig: str, payload_kg: float = 0.0, locked_joints: dict[str, float] | None = None,
                 timestep: float | None = None) -> "FlexArmPhysics":
        """`model.load_model(rig, payload_kg (kg), locked_joints (rad), timestep (s))` wrapped.

        Raises model.ConfigError for an unknown rig, a negative payload or an unknown joint.
        """
        model = load_model(rig, payload_kg=payload_kg, locked_joints=locked_joints, timestep=timestep)
        return cls.from_model(wrapper.MjModel(model))

    def hub_angle(self) -> float:
        """Laser-arm hub angle (rad, true, not quantised); KeyError on the Watflex model."""
        return float(self.named.data.qpos["hub"][0])

    def joint_angles(self) -> dict[str, float]:
        """Actuated joint angles (rad) by name ('hub' or 'shoulder', 'elbow'); locked joints are absent."""
        names = set(self.named.data.qpos.axes.row.names)
        return {j: float(self.named.data.qpos[j][0]) for j in _JOINTS if j in names}

    def tip_position(self) -> np.ndarray:
        """World position (m) of site 'tip': the laser arm's tip, the Watflex end-effector centre."""
        return self.named.data.site_xpos["tip"].copy()

    def bending_angles(self, link: str) -> np.ndarray:
        """Hinge angles (rad) of a flexible chain, root to tip: link 'beam', 'link1' or 'link2'.

        Raises ValueError if the model has no such chain.
        """
        names = [n for n in self.named.data.qpos.axes.row.names if n.startswith(f"{link}_j")]
        if not names:
            raise ValueError(f"no flexible chain {link!r} in this model (laser arm: 'beam'; watflex: 'link1', 'link2')")
        return self.named.data.qpos[sorted(names)].copy()


class StepTask(base.Task):
    """Follow a reference step with the rig's sensors and actuator.

    Laser arm: the reference is the laser spot direction theta_c (rad, = arc / L), the action
    the amplifier voltage (V, +-24). Watflex: the shoulder is locked, the reference is the
    elbow angle (rad), the action the elbow torque (N m, +-53.8 converter limit).
    Observations are `Rig.observe`'s channels, each shape (1,); `last_command` holds what
    `Rig.actuate` recorded. Reward: `rewards.tolerance` of the measured error (m or rad).
    """

    def __init__(self, rig: str, amplitude: float, step_time_s: float, locked_joints: dict[str, float] | None = None,
                 noise: bool = True, random=None):
        """amplitude (rad) applies from step_time_s (s); `random`: seed or RandomState for the noise."""
        super().__init__(random=random)
        self.rig_name, self.description = rig, load_rig(rig)
        self.params = self.description.params
        self.amplitude, self.step_time_s = float(amplitude), float(step_time_s)
        self.locked = dict(locked_joints or {})
        self.noise = bool(noise)
        self.reference_channel = "reference" if rig == "laser_arm" else "elbow_reference"
        self.rig = None
        self.last_command: dict[str, float] = {}
        self._obs = None
        self._held: dict[str, float] = {}  # last camera frame (m)
        self._age = 0.0  # s since it

    def _make_rig(self, physics, seed: int, noise: bool):
        return self.description.make_sensors(physics.model.ptr, physics.data.ptr, {"noise": noise, "seed": seed,
                                             "n_segments": 0, "locked_joints": self.locked}, CONTROL_PERIOD)

    def reference(self, t: float) -> float:
        """Reference (rad) at time t (s), evaluated on the 1 ms control grid."""
        tick = round(t / CONTROL_PERIOD)
        return self.amplitude if tick >= round(self.step_time_s / CONTROL_PERIOD) else 0.0

    def initialize_episode(self, physics):
        """Home keyframe, air bearings settled (Watflex), a new rig whose noise seed comes from `self.random`."""
        if physics.model.nkey:
            physics.reset(keyframe_id=0)
        _settle_bearings(physics.model.ptr, physics.data.ptr)
        self.rig = self._make_rig(physics, int(self.random.randint(2**31 - 1)), self.noise)
        self.last_command, self._held, self._age = {}, {}, 0.0
        super().initialize_episode(physics)  # calls after_step: clears the measurement

    def before_step(self, action, physics):
        """Send the action (V or N m per actuator, in action_spec order) through `Rig.actuate`."""
        action = np.asarray(getattr(action, "continuous_actions", action), dtype=float).ravel()
        names = [physics.model.id2name(i, "actuator") for i in range(physics.model.nu)]
        self.last_command = self.rig.actuate({_COMMAND[n]: float(a) for n, a in zip(names, action)})

    def after_step(self, physics):
        self._obs = None  # measured once per control step, on first use

    def _measure(self, physics) -> dict[str, float]:
        """The rig's channels; a camera channel between its 25 Hz frames holds the last frame
        (an agent never sees NaN) and `camera_age_s` (s) tells how old that frame is."""
        if self._obs is None:
            obs = self.rig.observe({self.reference_channel: self.reference(physics.time())})
            if "tip_x" in obs:
                fresh = np.isfinite(obs["tip_x"])
                self._age = 0.0 if fresh else self._age + CONTROL_PERIOD
                for c in ("tip_x", "tip_y"):
                    self._held[c] = obs[c] if fresh else self._held.get(c, 0.0)
                    obs[c] = self._held[c]
                obs["camera_age_s"] = self._age
            self._obs = obs
        return self._obs

    def get_observation(self, physics):
        """The rig's measured channels (rad, V, m; Watflex camera held between its 25 Hz frames,
        with `camera_age_s`, s since that frame)."""
        return collections.OrderedDict((k, np.array([v], dtype=float)) for k, v in self._measure(physics).items())

    def observation_spec(self, physics):
        """Channel names and shapes, from a noiseless probe rig (the episode's noise is untouched)."""
        probe = self._make_rig(physics, 0, False).observe({self.reference_channel: 0.0})
        if "tip_x" in probe:
            probe["camera_age_s"] = 0.0
        return collections.OrderedDict((k, specs.Array((1,), float, name=k)) for k in probe)

    def error(self, physics) -> float:
        """Measured tracking error: tip (m, tip sensor / gain) or elbow (rad, reference - encoder)."""
        obs = self._measure(physics)
        if self.rig_name == "laser_arm":
            return obs["tip_sensor"] / self.params.sensor_gain
        return obs["elbow_reference"] - obs["elbow_angle"]

    def get_reward(self, physics) -> float:
        """1 when |error| <= bound, Gaussian fall-off to 0.1 at `margin` beyond it (see _REWARD)."""
        bound, margin = _REWARD[self.rig_name]
        return float(rewards.tolerance(self.error(physics), bounds=(-bound, bound), margin=margin))


def load(rig: str = "laser_arm", payload_kg: float = 0.0, seed=None, time_limit: float = 1.0,
         noise: bool = True) -> control.Environment:
    """The rig's step task (amplitude, step time, direction and locks from its scenario file).

    payload_kg (kg) at the tip, seed for the measurement noise, time_limit (s) per episode,
    control timestep 1 ms. Raises ConfigError for an unknown rig or a bad payload.
    """
    params = rig_params(rig)
    if rig not in _SCENARIO:
        raise ConfigError(f"no dm_control task for rig {rig!r} (known: {', '.join(_SCENARIO)})")
    scenario = load_scenario(_SCENARIO[rig])
    table = scenario["reference"][0]
    sign = 1.0 if scenario["direction"] == "positive" else -1.0
    amplitude = sign * (table["arc_m"] / params.beam.length if "arc_m" in table else table["amplitude"])
    physics = FlexArmPhysics.from_rig(rig, payload_kg, scenario["locked_joints"])
    task = StepTask(rig, amplitude, table["time_s"], scenario["locked_joints"], noise=noise, random=seed)
    return control.Environment(physics, task, control_timestep=CONTROL_PERIOD, time_limit=time_limit)
