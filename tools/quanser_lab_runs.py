"""A lab's own controllers on the Quanser 2DSFL, as data: its LQG and H-infinity stair runs re-simulated.

Usage: python tools/quanser_lab_runs.py [--controller lqg hinf] [--data DIR] [--out runs/quanser_lab] [--rig NAME]

The lab (basta/quanser-2-dof-serial-flexible-link, MIT; tests/data/quanser_2dsfl/lab/SOURCE.md) ran stage 1 under
controllers of its own design, each a discrete state space at 10 ms (orr_controllers.mat: `lqg_ss`, `hinf_ss`; inputs
the Simulink Mux of [hub, deflection, their rates] and the setpoint [reference, 0, 0, 0]; WIRING.md), with stage 2
left under Quanser's state feedback at 2 ms. A stair of steps (run_lab_experiments.m: 0, 5, -5, 10, -10, 20, -20, 30,
-30, 0 deg, 4 s each) was logged at 500 Hz and cut into one file a step; only stage 1 was logged.

Each file can be read as it is, with its controller, by the rig files rigs/quanser_2dsfl_lab_lqg.toml and
rigs/quanser_2dsfl_lab_hinf.toml (the base rig extended by the lab's .mat layout and controller: `watflex-sim diagnose
LAB/lqg_step_10deg_run01.mat --rig quanser_2dsfl_lab_lqg`). This tool joins each controller's ten files, so read,
into one recording of the contract (recordings.md: NAME.csv and its sidecar, the controller that rig file's `parallel`
of a `linear` law and Quanser's stage-2 `state_feedback`), re-simulates it on the rig's nominal model and prints, per
channel, the NRMSE and, per step, where hub 1 ends; a figure beside. The recordings can then be diagnosed like any
other: watflex-sim diagnose OUT/lqg_stair.csv --report OUT/lqg.
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from watflex_sim.metrics import nrmse  # noqa: E402

DATA = ROOT / "tests" / "data" / "quanser_2dsfl" / "lab"
STEPS_DEG = (0, 5, -5, 10, -10, 20, -20, 30, -30, 0)  # run_lab_experiments.m: amps_deg, each held seg_dur
SEGMENT_S = 4.0  # s, run_lab_experiments.m: seg_dur
CHANNELS = ("hub1_reference", "hub1", "link1")


def segment_files(data: Path, controller: str) -> list[Path]:
    """The run's files in the order they were logged (run_lab_experiments.m names them by step and repeat)."""
    seen: dict[int, int] = {}
    files = []
    for deg in STEPS_DEG:
        seen[deg] = seen.get(deg, 0) + 1
        files.append(data / f"{controller}_step_{'neg_' if deg < 0 else ''}{abs(deg)}deg_run{seen[deg]:02d}.mat")
    missing = [f.name for f in files if not f.is_file()]
    if missing:
        raise SystemExit(f"error: {data}: missing {', '.join(missing)}")
    return files


def law(controller: str, limit: float | None = None) -> dict:
    """The controller of the lab's rig file (rigs/quanser_2dsfl_lab_CONTROLLER.toml): the lab's state space on stage 1
    (its matrices those of orr_controllers.mat, clipped at its design's umax, A, unless `limit`) beside Quanser's
    stage-2 state feedback."""
    from watflex_sim.rigdesc import load_rig

    table = copy.deepcopy(load_rig(f"quanser_2dsfl_lab_{controller}").controller)
    if limit is not None:
        table["parts"][0]["limits"] = [limit]
    return table


def stair(data: Path, controller: str, limit: float | None = None) -> tuple[np.ndarray, dict]:
    """(samples: columns time s, hub1_reference, hub1, link1 rad), sidecar) of one controller's stair run: its files
    read as the lab logged them (the lab rig's .mat layout), one after the other."""
    from watflex_sim.recording import read_recording
    from watflex_sim.rigdesc import load_rig

    layout = load_rig(f"quanser_2dsfl_lab_{controller}").sidecar
    parts = []
    for i, path in enumerate(segment_files(data, controller)):
        seg = read_recording(path, sidecar=layout)
        parts.append(np.column_stack([seg.time + i * SEGMENT_S, *(seg.channels[c] for c in CHANNELS)]))
    sidecar = {"format": "flexarm-recording/1", "rig": "quanser_2dsfl", "experiment": f"lab_{controller}_stair",
               "mode": "closed_loop", "controller": law(controller, limit),
               "notes": f"stage 1 under the lab's {controller} (orr_controllers.mat), stage 2 under Quanser's K2; "
                        "stage 2 not logged; joined by tools/quanser_lab_runs.py"}
    return np.vstack(parts), sidecar


