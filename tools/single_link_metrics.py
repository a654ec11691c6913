"""Peak link-2 strains and elbow step metrics of Watflex recordings (README "Single-link set-up").

Usage: python tools/single_link_metrics.py DIR [DIR ...]   (each DIR holds watflex_elbow_*.csv)
Prints, per recording: peak |strain_2A|, |strain_2B| (V), whether strain_1* channels are present,
and per reference step the elbow overshoot and 2 % settling time (NaN: friction holds it outside
the band), when the encoder last moved and where the joint stopped (% of the step).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from watflex_sim.metrics import step_metrics  # noqa: E402
from watflex_sim.recording import read_recording  # noqa: E402


def summary(path: Path) -> str:
    rec = read_recording(path)
    ch, t = rec.channels, rec.time
    parts = [f"{path.parent.name}/{path.stem}:",
             f"peak |2A| {np.nanmax(np.abs(ch['strain_2A'])):.3f} V, |2B| {np.nanmax(np.abs(ch['strain_2B'])):.3f} V",
             f"strain_1* in the file: {'yes' if 'strain_1A' in path.open().readline() else 'no'}"]
    ref = ch.get("elbow_reference", np.zeros_like(t))
    jumps = np.flatnonzero(np.abs(np.diff(ref)) > 1e-9)
    if jumps.size:
        for i, j in enumerate(jumps):
            end = jumps[i + 1] + 1 if i + 1 < len(jumps) else len(t)
            y, step = ch["elbow_angle"][: end], ref[j + 1] - ref[j]
            m = step_metrics(t[: end], y, t[j + 1], ref[j], ref[j + 1])
            moves = np.flatnonzero(np.diff(y[j:]) != 0)  # encoder count changes after the step
            rest = t[j + 1 + moves[-1]] - t[j + 1] if moves.size else 0.0
            parts.append(f"step {ref[j]:+.2f}->{ref[j + 1]:+.2f} rad at {t[j + 1]:.1f} s: overshoot "
                         f"{m['overshoot_pct']:.1f} %, 2 % settling {m['settling_time_s']:.3f} s, at rest "
                         f"{rest:.3f} s after the step, {100 * (y[-1] - ref[j + 1]) / step:+.1f} % of the step off")
    else:
        parts.append(f"elbow moved {np.ptp(ch['elbow_angle']):.2e} rad")
    return "\n  ".join(parts)


if __name__ == "__main__":
    for d in sys.argv[1:]:
        for csv in sorted(Path(d).glob("*.csv")):
            print(summary(csv))
