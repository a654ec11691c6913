"""`watflex-sim`: run scenarios headless or in the viewer, plot and log recordings."""
from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .engine import SimulationError, simulate
from .interrupts import move, staged, writable
from .model import ConfigError
from .recording import Recording, RecordingError, read_recording, write_recording
from .scenario import MAX_DURATION_S, RANGES, available, load_scenario

EXIT_BAD_INPUT = 2
EXIT_DIVERGED = 3


class ProgressBar:
    """A one-line text progress bar with ETA on stderr (only when stderr is a terminal or forced)."""

    def __init__(self, label: str, enabled: bool):
        self.label, self.enabled, self.start = label, enabled, time.perf_counter()

    def __call__(self, fraction: float) -> None:
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start
        eta = elapsed * (1 - fraction) / fraction if fraction > 0 else float("nan")
        bar = "#" * int(30 * fraction)
        end = "\n" if fraction >= 1 else ""
        sys.stderr.write(f"\r{self.label} [{bar:<30}] {100 * fraction:5.1f} %  ETA {eta:5.1f} s{end}")
        sys.stderr.flush()


EPILOG = ("--set keys (physical ranges): " + ", ".join(
    f"{k} {'[' if inc else '('}{lo:g}, {hi:g}] {unit}" for k, (lo, hi, unit, inc) in RANGES.items())
    + ", seed (integer >= 0), n_segments (0 or 2-100), noise (true|false), direction (positive|negative), "
    "friction (nominal|none), controller.KEY (gains >= 0). "
    "Exit codes: 0 done, 2 bad input (one line, nothing written), 3 simulation diverged or unstable, 130 interrupted.")


def _add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help=f"scenario name ({', '.join(available())}) or path to a .toml file")
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scenario parameter, e.g. --set payload_kg=0.7 (kg) --set direction=negative "
        "--set controller.kp=0.2 --set seed=3 --set noise=false; repeatable",
    )
    p.add_argument("--rig", help=RIG_HELP + "; the scenario runs on it")


RIG_HELP = "a rig: a bundled name, a rig folder (rig.toml + model) or a .toml file anywhere (docs/rigs.md)"


def _scenario(args) -> dict:
    """The scenario with --set overrides, on the --rig rig if one is given (loaded first, by path or name)."""
    overrides = list(args.overrides)
    if args.rig:
        overrides.insert(0, f"rig={json.dumps(_loaded_rig(args.rig).name)}")
    return load_scenario(args.scenario, overrides)


def _loaded_rig(rig: str | None):
    """The --rig description (loaded by path or name, so its name resolves everywhere), or None."""
    if not rig:
        return None
    from .rigdesc import use_rig

    return use_rig(rig)


