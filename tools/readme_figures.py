"""Regenerate the README's figures in docs/ (about 5 s): python tools/readme_figures.py"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from watflex_sim import run_scenario  # noqa: E402
from watflex_sim.plot import plot_recording  # noqa: E402

DOCS = Path(__file__).resolve().parent.parent / "docs"


def main() -> None:
    DOCS.mkdir(exist_ok=True)
    positive = run_scenario("laser_arm_step", payload_kg=0.7)
    negative = run_scenario("laser_arm_step", payload_kg=0.7, direction="negative")
    print(plot_recording(positive, DOCS / "laser_arm_step.png", {"anticlockwise": negative},
                         title="laser arm, 2.5 mm tip step, 0.7 kg payload, PD Kp = 0.127 V/V"))
    print(plot_recording(run_scenario("watflex_elbow_step"), DOCS / "watflex_elbow_step.png",
                         title="Watflex elbow PD step 0.5 rad, single-link set-up"))


if __name__ == "__main__":
    main()
