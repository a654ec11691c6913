"""Laser-arm PD step at the paper's four payloads: rise time and overshoot of the tip.

Run: python examples/payload_sweep.py   (about 1 s)
Uses the public API: run_scenario returns the recording as arrays (time in s, channels in SI units).
"""
from watflex_sim import run_scenario
from watflex_sim.metrics import step_metrics
from watflex_sim.params import LASER_ARM

L = LASER_ARM.beam.length  # m
print(f"{'payload [kg]':>12} {'rise [s]':>9} {'overshoot [%]':>14} {'settling [s]':>13}")
for payload in (0.0, 0.7, 1.15, 1.6):
    rec = run_scenario("laser_arm_step", payload_kg=payload, noise=False)
    ch = rec.channels
    tip = L * ch["reference"] - ch["tip_sensor"] / LASER_ARM.sensor_gain  # m along the arc
    m = step_metrics(rec.time, tip, t_step=0.1, initial=0.0, final=L * ch["reference"][-1])
    print(f"{payload:12.2f} {m['rise_time_s']:9.3f} {m['overshoot_pct']:14.1f} {m['settling_time_s']:13.3f}")