def _read(path: Path, rig) -> Recording:
    """A recording with its own NAME.json, or else with the --rig rig's default [sidecar]."""
    if path.with_suffix(".json").exists() or rig is None:
        return read_recording(path)
    if rig.sidecar is None:
        raise ConfigError(f"{path}: no {path.with_suffix('.json').name} and {rig.source} has no [sidecar] table")
    return read_recording(path, sidecar={"rig": rig.name, **rig.sidecar})


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="watflex-sim",
        description="MuJoCo simulator of the Watflex two-link and the laser-guided flexible arms. "
        "Recordings are NAME.csv (time in s, SI units) with a NAME.json sidecar.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"watflex-sim {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress of the library")
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="simulate a scenario headless; write NAME.csv/.json, a PNG plot and a .rrd")
    _add_scenario_args(run)
    run.add_argument("--out", required=True, type=Path, help="output directory (created if missing)")
    run.add_argument("--rrd", type=Path, help="rerun recording path (default OUT/NAME.rrd)")
    run.add_argument("--no-rrd", action="store_true", help="do not write a rerun recording")
    run.add_argument("--no-plot", action="store_true", help="do not write the PNG plot")
    run.add_argument("--spawn", action="store_true", help="also open the rerun viewer (needs a display)")
    run.add_argument("--patch", type=Path, help="a diagnosis' patch.json: simulate with its effects and refit parameters")

    view = sub.add_parser("view", help="run a scenario in MuJoCo's interactive viewer at real time (needs a display)",
                          description="Run a scenario at real time, seen from above, then hold its end until the "
                          "window is closed. Keys: space pause/resume, Backspace or R restart; Tab and Shift-Tab "
                          "show MuJoCo's panels.")
    _add_scenario_args(view)
    view.add_argument("--exit-after", type=float, metavar="S", help="close the window after S s of wall time (demos, tests)")

    plot = sub.add_parser("plot", help="plot a recording (.csv + .json, or .mat + .json) to PNG and/or rerun")
    plot.add_argument("recording", type=Path, help="NAME.csv (or .txt/.tsv/.dat text) or NAME.mat with NAME.json beside it")
    plot.add_argument("--png", type=Path, help="PNG path (default NAME.png beside the recording)")
    plot.add_argument("--rrd", type=Path, help="also write a rerun recording here")
    plot.add_argument("--spawn", action="store_true", help="open the rerun viewer (needs a display)")
    plot.add_argument("--rig", help=RIG_HELP + "; its default sidecar serves a file that comes without one")
    plot.add_argument("--simulate", action="store_true",
                      help="re-simulate the recording on the rig's nominal model, overlay it and print each "
                      "channel's NRMSE")
    plot.add_argument("--patch", type=Path, help="also (implies --simulate) a diagnosis' patch.json, e.g. one found on "
                      "other recordings: does its model predict this one?")

    diag = sub.add_parser(
        "diagnose", help="find where recordings and the model differ, name the missing physics, fit it",
        description="Diagnose recordings of one rig against its nominal model (recordings.md section 2): "
        "re-simulate, refit parameters within tolerance, locate the mismatch, fit catalogue effects, keep "
        "what improves held-out data. Writes DIR/report.json, fit_*.png, diagnosis.rrd, patched_model.xml, patch.json.")
    diag.add_argument("recordings", nargs="+", type=Path, help="NAME.csv (or .txt/.tsv/.dat: tab or space separated) or NAME.mat, each with NAME.json beside it (or the --rig's [sidecar])")
    diag.add_argument("--report", required=True, type=Path, help="output directory (created)")
    diag.add_argument("--rig", help=RIG_HELP + "; its default sidecar serves files that come without one, e.g. emps")
    diag.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes fitting candidates (default: all cores)")
    diag.add_argument("--max-effects", type=int, default=2, help="findings at most (default 2)")
    diag.add_argument("--no-rrd", action="store_true", help="do not write diagnosis.rrd")

    batch = sub.add_parser(
        "batch", help="run a sweep file: one scenario over varied parameters; DIR/results.parquet + .csv",
        description="Run every run of a sweep file (README 'Sweeps'; examples in sweeps/) on a local process "
        "pool or on Ray, one row per run in DIR/results.parquet and DIR/results.csv, DIR/summary.png. Re-running "
        "the same command resumes: finished runs (DIR/runs.jsonl) are skipped.")
    batch.add_argument("sweep", type=Path, help="sweep file (.toml): scenario, method, [fixed], [parameters]")
    batch.add_argument("--out", required=True, type=Path, help="output directory (created; the same one resumes)")
    batch.add_argument("--workers", type=int, help="processes of the local pool; with --ray local, CPUs (default: all cores)")
    batch.add_argument("--ray", metavar="ADDRESS", help="run as Ray tasks: 'auto' (the running cluster), 'local' "
                       "(start one here) or HOST:PORT; needs pip install 'watflex-sim[cluster]'")
    batch.add_argument("--keep-recordings", action="store_true", help="write each run's recording to DIR/recordings/RUN_ID.csv/.json")
    batch.add_argument("--no-plot", action="store_true", help="do not write DIR/summary.png")
    batch.add_argument("--rig", help=RIG_HELP + "; the sweep's scenario may name it")

    build = sub.add_parser("build-model", help="write the MJCF model a rig generates from its [datasheet] (docs/rigs.md)")
    build.add_argument("--rig", required=True, help=RIG_HELP + ', with model = "datasheet"')
    build.add_argument("--out", type=Path, help="the .xml file to write (default: NAME.xml beside the rig file)")

    listing = sub.add_parser("list", help="list the scenarios shipped in scenarios/ (--rigs: the rigs found)")
    listing.add_argument("--rigs", action="store_true", help="list the rigs instead: WATFLEX_RIGS's, then the bundled ones, with their files")
    return parser


def _log_rerun(rec: Recording, rrd: Path | None, spawn: bool, frames=None, frame_time=None) -> None:
    from .rerun_log import log_run

    log_run(rec.time, rec.channels, rec.units(), rrd_path=rrd, spawn=spawn, frames=frames,
            frame_time=frame_time, recording_name=rec.meta.get("experiment"))


