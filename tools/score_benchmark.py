"""Score the diagnosis on a benchmark made by tools/make_benchmark.py, beside two baselines.

    python tools/score_benchmark.py BENCH_DIR [--cases PATTERN] [--no-baselines] [--workers 2] [--resume]

For every case it runs `watflex_sim.diagnosis.diagnose` on the case's recordings only (the truth
in BENCH_DIR/truth.json is read afterwards, to score), then baseline (a) refit-only and
(b) SINDy on the residual (tools/baselines.py). It prints and writes BENCH_DIR/score.md:

- per case: truth, what each method names first, parameter error, held-out NRMSE, time;
- a confusion table (true effect -> effect named first, ours);
- the summary: top-1 effect accuracy (effect and out-of-tolerance cases), location accuracy,
  "nothing missing" specificity (clean cases, with or without an uninformative last file),
  `unexplained` recall (physics outside the catalogue), median parameter error, 95 % interval
  coverage (share of true parameter values inside the finding's interval), the verdicts, how often
  an experiment was proposed and, where one was, whether running it on the case's truth and
  diagnosing again named the true effect with no alternative left, median validation NRMSE ratio
  after/before, time per case (also scaled to the reference machine by this machine's bare `mj_step`,
  measured first); for cases with two effects (make_benchmark --pairs, kept out of the
  top-1 figure): whether the first finding is one of them and whether both, and nothing else, are found.

Parameter error of a finding that names the right effect: for each true parameter,
|found - true| / |true - neutral| (neutral: the value at which the effect vanishes, effects.py;
for a parameter whose true value is neutral, e.g. the zero side of a one-direction friction,
relative to the largest true deviation of the effect); the case's error is the mean over them (over both
true effects, each matched by name among the findings, in a two-effect case). The truth is compared in the form
the report gives (effects.canonical: a position-dependent friction with a negative amplitude as the same torque
with a positive one, its phase moved by pi).
Results are also written to BENCH_DIR/score.json, each case's whole report to BENCH_DIR/reports/ID.json.
"""
from __future__ import annotations

import argparse
import fnmatch
import json
import statistics
import sys
import time
import zlib
from collections import Counter, defaultdict
from pathlib import Path

REFERENCE_STEP_US = 3.0  # µs: bare mj_step of the laser arm at rest on the machine the times in docs/diagnosis.md and
# docs/speed.md were measured on until 2026-11-26 (docs/speed.md: 2.99-3.07 µs); times per case are also given scaled to it

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the repository: watflex_sim
sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools: make_benchmark's recorder, imported by rig_records

from watflex_sim import SimulationError  # noqa: E402
from watflex_sim.diagnosis import diagnose  # noqa: E402
from watflex_sim.effects import CATALOGUE, canonical  # noqa: E402
from watflex_sim.model import ConfigError  # noqa: E402
from watflex_sim.recording import read_recording  # noqa: E402
from watflex_sim.diagnosis.explain import commands_recorded  # noqa: E402
from watflex_sim.rigdesc import load_rig  # noqa: E402

NONE = "none"


def parameter_error(effect: str, truth: dict, found: dict) -> float | None:
    """Mean relative error of the found parameters against the true ones (see module doc)."""
    neutral = {p.name: (p.neutral or 0.0) for p in CATALOGUE[effect][1]}
    deviations = {k: abs(v - neutral.get(k, 0.0)) for k, v in truth.items() if k in found}
    if not deviations:
        return None
    largest = max(deviations.values()) or 1.0
    return statistics.mean(abs(found[k] - truth[k]) / (deviations[k] or largest) for k in deviations)


def true_place(case: dict, recordings: list) -> str | None:
    """The truth's place as the report names it: a delay on "command" is on the command channels the
    recordings carry (explain.physical_place), e.g. the laser's voltage_cmd."""
    where = case.get("where")
    if case.get("effect") == "delay" and where == "command":
        return commands_recorded(load_rig(case["rig"]), recordings) or where
    return where


def truths(case: dict) -> list[dict]:
    """A case's true effects, each {"effect", "where", "parameters", ...}: one, or two for a pair case (`others`)."""
    return [case, *case.get("others", [])]


