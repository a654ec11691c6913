"""How long one diagnosis takes, and where the time goes (issue 6: <= 60 s for three 6 s recordings).

    python tools/bench_diagnose.py [--workers 2] [--duration 6]

Two cases of three recordings each, simulated with noise (seeded), diagnosed blind:
- laser arm: hub friction 0.6 / 0.3 N m; 2.5 mm steps positive and negative at 0.7 kg, then 1.15 kg;
- Watflex: end effector 1.0 kg heavier than declared; elbow steps +-0.5 rad, then the staircase.
Prints per case the findings, the wall time per stage (report "timing") and the ratio of the
diagnosis time to the recordings' simulated time, and the time of one re-simulation of a
recording without and with the friction callback (what a job costs).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from watflex_sim import load_scenario, simulate  # noqa: E402
from watflex_sim.diagnosis import diagnose  # noqa: E402
from watflex_sim.resim import resimulate  # noqa: E402

CASES = {
    "laser_arm": ([("laser_arm_step", ["direction=positive"]), ("laser_arm_step", ["direction=negative"]),
                   ("laser_arm_step", ["direction=positive", "payload_kg=1.15"])],
                  [dict(effect="coulomb_friction", where="hub", torque_positive=0.6, torque_negative=0.3)]),
    "watflex": ([("watflex_elbow_step", ["direction=positive"]), ("watflex_elbow_step", ["direction=negative"]),
                 ("watflex_elbow_staircase", [])],
                [dict(effect="payload", where="tip", mass=1.0)]),
}


def recordings(runs, effects, duration: float):
    out = []
    for i, (name, sets) in enumerate(runs):
        scenario = load_scenario(name, sets + [f"duration_s={duration}", "noise=true", f"seed={i + 1}"])
        scenario["effects"] = effects
        rec = simulate(scenario).recording
        rec.meta["scenario"].pop("effects")  # blind
        out.append(rec)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--duration", type=float, default=6.0, help="length of each recording, s (default 6)")
    args = parser.parse_args(argv)
    for rig, (runs, effects) in CASES.items():
        recs = recordings(runs, effects, args.duration)
        t = time.perf_counter()
        resimulate(recs[0])
        plain = time.perf_counter() - t
        t = time.perf_counter()
        resimulate(recs[0], effects if rig == "laser_arm" else [])
        loaded = time.perf_counter() - t
        start = time.perf_counter()
        report = diagnose(recs, [f"{rig}_{i}" for i in range(len(recs))], workers=args.workers)
        wall = time.perf_counter() - start
        found = ", ".join(f"{f['effect']}@{f['where']} {f['parameters']}" for f in report["findings"]) or "nothing missing"
        print(f"\n{rig}: truth {effects}\n  found: {found}")
        print(f"  one re-simulation of a {args.duration:g} s recording: {plain:.2f} s"
              + (f", {loaded:.2f} s with the friction callback" if rig == "laser_arm" else ""))
        print("  | stage | wall (s) | jobs |\n  |---|---:|---:|")
        for stage, row in report["timing"].items():
            print(f"  | {stage} | {row['seconds']:.1f} | {row['jobs']} |")
        simulated = args.duration * len(recs)
        print(f"  total {wall:.1f} s for {len(recs)} x {args.duration:g} s "
              f"({wall / simulated:.1f} s per simulated second; target 60 s: {'met' if wall <= 60 else 'missed'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
