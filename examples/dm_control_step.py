"""Laser arm as a dm_control environment: the datasheet's tip PD (u = 0.127 e_V) for 1 s.

Run: python examples/dm_control_step.py   (headless; prints the final tip error in mm)
"""
import os

os.environ.setdefault("MUJOCO_GL", "disable")  # no rendering needed

from watflex_sim import dmc  # noqa: E402
from watflex_sim.params import LASER_ARM  # noqa: E402

env = dmc.load("laser_arm", payload_kg=0.7, seed=0, time_limit=1.0)  # 2.5 mm step at t = 0.1 s
ts = env.reset()
while not ts.last():
    ts = env.step([0.127 * ts.observation["tip_sensor"][0]])  # V, amplifier voltage
error_mm = 1e3 * ts.observation["tip_sensor"][0] / LASER_ARM.sensor_gain  # tip sensor 3.3 V/mm
print(f"t = {env.physics.time():.3f} s: tip error {error_mm:+.4f} mm (step 2.5 mm), reward {ts.reward:.3f}")
