"""Re-write recordings as another lab's logger might have written them: to try the diagnosis off home ground.

    python tools/relog.py SRC_DIR OUT_DIR [--every 2] [--start-s 100] [--empty 0.02] [--drop tip_x,tip_y]
                          [--jitter-s 0] [--time-unit s] [--filtered-noise 0 --filter-hz 100]
                          [--glitches 0 --glitch-size 30] [--hold tip_x,tip_y] [--seed 0]

Every NAME.csv (with NAME.json) in SRC_DIR is written to OUT_DIR keeping one sample in `--every` (a 1 ms recording
logged at 2 ms), its time shifted to start at `--start-s` s, a share `--empty` of the measured cells left empty
(drop-outs; references never), the columns `--drop` left out (sensors the rig does not have), each time stamp off by
up to `--jitter-s` s (uniform; the values stay those of the sample: a logger that stamps when it writes), time in
`--time-unit` (s or ms; ms is declared in the sidecar as recordings.md asks), `--filtered-noise` x its declared noise
added to each measured channel the rig declares a noise for and whose values are not quantised (not the encoders', the
12-bit strain bridges': noise.QUANTUM_SHARE), through a first-order low-pass at `--filter-hz` (a sensor's anti-alias
filter or amplifier), `--glitches` single samples of each measured channel with a declared noise moved by
`--glitch-size` x that noise (either sign; a logger's glitches, after the sampling; a channel with fewer values, as
many fewer), the columns `--hold` written in every row as their last value (a slower sensor, the 25 Hz camera, held
by the logger between its samples), and a minimal sidecar:
format, rig, experiment, payload, controller, mode, notes and locked joints, none of what our simulator adds
(scenario, seed, control period). Same seed, same files. docs/diagnosis.md, "A case as another lab logs it", reports
what the diagnosis made of seed-97 cases so re-written.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from watflex_sim.diagnosis.noise import quantised
from watflex_sim.rigdesc import load_rig

TIME_UNITS = {"s": (1.0, 7), "ms": (1e3, 4)}  # unit -> (its count per s, decimals written: 0.1 us either way)
KEPT = ("format", "rig", "experiment", "payload_kg", "controller", "mode", "notes", "locked_joints")  # sidecar keys


def relog(src: Path, out: Path, every: int = 2, start_s: float = 100.0, empty: float = 0.02,
          drop: frozenset = frozenset(), seed: int = 0, jitter_s: float = 0.0, time_unit: str = "s",
          filtered_noise: float = 0.0, filter_hz: float = 100.0, glitches: int = 0, glitch_size: float = 30.0,
          hold: frozenset = frozenset()) -> list[Path]:
    """Write each recording of `src` to `out` as the module says; returns the CSV files written."""
    files = sorted(src.glob("*.csv"))
    if not files:
        raise ValueError(f"{src}: no recordings (*.csv)")
    columns = set()
    for path in files:
        with path.open(newline="") as f:
            columns.update(next(csv.reader(f), []))
    unknown = sorted((drop | hold) - columns)
    if unknown:  # before anything is written
        raise ValueError(f"{src}: no column {', '.join(unknown)} in its recordings "
                         f"(columns: {', '.join(sorted(columns))})")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    scale, decimals = TIME_UNITS[time_unit]
    written = []
    for path in files:
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
        header, rows = rows[0], rows[1:]
        if header[0] != "time":
            raise ValueError(f"{path}: the first column is {header[0]!r}, not time")
        meta = json.loads(path.with_suffix(".json").read_text())
        if filtered_noise:
            add_filtered_noise(header, rows, meta["rig"], filtered_noise, filter_hz, rng)
        rows = rows[::every]
        if glitches:
            add_glitches(header, rows, meta["rig"], glitches, glitch_size, rng)
        hold_last_values(header, rows, hold)
        keep = [i for i, name in enumerate(header) if name not in drop]
        with (out / path.name).open("w", newline="") as f:
            writer = csv.writer(f, lineterminator="\n")
            writer.writerow([header[i] for i in keep])
            for row in rows:
                stamp = start_s + float(row[0]) + (jitter_s * rng.uniform(-1, 1) if jitter_s else 0.0)  # s
                row = [f"{scale * stamp:.{decimals}f}"] + [
                    "" if not header[c].endswith("reference") and rng.random() < empty else row[c]
                    for c in range(1, len(row))]
                writer.writerow([row[i] for i in keep])
        meta = {k: meta[k] for k in KEPT if k in meta} | ({"time_unit": "ms"} if time_unit == "ms" else {})
        (out / path.name).with_suffix(".json").write_text(json.dumps(meta, indent=1))
        written.append(out / path.name)
    return written


def noisy_columns(header: list[str], rig: str):
    """(column index, declared noise rms in its unit) of each measured channel of `rig` in `header` declaring one."""
    description = load_rig(rig)
    for c, name in enumerate(header):
        spec = description.channels.get(name, {})
        if spec.get("kind") == "measured" and spec.get("noise"):
            yield c, float(spec["noise"])


def add_filtered_noise(header: list[str], rows: list[list[str]], rig: str, times: float, filter_hz: float,
                       rng: np.random.Generator) -> None:
    """Add to `rows` (CSV cells, in place) on each measured channel of `rig` with a declared noise and values that are
    not quantised (their grid's rms step under QUANTUM_SHARE x the noise added): `times` x that noise (rms, its unit)
    of white noise through a first-order low-pass at `filter_hz` (at the rows' own sample spacing dt: consecutive
    samples correlated by a = exp(-2 pi filter_hz dt))."""
    dt = float(np.median(np.diff([float(r[0]) for r in rows])))  # s
    a = float(np.exp(-2 * np.pi * filter_hz * dt))
    for c, declared in noisy_columns(header, rig):
        values = np.array([float(r[c]) if r[c] else np.nan for r in rows])
        if quantised(values, times * declared):  # an encoder's counts
            continue
        noise = times * declared * lfilter([np.sqrt(1 - a * a)], [1.0, -a], rng.standard_normal(len(rows)))
        for row, value, extra in zip(rows, values, noise):
            if np.isfinite(value):
                row[c] = repr(float(value + extra))


def add_glitches(header: list[str], rows: list[list[str]], rig: str, count: int, size: float,
                 rng: np.random.Generator) -> None:
    """Move `count` cells of each measured channel of `rig` with a declared noise (in place; distinct rows with a
    value, not the first or last ten) by `size` x that noise (its unit), each up or down at random; a channel with
    values in fewer rows (the 25 Hz camera) as many fewer (rounded): glitches at one rate a value written."""
    for c, declared in noisy_columns(header, rig):
        filled = [i for i in range(10, len(rows) - 10) if rows[i][c]]
        share = len(filled) / max(1, len(rows) - 20)  # of the rows a channel at the full rate has values in
        for i in rng.choice(filled, size=min(round(count * share), len(filled)), replace=False):
            rows[i][c] = repr(float(rows[i][c]) + size * declared * float(rng.choice((-1.0, 1.0))))


def hold_last_values(header: list[str], rows: list[list[str]], hold: frozenset) -> None:
    """Write each empty cell of the columns named in `hold` (in place) as the last value above it (none before the
    first): a logger holding a slower sensor's value between its samples."""
    for c in [i for i, name in enumerate(header) if name in hold]:
        last = ""
        for row in rows:
            last = row[c] = row[c] or last


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("src", type=Path, help="folder of NAME.csv + NAME.json recordings (a benchmark case)")
    parser.add_argument("out", type=Path, help="folder to write the re-logged recordings to (created)")
    parser.add_argument("--every", type=int, default=2, help="keep one sample in this many (default 2: 1 ms -> 2 ms)")
    parser.add_argument("--start-s", type=float, default=100.0, help="time of the first sample, s (default 100)")
    parser.add_argument("--empty", type=float, default=0.02, help="share of measured cells left empty (default 0.02)")
    parser.add_argument("--drop", default="", help="columns to leave out, comma-separated (e.g. tip_x,tip_y)")
    parser.add_argument("--jitter-s", type=float, default=0.0,
                        help="each time stamp off by up to this, s, uniform (default 0; the values are not moved)")
    parser.add_argument("--time-unit", choices=tuple(TIME_UNITS), default="s",
                        help="unit of the time column (default s)")
    parser.add_argument("--filtered-noise", type=float, default=0.0,
                        help="x each measured channel's declared noise added, low-passed (default 0: none)")
    parser.add_argument("--filter-hz", type=float, default=100.0,
                        help="corner of that noise's first-order low-pass, Hz (default 100)")
    parser.add_argument("--glitches", type=int, default=0,
                        help="single samples of each measured channel moved, per recording (default 0: none)")
    parser.add_argument("--glitch-size", type=float, default=30.0,
                        help="how far each is moved, x the channel's declared noise (default 30)")
    parser.add_argument("--hold", default="",
                        help="columns written in every row as their last value, comma-separated (e.g. tip_x,tip_y: "
                             "the 25 Hz camera held by a 1 kHz logger; default none)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the empty cells, the jitter, the noise and the glitches (default 0)")
    args = parser.parse_args(argv)
    if (args.every < 1 or not 0 <= args.empty < 1 or args.jitter_s < 0 or args.filtered_noise < 0 or args.filter_hz <= 0
            or args.glitches < 0):
        print("relog: --every must be >= 1, --empty in [0, 1), --jitter-s, --filtered-noise and --glitches >= 0, "
              "--filter-hz > 0", file=sys.stderr)
        return 2
    try:
        written = relog(args.src, args.out, args.every, args.start_s, args.empty,
                        frozenset(c for c in args.drop.split(",") if c), args.seed, args.jitter_s, args.time_unit,
                        args.filtered_noise, args.filter_hz, args.glitches, args.glitch_size,
                        frozenset(c for c in args.hold.split(",") if c))
    except (OSError, ValueError, KeyError) as exc:
        print(f"relog: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(written)} recordings to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
