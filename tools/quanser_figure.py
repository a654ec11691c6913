"""Figure docs/quanser_fit.png: the Quanser 2DSFL runs, measured vs nominal vs diagnosed model.

Usage: python tools/quanser_figure.py REPORT_DIR [--out docs/quanser_fit.png] [--rate-method M]
REPORT_DIR is a `watflex-sim diagnose` output on tests/data/quanser_2dsfl/data_{fsf,psf}_th11.mat;
its patch.json (effects and refit parameters) is re-simulated. Hub 2 and its current are shown,
where the rig's drive 2 visibly sticks short of its target, and hub 1, whose moves knock it.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from watflex_sim.recording import read_recording  # noqa: E402
from watflex_sim.resim import resimulate  # noqa: E402

DATA = ROOT / "tests" / "data" / "quanser_2dsfl"
DEG = 180 / math.pi


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "quanser_fit.png")
    parser.add_argument("--rate-method", help="override the sidecar's rate filter discretisation (the diagnosis must have used it)")
    args = parser.parse_args()
    patch = json.loads((args.report / "patch.json").read_text())
    runs = ("fsf", "psf")
    rows = (("hub2", DEG, "hub 2 [deg]"), ("current2_cmd", 1.0, "current 2 command [A]"), ("hub1", DEG, "hub 1 [deg]"))
    fig, axes = plt.subplots(len(rows), len(runs), figsize=(13, 8), sharex=True)
    for col, run in enumerate(runs):
        rec = read_recording(DATA / f"data_{run}_th11.mat")
        if args.rate_method:
            rec.meta["controller"]["rate_method"] = args.rate_method
        nominal = resimulate(rec)
        diagnosed = resimulate(rec, patch.get("effects", []), patch.get("parameters", {}))
        for row, (channel, scale, label) in enumerate(rows):
            ax = axes[row, col]
            ax.plot(rec.time, rec.channels[channel] * scale, "k", lw=1.2, label="measured")
            ax.plot(rec.time, nominal.channels[channel] * scale, "C0--", lw=1, label="nominal model")
            ax.plot(rec.time, diagnosed.channels[channel] * scale, "C3:", lw=1.4, label="diagnosed model")
            if channel.startswith("hub"):
                ax.plot(rec.time, rec.channels[f"{channel}_reference"] * scale, color="0.6", lw=0.8, label="reference")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        axes[0, col].set_title(f"Quanser 2DSFL, {run} run ({'full' if run == 'fsf' else 'partial'}-state feedback)")
        axes[-1, col].set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8, ncol=2)
    fig.tight_layout()
    args.out.parent.mkdir(exist_ok=True)
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