def write(samples: np.ndarray, sidecar: dict, stem: Path) -> Path:
    """NAME.csv and NAME.json; returns the csv's path."""
    stem.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(stem.with_suffix(".csv"), samples, delimiter=",", header=",".join(("time",) + CHANNELS), comments="",
               fmt="%.10g")
    stem.with_suffix(".json").write_text(json.dumps(sidecar, indent=1) + "\n")
    return stem.with_suffix(".csv")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--controller", nargs="+", choices=("lqg", "hinf"), default=["lqg", "hinf"])
    parser.add_argument("--data", type=Path, default=DATA, help=f"the lab's files (default {DATA.relative_to(ROOT)})")
    parser.add_argument("--out", type=Path, default=Path("runs/quanser_lab"), help="where the recordings and figure go")
    parser.add_argument("--rig", default="quanser_2dsfl", help="the rig the sidecars name (a variant on WATFLEX_RIGS)")
    parser.add_argument("--limit", type=float, default=None, help="stage 1's current clip, A (default the design's)")
    parser.add_argument("--patch", type=Path,
                        help="a diagnosis' patch.json (of other runs): its model predicts these too")
    args = parser.parse_args(argv)
    try:
        patch = json.loads(args.patch.read_text()) if args.patch else None
        models = {"nominal": ([], {})} | ({"diagnosed": (patch["effects"], patch["parameters"])} if patch else {})
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"error: {args.patch}: not a diagnosis patch.json ({exc})".replace("\n", " ")) from None

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from watflex_sim.recording import read_recording
    from watflex_sim.resim import resimulate

    fig, axes = plt.subplots(2, len(args.controller), figsize=(7 * len(args.controller), 6), squeeze=False,
                             sharex=True)
    for column, controller in enumerate(args.controller):
        samples, sidecar = stair(args.data, controller, args.limit)
        sidecar["rig"] = args.rig
        path = write(samples, sidecar, args.out / f"{controller}_stair")
        rec = read_recording(path)
        sims = {name: resimulate(rec, effects, parameters) for name, (effects, parameters) in models.items()}
        print(f"{controller}: {path} ({rec.time[-1]:.1f} s), re-simulated on {args.rig}: {', '.join(sims)} model")
        for channel in ("hub1", "link1"):
            print(f"  {channel}: rms {np.degrees(np.std(rec.channels[channel])):.3f} deg recorded; " + "; ".join(
                f"{name}: NRMSE {nrmse(rec.channels[channel], sim.channels[channel]):.4f}, rms "
                f"{np.degrees(np.std(sim.channels[channel])):.3f} deg" for name, sim in sims.items()))
        print(f"  step (deg)  hub 1 at its end (deg): recorded, {', '.join(sims)}   "
              f"link 1 rms from 0.5 s on (deg): recorded, {', '.join(sims)}")
        for i, deg in enumerate(STEPS_DEG):
            window = (rec.time >= i * SEGMENT_S + 0.5) & (rec.time < (i + 1) * SEGMENT_S)
            ends = [np.degrees(x.channels["hub1"][window][-1]) for x in (rec, *sims.values())]
            rms = [np.degrees(np.std(x.channels["link1"][window])) for x in (rec, *sims.values())]
            print(f"  {deg:9d}  " + " ".join(f"{v:9.3f}" for v in ends) + "     " + " ".join(f"{v:7.3f}" for v in rms))
        for row, channel in enumerate(("hub1", "link1")):
            ax = axes[row][column]
            if channel == "hub1":
                ax.plot(rec.time, np.degrees(rec.channels["hub1_reference"]), color="0.6", lw=0.8, label="reference")
            ax.plot(rec.time, np.degrees(rec.channels[channel]), lw=0.8, label="recorded")
            for name, sim in sims.items():
                ax.plot(sim.time, np.degrees(sim.channels[channel]), lw=0.8, label=f"{name} model ({args.rig})")
            ax.set_ylabel(f"{channel} (deg)")
            ax.set_title(f"lab's {controller}: {channel}")
            ax.legend(loc="upper right", fontsize=7)
        axes[1][column].set_xlabel("time (s)")
    fig.tight_layout()
    figure = args.out / "quanser_lab_runs.png"
    fig.savefig(figure, dpi=110)
    print(f"figure: {figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
