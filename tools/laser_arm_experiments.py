"""The laser arm paper's step experiments (section 3, tables 9-12) on the nominal model.

    python tools/laser_arm_experiments.py             # markdown tables to stdout, figures in docs/ (about 5 s)
    python tools/laser_arm_experiments.py --no-figures

Runs the 2.5 mm tip step (scenarios laser_arm_step and laser_arm_fuzzy_step) with the PD on the
tip sensor at 0, 0.7, 1.15 and 1.6 kg in both directions, and the fuzzy PD of section 2.4,
each with measurement noise (seed 0) and without. Rise time is 10-90 %, settling time the
entry into +-2 % of the step for good, from the step at 0.1 s; overshoot in % of the step
(watflex_sim.metrics.step_metrics). The tip position is the one the sensor measures:
L theta_c - V / 3300 V/m (rigs.md §1). The paper does not define its rise and settling times.

Paper numbers are transcribed from ../shared/seeds/laser_arm_paper.txt, tables 9-12;
">0.9" is kept as the paper writes it. Clockwise = positive theta = the paper's RHS.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from watflex_sim import run_scenario  # noqa: E402
from watflex_sim.metrics import step_metrics  # noqa: E402
from watflex_sim.params import LASER_ARM  # noqa: E402

DOCS = ROOT / "docs"
PAYLOADS = (0.0, 0.7, 1.15, 1.6)  # kg, paper section 3
DIRECTIONS = {"positive": "clockwise", "negative": "anticlockwise"}
T_STEP = 0.1  # s, scenarios' step time

# Table 9: prototype, clockwise; table 10: prototype, anticlockwise (no 0 kg run).
# Values: (rise T_r s, settling T_s s, overshoot %), strings exactly as printed.
PAPER_PROTOTYPE = {
    ("clockwise", 0.0): ("0.03", "0.3", "38.5"),
    ("clockwise", 0.7): ("0.03", "0.29", "67.7"),
    ("clockwise", 1.15): ("0.045", "0.33", "94.7"),
    ("clockwise", 1.6): ("0.03", ">0.9", "84.9"),
    ("anticlockwise", 0.7): ("0.0623", "0.2751", "3.38"),
    ("anticlockwise", 1.15): ("0.0396", ">0.9", "25.4"),
    ("anticlockwise", 1.6): ("0.056", ">0.9", "20.35"),
}
PAPER_TABLE = {("clockwise", p): 9 for p in PAYLOADS} | {("anticlockwise", p): 10 for p in PAYLOADS}
# Table 11: the paper's ACSL simulation, one value for all payloads ("shown typically for 0.7 kg").
PAPER_SIMULATION = {
    "without stiction torque": ("0.0682", "0.23672", "12.7"),
    "with stiction torque, clockwise": ("0.0709", "0.5", "12.64"),
    "with stiction torque, anticlockwise": ("0.075", "0.375", "10.0"),
}
# Table 12: fuzzy control, RHS (clockwise); payload not stated; no overshoot given.
PAPER_FUZZY = {"prototype": ("0.032", "0.076", "-"), "simulation": ("0.055", "0.1", "-")}


def tip_step(scenario: str, payload: float, direction: str, noise: bool, seed: int = 0):
    """Run one step; returns (time s, tip position m along the arc, voltage_cmd V, metrics)."""
    rec = run_scenario(scenario, payload_kg=payload, direction=direction, noise=noise, seed=seed)
    ch, L = rec.channels, LASER_ARM.beam.length
    tip = L * ch["reference"] - ch["tip_sensor"] / LASER_ARM.sensor_gain
    m = step_metrics(rec.time, tip, t_step=T_STEP, initial=0.0, final=L * ch["reference"][-1])
    return rec.time, tip, ch["voltage_cmd"], m


def fmt(m: dict) -> tuple[str, str, str]:
    """(rise, settling, overshoot) as table cells; a settling time that never comes is '>0.9'."""
    settle = m["settling_time_s"]
    return (f"{m['rise_time_s']:.3f}", ">0.9" if not np.isfinite(settle) else f"{settle:.3f}",
            f"{m['overshoot_pct']:.1f}")


def run_all(seed: int) -> dict:
    """Every step: results[(controller, direction, payload, noise)] = (time, tip, voltage, metrics)."""
    out = {}
    for controller, scenario in (("pd", "laser_arm_step"), ("fuzzy", "laser_arm_fuzzy_step")):
        for direction in DIRECTIONS:
            for payload in PAYLOADS:
                for noise in (True, False):
                    out[controller, direction, payload, noise] = tip_step(scenario, payload, direction, noise, seed)
    return out


def pd_table(results: dict) -> str:
    rows = ["| direction | payload | ours: rise (s) | settling (s) | overshoot (%) "
            "| ours, noise off: rise / settling / overshoot | prototype: rise / settling / overshoot | paper table |",
            "|---|---:|---:|---:|---:|---|---|:-:|"]
    for direction, name in DIRECTIONS.items():
        for p in PAYLOADS:
            on, off = fmt(results["pd", direction, p, True][3]), fmt(results["pd", direction, p, False][3])
            paper = PAPER_PROTOTYPE.get((name, p))
            paper_cell = " / ".join(paper) if paper else "none (no 0 kg run in table 10)"
            rows.append(f"| {name} | {p:g} kg | {on[0]} | {on[1]} | {on[2]} | {' / '.join(off)} | {paper_cell} "
                        f"| {PAPER_TABLE[name, p]} |")
    rows.append("")
    rows.append("Paper's ACSL simulation (table 11, one value for every payload): "
                + "; ".join(f"{k} {' / '.join(v)}" for k, v in PAPER_SIMULATION.items()) + ".")
    return "\n".join(rows)


def fuzzy_table(results: dict) -> str:
    rows = ["| fuzzy PD, 2.5 mm step | rise (s) | settling (s) | overshoot (%) |", "|---|---:|---:|---:|"]
    for p in PAYLOADS:
        on, off = fmt(results["fuzzy", "positive", p, True][3]), fmt(results["fuzzy", "positive", p, False][3])
        rows.append(f"| ours, clockwise, {p:g} kg (noise off) "
                    f"| {on[0]} ({off[0]}) | {on[1]} ({off[1]}) | {on[2]} ({off[2]}) |")
    for p in (0.7,):
        on = fmt(results["fuzzy", "negative", p, True][3])
        rows.append(f"| ours, anticlockwise, {p:g} kg | {on[0]} | {on[1]} | {on[2]} |")
    for who, (r, s, o) in PAPER_FUZZY.items():
        rows.append(f"| paper table 12, {who} (RHS, payload not stated) | {r} | {s} | {o} |")
    return "\n".join(rows)


def figures(results: dict) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    DOCS.mkdir(exist_ok=True)
    paths = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=False)
    for ax, (direction, name) in zip(axes, DIRECTIONS.items()):
        for i, p in enumerate(PAYLOADS):
            t, tip, _, m = results["pd", direction, p, True]
            ax.plot(t, tip * 1e3, color=f"C{i}", lw=1.1, label=f"{p:g} kg (overshoot {m['overshoot_pct']:.1f} %)")
        sign = 1 if direction == "positive" else -1
        ax.axhline(sign * 2.5, color="k", ls=":", lw=0.8)
        ax.set_title(f"PD on the tip sensor, {name}")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("tip position along the arc [mm]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Laser arm 2.5 mm step, nominal model, Kp 0.127 V/V (noise on, seed 0)")
    fig.tight_layout()
    paths.append(DOCS / "laser_pd_steps.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, (ax, axu) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    for i, p in enumerate(PAYLOADS):
        t, tip, u, m = results["fuzzy", "positive", p, True]
        ax.plot(t, tip * 1e3, color=f"C{i}", lw=1.1, label=f"fuzzy PD, {p:g} kg")
    t, tip, u, _ = results["fuzzy", "positive", 0.7, True]
    tp, tipp, up, _ = results["pd", "positive", 0.7, True]
    ax.plot(tp, tipp * 1e3, "--", color="0.4", lw=1.0, label="PD (Kp 0.127), 0.7 kg")
    ax.axhline(2.5, color="k", ls=":", lw=0.8)
    ax.axvline(T_STEP + 0.1, color="C3", ls="-.", lw=0.8, label="paper table 12 sim. settling 0.1 s")
    ax.set_ylabel("tip position [mm]")
    ax.set_title("Laser arm fuzzy PD, 2.5 mm clockwise step (noise on, seed 0)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    axu.plot(t, u, color="C1", lw=1.0, label="fuzzy PD, 0.7 kg")
    axu.plot(tp, up, "--", color="0.4", lw=1.0, label="PD, 0.7 kg")
    axu.set_ylabel("voltage_cmd [V]")
    axu.set_xlabel("time [s]")
    axu.grid(alpha=0.3)
    axu.legend(fontsize=8)
    fig.tight_layout()
    paths.append(DOCS / "laser_fuzzy_step.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="Tables go to stdout (markdown); figures to docs/laser_pd_steps.png "
                                            "and docs/laser_fuzzy_step.png.")
    parser.add_argument("--seed", type=int, default=0, help="seed of the measurement noise (integer; default 0)")
    parser.add_argument("--no-figures", action="store_true", help="write no PNG figures")
    args = parser.parse_args(argv)
    results = run_all(args.seed)
    print(f"### PD on the tip sensor (Kp 0.127 V/V), 2.5 mm step: ours (noise on, seed {args.seed}) "
          "beside the prototype (paper tables 9, 10)\n")
    print(pd_table(results))
    print(f"\n### Fuzzy PD (controllers/fuzzy_pd.py), 2.5 mm step: ours (noise on, seed {args.seed}; "
          "noise off in brackets) beside paper table 12\n")
    print(fuzzy_table(results))
    if not args.no_figures:
        for path in figures(results):
            print(f"wrote {path.relative_to(ROOT)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