def score_case(root: Path, case: dict, workers: int, baselines: bool, recorder: dict | None = None) -> dict:
    """Diagnose one case (and the baselines); compare with its truth."""
    paths = [root / p for p in case["recordings"]]
    recordings = [read_recording(p) for p in paths]
    names = [p.name for p in paths]
    start = time.perf_counter()
    report = diagnose(recordings, names, workers=workers)
    seconds = time.perf_counter() - start
    (root / "reports").mkdir(exist_ok=True)  # what the diagnosis said, whole, for a look at a miss afterwards
    (root / "reports" / f"{case['id']}.json").write_text(
        json.dumps({k: v for k, v in report.items() if k != "sims"}, indent=1, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v)) + "\n")
    first = report["findings"][0] if report["findings"] else None
    kind = case.get("kind", "clean" if case["effect"] is None else "effect")
    truth_effect = case["effect"] or NONE
    if kind == "outside_catalogue":
        truth_effect = "unexplained"
    row = {
        "id": case["id"], "rig": case["rig"], "kind": kind, "truth": truth_effect, "where": true_place(case, recordings),
        "concealment": case.get("concealment", ""), "verdict": report.get("verdict"),
        "proposed": bool(report.get("proposed_experiment")), "covered": [],
        "ours": first["effect"] if first else NONE, "ours_where": first["where"] if first else None,
        "ours_all": [f["effect"] for f in report["findings"]],
        "held_before": report["held_out"]["before"]["nrmse"], "held_after": report["held_out"]["after"]["nrmse"],
        "seconds": seconds, "error": None,
    }
    if kind == "outside_catalogue":
        row["ours"] = "unexplained" if report.get("verdict") == "unexplained" else row["ours"]
    row["truth_all"] = [(t["effect"], t["where"]) for t in truths(case)] if kind == "pair" else None
    errors = []
    scored_truths = truths(case) if first and truth_effect in CATALOGUE else []
    for truth in scored_truths:  # a true effect anywhere among the findings counts for the error
        match = next((f for f in report["findings"] if f["effect"] == truth["effect"]), None)
        if match:  # the truth in the form the report gives (effects.canonical: one form for the same physics)
            true = {k: v for k, v in canonical({"effect": truth["effect"], **truth["parameters"]}).items() if k != "effect"}
            errors.append(parameter_error(truth["effect"], true, match["parameters"]))
            row.setdefault("found", {"true": true, "found": match["parameters"], "intervals": match.get("intervals", {})})
            row["covered"] += [lo <= true[k] <= hi for k, (lo, hi) in match.get("intervals", {}).items() if k in true]
    errors = [e for e in errors if e is not None]
    row["error"] = statistics.mean(errors) if errors else None
    proposal = report.get("proposed_experiment") or {}
    if proposal.get("scenario_dict") and kind in ("effect", "out_of_tolerance", "pair"):  # catalogue truths, simulated
        row["resolved"] = resolves(case, recordings, names, proposal["scenario_dict"], workers, recorder)
    if baselines:
        from baselines import refit_only, sindy_residual

        refit = refit_only(recordings, names)
        row["refit_held_after"] = refit["held_out"]["after"]
        try:
            sindy = sindy_residual(recordings, names, parameters=refit["refit_parameters"])
            row["sindy"] = sindy["effect"] or NONE
            row["sindy_held_after"] = sindy["held_out"]["after"]
        except ImportError as exc:
            row["sindy"], row["sindy_held_after"] = f"unavailable ({exc})", float("nan")
    return row


def resolves(case: dict, recordings: list, names: list[str], scenario: dict, workers: int,
             recorder: dict | None = None) -> bool:
    """Run the proposed experiment on the "rig" (rig_records), diagnose again with it added, and say whether
    the ambiguity is gone: a true effect named first, every true effect found (a pair case has two) and no
    alternative left."""
    try:
        extra = rig_records(case, scenario, recorder)
    except SimulationError:
        return False
    again = diagnose(recordings + [extra], names + ["discriminate.csv"], workers=workers, propose=False)
    found, true = [f["effect"] for f in again["findings"]], {t["effect"] for t in truths(case)}
    return bool(found) and found[0] in true and true <= set(found) and not again["alternatives"]


def rig_records(case: dict, scenario: dict, recorder: dict | None = None):
    """The Recording of `scenario` on the case's "rig": its truth (effects, parameter errors, dropped channels),
    recorded as make_benchmark recorded the case: noise on, a seed of its own (from the case's id), and
    truth.json's `recorder`. (Run noise-free on our own discretisation, as until 2026-12-01, the new recording was
    the one file the refit rig could not match to its noise: seed 71's laser_arm-31e8e2c7 came out `unexplained`,
    the truth 11.7x the noise.)"""
    from make_benchmark import recorder_of, simulate_case

    drop = ("elbow_angle",) if case.get("concealment") == "indirect channel" else ()
    effects = [dict(effect=t["effect"], where=t["where"], **t["parameters"]) for t in truths(case)]
    recorded = dict(scenario, noise=True, seed=zlib.crc32(f"{case['id']}/discriminate".encode()),
                    **recorder_of(case["rig"], **(recorder or {})))
    (_, extra), = simulate_case([("discriminate", recorded)], effects, case["refit_parameters"], drop)
    return extra


def _pct(hits: int, total: int) -> str:
    return f"{100 * hits / total:.0f} % ({hits}/{total})" if total else "-"