def _need_display(what: str) -> None:
    """ConfigError before any work when `what` needs a display and there is none (Linux)."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError(f"{what} needs a display and there is no display (DISPLAY is not set); write a .rrd headless and open it "
                          "where there is one: rerun FILE.rrd")


def _read_patch(path: Path) -> tuple[list[dict], dict[str, float]]:
    """(effects, parameters) of a diagnosis' patch.json; ConfigError in one line for anything else."""
    try:
        patch = json.loads(path.read_text())
        return list(patch["effects"]), dict(patch["parameters"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: not a diagnosis patch.json ({exc})".replace("\n", " ")) from None


def cmd_run(args) -> int:
    scenario = _scenario(args)
    if args.patch:
        effects, parameters = _read_patch(args.patch)
        scenario["effects"] = list(scenario["effects"]) + effects
        scenario["parameters"] = {**scenario["parameters"], **parameters}
    name = scenario["name"]
    rrd = None if args.no_rrd else (args.rrd or args.out / f"{name}.rrd")
    if args.spawn:
        _need_display("--spawn (the rerun viewer)")
    writable(args.out)  # before simulating: a bad directory costs nothing
    if rrd is not None and args.rrd:
        writable(rrd.parent, "rrd directory")
    bar = ProgressBar(name, sys.stderr.isatty() or bool(os.environ.get("WATFLEX_PROGRESS")))
    result = simulate(scenario, progress=bar)
    rec = result.recording
    with staged(args.out) as stage:  # every output appears at the end, or none
        write_recording(rec, stage, name)
        if not args.no_plot:
            from .plot import plot_recording

            plot_recording(rec, stage / f"{name}.png")
        staged_rrd = None if rrd is None else stage / f".{name}.rrd.part" if args.rrd else stage / f"{name}.rrd"
        if staged_rrd or args.spawn:
            _log_rerun(rec, staged_rrd, args.spawn, result.frames, result.frame_time)
        if args.rrd and staged_rrd:
            move(staged_rrd, rrd)
    csv_path = args.out / f"{name}.csv"
    print(f"wrote {csv_path} and {csv_path.with_suffix('.json').name} "
          f"({rec.time.size} samples, {len(rec.channels)} channels, {result.wall_time_s:.2f} s wall, "
          f"{rec.time[-1] / result.wall_time_s:.1f}x real time)")
    if not args.no_plot:
        print(f"wrote {args.out / f'{name}.png'}")
    if rrd:
        print(f"wrote {rrd}  (open with: rerun {rrd})")
    return 0


def cmd_view(args) -> int:
    scenario = _scenario(args)
    _need_display("the viewer")
    from .viewer import check_display, view

    check_display()
    if args.exit_after is not None and not (math.isfinite(args.exit_after) and args.exit_after > 0):
        raise ConfigError(f"--exit-after must be a number of seconds > 0, got {args.exit_after}")
    view(scenario, exit_after_s=args.exit_after)
    return 0


def cmd_plot(args) -> int:
    from .plot import plot_recording

    png = args.png or args.recording.with_suffix(".png")
    if args.spawn:
        _need_display("--spawn (the rerun viewer)")
    writable(png.parent, "PNG directory")
    if args.rrd:
        writable(args.rrd.parent, "rrd directory")
    rec = _read(args.recording, _loaded_rig(args.rig))
    models = {"nominal": ([], {})} if args.simulate or args.patch else {}
    if args.patch:
        models["patched"] = _read_patch(args.patch)
    from .metrics import nrmse
    from .resim import resimulate
    from .rigdesc import load_rig

    others, kinds = {}, load_rig(rec.rig).channels
    for label, (effects, parameters) in models.items():
        others[label] = sim = resimulate(rec, effects, parameters)
        scores = {c: nrmse(x, sim.channels[c]) for c, x in rec.channels.items()
                  if kinds.get(c, {}).get("kind") in ("measured", "command") and c in sim.channels}
        print(f"{label} model: NRMSE " + ", ".join(f"{c} {v:.4f}" for c, v in scores.items() if math.isfinite(v))
              + f"; mean {np.nanmean(list(scores.values())):.4f}")
    with staged(png.parent) as stage:
        plot_recording(rec, stage / png.name, others=others)
    print(f"wrote {png}")
    if args.rrd or args.spawn:
        _log_rerun(rec, args.rrd, args.spawn)
        if args.rrd:
            print(f"wrote {args.rrd}")
    return 0


def cmd_diagnose(args) -> int:
    from .diagnosis import diagnose
    from .diagnosis.data import MIN_SPAN_S
    from .report import summary, write_report

    rig = _loaded_rig(args.rig)
    writable(args.report, "report directory")  # before hours of fitting
    recordings = []
    for path in args.recordings:
        rec = _read(path, rig)
        span = float(rec.time[-1] - rec.time[0])
        if span < MIN_SPAN_S:  # checked here too, to name the file before the others are read
            raise ConfigError(f"{path}: recording shorter than {MIN_SPAN_S * 1e3:g} ms ({span * 1e3:.3g} ms), too short to simulate")
        step = float(np.median(np.diff(rec.time)))
        if step >= 0.1 or span > MAX_DURATION_S:
            raise ConfigError(f"{path}: time looks like milliseconds or is too long (median step {step:g} s, span "
                              f"{span:g} s; at most {MAX_DURATION_S:g} s): time is in seconds (recordings.md); "
                              "convert it, or declare \"time_unit\": \"ms\" in the sidecar")
        recordings.append(rec)
    start = time.perf_counter()
    bar = ProgressBar("", sys.stderr.isatty() or bool(os.environ.get("WATFLEX_PROGRESS")))

    def say(message: str) -> None:  # one line per stage; the bar below counts its simulations
        if bar.enabled:
            sys.stderr.write("\r\033[K")
        print(f"[{time.perf_counter() - start:6.1f} s] {message}", file=sys.stderr, flush=True)
        bar.label, bar.start = "  simulations", time.perf_counter()

    def jobs_done(done: int, total: int) -> None:
        bar.label = f"  simulations {done}/{total}"
        bar(done / total if done < total else 0.999)

    report = diagnose(recordings, [p.name for p in args.recordings], workers=max(1, args.workers),
                      max_effects=args.max_effects, progress=say, jobs_done=jobs_done)
    if bar.enabled:
        sys.stderr.write("\r\033[K")
    path = write_report(report, recordings, args.report, rrd=not args.no_rrd)
    print(summary(report))
    print(f"wrote {path} ({time.perf_counter() - start:.1f} s)")
    return 0


def cmd_batch(args) -> int:
    from .batch import load_sweep, run_sweep

    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    _loaded_rig(args.rig)
    sweep = load_sweep(args.sweep)
    writable(args.out)
    bar = ProgressBar("batch", sys.stderr.isatty() or bool(os.environ.get("WATFLEX_PROGRESS")))

    def progress(done: int, total: int) -> None:
        bar.label = f"batch {done}/{total}"
        bar(done / total)

    try:
        result = run_sweep(sweep, args.out, workers=args.workers, ray_address=args.ray,
                           keep_recordings=args.keep_recordings, progress=progress, plots=not args.no_plot)
    except KeyboardInterrupt:
        print(f"{chr(10) if bar.enabled else ''}watflex-sim: interrupted; finished runs kept in {args.out / 'results.parquet'} (and .csv); "
              "run the same command again to resume", file=sys.stderr)
        return 130
    print(f"{result.ran} runs done ({result.failed} failed), {result.skipped} already done; wrote {result.results} "
          f"and results.csv ({len(result.rows)} rows) in {result.wall_s:.1f} s")
    return 0


def cmd_build_model(args) -> int:
    """The model is generated at load; this writes it to a file to read or to open in MuJoCo's viewer."""
    from .datasheet import model_xml
    from .rigdesc import DATASHEET

    rig = _loaded_rig(args.rig)
    if rig.model != DATASHEET:
        raise ConfigError(f'{rig.source}: model = {rig.model!r}, not "datasheet": nothing to generate')
    out = args.out or rig.model_path
    text = f"<!-- Generated by watflex-sim build-model from {Path(rig.source).name} [datasheet]. Do not edit. -->\n"
    out.write_text(text + model_xml(rig.datasheet, rig.name))
    print(f"wrote {out}")
    return 0


def cmd_list(args) -> int:
    if args.rigs:
        from .rigdesc import known_rigs, rig_file

        for name in known_rigs():
            print(f"{name}  {rig_file(name)}")
        return 0
    for name in available():
        print(name)
    return 0


COMMANDS = {"run": cmd_run, "view": cmd_view, "plot": cmd_plot, "list": cmd_list, "diagnose": cmd_diagnose}

COMMANDS["batch"] = cmd_batch
COMMANDS["build-model"] = cmd_build_model


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(name)s: %(message)s")
    try:
        return COMMANDS[args.command](args)
    except (ConfigError, RecordingError) as exc:
        print(f"watflex-sim: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SimulationError as exc:
        print(f"watflex-sim: error: {exc}", file=sys.stderr)
        return EXIT_DIVERGED
    except KeyboardInterrupt:
        print("watflex-sim: interrupted; nothing was written for the unfinished run", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