def machine_step_us() -> float:
    """This machine's speed: bare `mj_step` of the laser arm at rest, µs per step (best of 3 x 20,000 steps)."""
    from bench import initial_state, load, time_bare

    model, start, _ = initial_state(load("laser_arm_step", None))
    return min(time_bare(model, start, 20_000, 1_000)[0] for _ in range(3)) / 20_000 * 1e6


def _scaled(rows: list[dict], times: list[float]) -> str:
    """Median / max time per case scaled to REFERENCE_STEP_US, with this machine's step; '-' if not measured."""
    steps = [r["machine_step_us"] for r in rows if r.get("machine_step_us")]
    if not times or not steps:
        return "-"
    ratio = REFERENCE_STEP_US / statistics.median(steps)
    return (f"{statistics.median(times) * ratio:.0f} / {max(times) * ratio:.0f} (bare step {statistics.median(steps):.2f} µs here, "
            f"{REFERENCE_STEP_US} µs there)")


def summary(rows: list[dict], baselines: bool) -> str:
    """The markdown tables: per case, confusion, and the summary figures."""
    lines = ["| case | concealment | truth | ours | " + ("refit-only | SINDy | " if baselines else "")
             + "param. error | held-out NRMSE before -> ours" + (" / refit / SINDy" if baselines else "") + " | time (s) |",
             "|---|---|---|---|" + ("---|---|" if baselines else "") + "---|---|---|"]
    for r in rows:
        err = "-" if r["error"] is None else f"{100 * r['error']:.0f} %"
        ours = r["ours"] + (f" @ {r['ours_where']}" if r["ours_where"] else "")
        base = f"none | {r['sindy']} | " if baselines else ""
        held = f"{r['held_before']:.3f} -> {r['held_after']:.3f}"
        if baselines:
            held += f" / {r['refit_held_after']:.3f} / {r['sindy_held_after']:.3f}"
        truth = (" + ".join(f"{e} @ {w}" for e, w in r["truth_all"]) if r.get("truth_all")
                 else r["truth"] + (f" @ {r['where']}" if r["where"] else ""))
        lines.append(f"| {r['id']} | {r['concealment']} | {truth} | {ours} | {base}{err} | {held} | {r['seconds']:.0f} |")
    confusion = defaultdict(Counter)
    for r in rows:
        confusion[r["truth"]][r["ours"]] += 1
    lines += ["", "| true effect | named first by the diagnosis (count) |", "|---|---|"]
    for truth in sorted(confusion):
        lines.append(f"| {truth} | " + ", ".join(f"{k} {v}" for k, v in confusion[truth].most_common()) + " |")
    pairs = [r for r in rows if r.get("kind") == "pair"]
    effect_rows = [r for r in rows if r["truth"] in CATALOGUE and r.get("kind") != "pair"]
    clean = [r for r in rows if r["truth"] == NONE]
    outside = [r for r in rows if r["truth"] == "unexplained"]
    errors = [r["error"] for r in effect_rows + pairs if r["error"] is not None]
    covered = [c for r in rows for c in r.get("covered", [])]
    verdicts = Counter(f"{r.get('kind', '?')}: {r.get('verdict')}" for r in rows)
    ratios = [r["held_after"] / r["held_before"] for r in rows if r["held_before"] > 0]
    times = [r["seconds"] for r in rows]
    figures = [
        ("top-1 effect accuracy (target >= 90 %)", _pct(sum(r["ours"] == r["truth"] for r in effect_rows), len(effect_rows))),
        ("location accuracy (first finding at the true place)", _pct(sum(r["ours_where"] == r["where"] for r in effect_rows), len(effect_rows))),
        ('"nothing missing" specificity on clean cases (target >= 90 %)',
         _pct(sum(r["ours"] == NONE and r.get("verdict", "nothing_missing") == "nothing_missing" for r in clean), len(clean))),
        ("`unexplained` recall, physics outside the catalogue (target >= 80 %)", _pct(sum(r["ours"] == "unexplained" for r in outside), len(outside))),
        ("two effects at once: the first finding is one of them", _pct(sum(r["ours"] in {e for e, _ in r["truth_all"]}
                                                                            for r in pairs), len(pairs))),
        ("two effects at once: both found, and nothing else", _pct(sum(sorted(r["ours_all"]) == sorted(e for e, _ in r["truth_all"])
                                                                   for r in pairs), len(pairs))),
        ("95 % intervals covering the true value (target >= 80 %)", _pct(sum(covered), len(covered))),
        ("verdicts by kind of case", ", ".join(f"{k} {v}" for k, v in sorted(verdicts.items()))),
        ("experiment proposed (alternatives within noise)", _pct(sum(r.get("proposed", False) for r in rows), len(rows))),
        ("proposed experiment run on the truth resolved the ambiguity (true effect first, no alternative left)",
         _pct(sum(r["resolved"] for r in rows if "resolved" in r), sum("resolved" in r for r in rows))),
        ("median parameter error, right effect (target <= 15 %)", f"{100 * statistics.median(errors):.1f} % (n={len(errors)})" if errors else "-"),
        ("median held-out NRMSE after / before", f"{statistics.median(ratios):.3f}" if ratios else "-"),
        ("time per case: median / max (s)", f"{statistics.median(times):.0f} / {max(times):.0f}" if times else "-"),
        ("time per case scaled to the reference machine by bare `mj_step` speed: median / max (s)", _scaled(rows, times)),
    ]
    if baselines:
        figures += [
            ("SINDy baseline: top-1 effect accuracy", _pct(sum(r["sindy"] == r["truth"] for r in effect_rows), len(effect_rows))),
            ('SINDy baseline: "none" specificity', _pct(sum(r["sindy"] == NONE for r in clean), len(clean))),
            ("refit-only baseline: top-1 effect accuracy", _pct(0, len(effect_rows)) + " (it cannot name physics)"),
            ("median held-out NRMSE after / before: refit-only, SINDy",
             f"{statistics.median(r['refit_held_after'] / r['held_before'] for r in rows):.3f}, "
             f"{statistics.median(r['sindy_held_after'] / r['held_before'] for r in rows):.3f}"),
        ]
    lines += ["", "| figure | value |", "|---|---|"] + [f"| {k} | {v} |" for k, v in figures]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("bench", type=Path, help="directory written by tools/make_benchmark.py (holds truth.json)")
    parser.add_argument("--cases", default="*", help="only case ids matching this glob, e.g. 'laser_arm-*'")
    parser.add_argument("--no-baselines", action="store_true", help="skip refit-only and SINDy")
    parser.add_argument("--workers", type=int, default=2, help="processes per diagnosis (default 2)")
    parser.add_argument("--resume", action="store_true",
                        help="keep the cases already scored in BENCH_DIR/score.json (a run stopped early) and score the rest")
    parser.add_argument("--summarise", action="store_true",
                        help="only print the tables of the cases already scored (BENCH_DIR/score.json, e.g. of a run stopped early)")
    args = parser.parse_args(argv)
    rows = []  # the cases already scored: what --summarise prints, what --resume keeps
    if args.summarise or (args.resume and (args.bench / "score.json").exists()):
        try:
            rows = json.loads((args.bench / "score.json").read_text())
        except (OSError, ValueError) as exc:
            print(f"error: cannot read {args.bench / 'score.json'}: {exc}", file=sys.stderr)
            return 2
    if args.summarise:
        print(summary(rows, all("sindy" in r for r in rows) and bool(rows)))
        return 0
    truth_path = args.bench / "truth.json"
    try:
        truth = json.loads(truth_path.read_text())
        cases = [c for c in truth["cases"] if fnmatch.fnmatch(c["id"], args.cases)]
    except (OSError, ValueError, KeyError) as exc:
        print(f"error: cannot read {truth_path}: {exc}", file=sys.stderr)
        return 2
    if not cases:
        print(f"error: no case matches {args.cases!r} in {truth_path}", file=sys.stderr)
        return 2
    cases.sort(key=lambda c: c["id"].rsplit("-", 1)[-1])  # by the opaque hash: rigs and kinds interleaved,
    # so a run stopped early has scored a fair sample (score.json is rewritten after every case)
    if rows:
        done = {r["id"] for r in rows}
        cases = [c for c in cases if c["id"] not in done]
        print(f"resuming: {len(done)} cases already scored, {len(cases)} to go", file=sys.stderr, flush=True)
    step_us = machine_step_us()
    start = time.perf_counter()
    for i, case in enumerate(cases, 1):
        try:
            row = score_case(args.bench, case, args.workers, not args.no_baselines, truth.get("recorder"))
        except ConfigError as exc:
            print(f"error: case {case['id']}: {exc}", file=sys.stderr)
            return 2
        rows.append({**row, "machine_step_us": step_us})
        (args.bench / "score.json").write_text(json.dumps(rows, indent=1, default=float) + "\n")
        elapsed = time.perf_counter() - start
        print(f"[{i}/{len(cases)}] {case['id']}: truth {row['truth']}, ours {row['ours']} ({row['verdict']})"
              + (f", SINDy {row['sindy']}" if "sindy" in row else "")
              + f" ({row['seconds']:.0f} s; ETA {elapsed / i * (len(cases) - i) / 60:.1f} min)", file=sys.stderr, flush=True)
    table = summary(rows, not args.no_baselines)
    print(table)
    (args.bench / "score.md").write_text(table + "\n")
    (args.bench / "score.json").write_text(json.dumps(rows, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
