"""Recordings: samples in ``NAME.csv`` (or MATLAB ``NAME.mat``) plus a ``NAME.json`` sidecar.

The contract is ``recordings.md`` section 1. Every bad input raises :class:`RecordingError`
with a one-line message ``<file>: <cause>``; writing is atomic.
"""
from __future__ import annotations

import copy
import csv
import io
import json
import logging
import math
import os
import re
import struct
import uuid
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .params import RIGS
from .rigdesc import channel_units

FORMAT = "flexarm-recording/1"

# rig -> {channel: SI unit}: recordings.md section 1's vocabulary, from the rig descriptions (rigs/*.toml).
CHANNELS: dict[str, dict[str, str]] = channel_units()

TEXT_SUFFIXES = (".csv", ".txt", ".tsv", ".dat")  # comma, tab or space separated (the header line says which)
COMMENTS = ("#", "%")  # lines starting so, before the header or among the samples, are skipped
IGNORED = "\0"  # prefix of a column the rig's [columns] maps to "": read, then dropped

# A CSV cell: a decimal number, or nan/inf (nan is read as a missing sample like an empty cell).
_NUMBER = re.compile(r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)", re.I)

class RecordingError(ValueError):
    """Bad recording or sidecar. ``str(err)`` is one line: ``<file>: <cause>``."""

    def __init__(self, source, cause: str):
        super().__init__(" ".join(f"{source}: {cause}".splitlines()))


def _show(value, limit: int = 40) -> str:
    """Short repr of an offending value for an error message."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass
class Recording:
    """One experiment: ``time`` in s (1-D, strictly increasing), ``channels`` mapping a
    channel name to a 1-D float array in the unit of :data:`CHANNELS` (NaN = missing
    sample), ``meta`` the sidecar dict."""

    time: np.ndarray
    channels: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)

    @property
    def rig(self) -> str:
        """``meta["rig"]``; raises RecordingError if absent or unknown."""
        return _check_meta(self.meta, "recording", need_format=False)

    def units(self) -> dict[str, str]:
        """Channel name -> SI unit; raises RecordingError for an unknown rig or channel."""
        _check_names(self.channels, self.rig, "recording")
        return {name: CHANNELS[self.rig][name] for name in self.channels}


def _check_meta(meta, source, need_format: bool) -> str:
    """Check the sidecar's format tag and rig; return the rig."""
    if not isinstance(meta, dict):
        raise RecordingError(source, "sidecar is not a JSON object")
    if "format" not in meta:
        if need_format:
            raise RecordingError(source, f"sidecar has no 'format' (expected {FORMAT!r})")
    elif meta["format"] != FORMAT:
        raise RecordingError(source, f"sidecar format {_show(meta['format'])} is not {FORMAT!r}")
    if "rig" not in meta:
        raise RecordingError(source, "sidecar has no 'rig'")
    rig = meta["rig"]
    if not isinstance(rig, str) or rig not in CHANNELS:
        raise RecordingError(source, f"unknown rig {_show(rig)} (known: {', '.join(CHANNELS)})")
    return rig


def _check_names(names, rig: str, source) -> None:
    """Raise naming the channels (and only those) that are not in the rig's vocabulary."""
    unknown = [n for n in names if not isinstance(n, str) or n not in CHANNELS[rig]]
    if unknown:
        shown = ", ".join(_show(n) for n in unknown[:10])
        more = f" (+{len(unknown) - 10} more)" if len(unknown) > 10 else ""
        plural = "s" if len(unknown) > 1 else ""
        raise RecordingError(source, f"unknown channel{plural} for rig {rig!r}: {shown}{more}")


def _as_vector(value, what: str, source, squeeze: bool = False) -> np.ndarray:
    """``value`` as a 1-D float64 array; ``squeeze`` accepts MATLAB row/column vectors."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise RecordingError(source, f"{what} is not real numeric data (dtype {arr.dtype})")
    if squeeze and arr.ndim > 1 and arr.size == max(arr.shape):
        arr = arr.reshape(-1)
    if arr.ndim != 1:
        raise RecordingError(source, f"{what} is not a vector (shape {arr.shape})")
    return arr.astype(np.float64)


def _check_samples(time, channels, source, where) -> None:
    """Check time and channel arrays; ``where(i)`` names sample i ('line 5', 'sample 4')."""
    n = len(time)
    if n < 2:
        raise RecordingError(source, f"fewer than 2 samples ({n})")
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise RecordingError(source, f"time is not finite at {where(bad[0])}")
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        i = back[0] + 1
        raise RecordingError(source, f"time is not strictly increasing at {where(i)} "
                                     f"({time[i]:.10g} s after {time[i - 1]:.10g} s)")
    if not channels:
        raise RecordingError(source, "no channels besides time")
    for name, x in channels.items():
        if len(x) != n:
            raise RecordingError(source, f"channel {name!r} has {len(x)} samples, time has {n}")
        inf = np.flatnonzero(np.isinf(x))
        if inf.size:
            raise RecordingError(source, f"channel {name!r} is infinite at {where(inf[0])}")
        if np.isnan(x).all():
            raise RecordingError(source, f"channel {name!r} has no samples (all empty/NaN)")


def validate(rec: Recording, source: str = "recording") -> Recording:
    """Check a recording against the contract; return it with float64 arrays.

    Raises RecordingError (message starting with ``source``) for a bad format tag or rig,
    unknown channels, non-vector or non-numeric arrays, fewer than 2 samples, non-finite
    or non-increasing time, mismatched lengths, infinite or all-NaN channels, no channels.
    """
    rig = _check_meta(rec.meta, source, need_format=False)
    if not isinstance(rec.channels, dict):
        raise RecordingError(source, "channels is not a dict")
    _check_names(rec.channels, rig, source)
    time = _as_vector(rec.time, "time", source)
    chans = {n: _as_vector(x, f"channel {n!r}", source) for n, x in rec.channels.items()}
    _check_samples(time, chans, source, lambda i: f"sample {i}")
    return Recording(time, chans, rec.meta)


def _mounted(chans: dict, meta: dict, source) -> dict:
    """`chans` without the channels no sensor gives in the recording's set-up: link 1's strain
    bridges in the Watflex single-link set-up (locked_joints naming the shoulder, rigs.md §2)."""
    params, locked = RIGS.get(meta.get("rig")), meta.get("locked_joints")
    if not hasattr(params, "unmounted_channels") or not isinstance(locked, dict):
        return chans
    absent = [n for n in params.unmounted_channels(locked) if n in chans]
    if absent:
        logging.getLogger(__name__).warning("%s: %s left out: not mounted in the single-link set-up "
                                            "(rigs.md §2)", source, ", ".join(absent))
    return {n: x for n, x in chans.items() if n not in absent}


CSV_CHUNK = 20_000  # rows formatted at a time when writing


def _csv_chunks(rec: Recording):
    """CSV text in pieces: header ``time,<channels>``, ``.10g`` numbers, NaN as an empty cell."""
    yield ",".join(["time", *rec.channels]) + "\n"
    arrays = [rec.time, *rec.channels.values()]
    for start in range(0, len(rec.time), CSV_CHUNK):
        cols = [a[start:start + CSV_CHUNK].tolist() for a in arrays]
        yield "".join(",".join("" if x != x else format(x, ".10g") for x in row) + "\n" for row in zip(*cols))


def _csv_text(rec: Recording) -> str:
    """The whole CSV text (see _csv_chunks)."""
    return "".join(_csv_chunks(rec))


def write_recording(rec: Recording, directory, name: str) -> Path:
    """Write ``directory/name.csv`` and ``name.json`` atomically; return the csv path.

    Both files are written to temporary files in ``directory`` and then moved into place;
    on error none of them is left behind. ``meta["format"]`` defaults to FORMAT. Raises
    RecordingError for invalid data, a bad ``name`` or a meta that is not JSON-serialisable;
    OSError for I/O failures.
    """
    directory = Path(directory)
    seps = {"/", "\0", os.sep, os.altsep} - {None}
    if not isinstance(name, str) or name in ("", ".", "..") or any(s in name for s in seps):
        raise RecordingError(directory, f"bad recording name {_show(name)}")
    csv_path, json_path = directory / f"{name}.csv", directory / f"{name}.json"
    rec = validate(rec, str(csv_path))
    rec = Recording(rec.time, _mounted(rec.channels, rec.meta, csv_path), rec.meta)
    meta = {"format": FORMAT, **rec.meta}
    try:
        sidecar = json.dumps(meta, indent=2, sort_keys=True, allow_nan=False) + "\n"  # strict JSON
    except (TypeError, ValueError) as err:
        raise RecordingError(json_path, f"meta is not JSON-serialisable: {err}") from None
    contents = [(csv_path, _csv_chunks(rec)), (json_path, [sidecar])]
    directory.mkdir(parents=True, exist_ok=True)
    csv_existed = csv_path.exists()
    temps, placed = [], []
    try:
        for target, data in contents:
            tmp = directory / f".{name}.{uuid.uuid4().hex}{target.suffix}.tmp"
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            temps.append(tmp)
            with os.fdopen(fd, "wb") as f:
                for piece in data:
                    f.write(piece.encode())
                f.flush()
                os.fsync(f.fileno())
        for tmp, (target, _) in zip(temps, contents):
            os.replace(tmp, target)
            placed.append(target)
    except BaseException:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
        if placed == [csv_path] and not csv_existed:  # no csv without its sidecar
            csv_path.unlink(missing_ok=True)
        raise
    return csv_path


def _read_bytes(path: Path, source, missing: str = "file not found") -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise RecordingError(source, missing) from None
    except (OSError, ValueError) as err:  # ValueError: NUL in the path
        raise RecordingError(source, f"cannot read {path.name}: "
                                     f"{getattr(err, 'strerror', None) or err}") from None


def _load_sidecar(path: Path) -> dict:
    side = path.with_suffix(".json")
    raw = _read_bytes(side, path, f"sidecar {side.name} not found")
    try:
        return json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError as err:
        raise RecordingError(side, f"sidecar is not UTF-8 text (byte {err.start})") from None
    except (ValueError, RecursionError) as err:
        raise RecordingError(side, f"sidecar is not valid JSON: {err}") from None


BLOCK_BYTES = 1 << 20  # CSV bytes parsed at a time (pyarrow reads a few dozen blocks ahead)


def _read_csv(path: Path, rig: str, source):
    """Read the CSV columnar (pyarrow, in blocks: memory about the data's size); on anything
    pyarrow refuses, the line-by-line reader below names the first bad line as it reaches it.
    Return (time, channels, where)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    raw_header, skip, delimiter = _csv_header(path, source)
    header = _file_columns(raw_header, rig)
    _check_header(header, rig, source)
    if delimiter is None:  # columns aligned by spaces: pyarrow takes one delimiter character only
        return _read_csv_lines(path, rig, source)
    try:
        reader = pacsv.open_csv(
            path, read_options=pacsv.ReadOptions(skip_rows=skip, column_names=header, block_size=BLOCK_BYTES,
                                                 use_threads=False),  # threads read the whole file ahead
            parse_options=pacsv.ParseOptions(delimiter=delimiter, newlines_in_values=False, ignore_empty_lines=True),
            convert_options=pacsv.ConvertOptions(column_types={h: pa.float64() for h in header},
                                                 null_values=[""], strings_can_be_null=False))
        data, n = np.empty((len(header), 0)), 0
        for batch in reader:  # each block copied into one preallocated array, then freed
            if n + batch.num_rows > data.shape[1]:  # capacity from the file size and the rows per block
                rows = int(os.path.getsize(path) * batch.num_rows / BLOCK_BYTES * 1.05) + 1024
                grown = np.empty((len(header), max(rows, int(1.25 * (n + batch.num_rows)))))
                grown[:, :n] = data[:, :n]
                data = grown
            for j, column in enumerate(batch.columns):
                data[j, n:n + batch.num_rows] = column.to_numpy(zero_copy_only=False)
            n += batch.num_rows
    except (pa.ArrowInvalid, pa.ArrowTypeError, UnicodeDecodeError, OSError):
        return _read_csv_lines(path, rig, source)
    cols = {h: data[j, :n] for j, h in enumerate(header)}  # rows of one array: no copy
    time, cols = _scaled(cols.pop("time"), cols, raw_header, rig)
    return time, cols, None  # None: line numbers unknown (blank lines are skipped); see read_recording


def _csv_header(path: Path, source) -> tuple[list[str], int, str | None]:
    """The header's cells (stripped), the number of lines up to and including it (blank lines and
    lines starting with # or % before it are skipped), and the delimiter: "," (CSV), a tab, or None
    (columns separated by runs of spaces)."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            for n, line in enumerate(f, 1):
                if line.strip() and not line.lstrip().startswith(COMMENTS):
                    break
            else:
                raise RecordingError(source, "empty file (no header line)")
    except UnicodeDecodeError as err:
        raise RecordingError(source, f"not UTF-8 text (byte {err.start})") from None
    delimiter = "," if "," in line else "\t" if "\t" in line else None
    if delimiter is None:
        return line.split(), n, None
    try:
        row = next(csv.reader([line], strict=True, delimiter=delimiter))
    except (csv.Error, StopIteration) as err:
        raise RecordingError(source, f"malformed CSV at line {n}: {err}") from None
    return [c.strip() for c in row], n, delimiter


def _file_columns(header: list[str], rig: str) -> list[str]:
    """The file's column names as the recording's: renamed by the rig's [columns] table (a column
    it maps to "" is kept as IGNORED + its name, and dropped after reading)."""
    from .rigdesc import load_rig

    table = load_rig(rig).columns
    return [(table[h][0] or IGNORED + h) if h in table else h for h in header]


def _scaled(time: np.ndarray, cols: dict, header: list[str], rig: str):
    """Columns in the recording's units: each times its [columns] scale; ignored columns dropped."""
    from .rigdesc import load_rig

    table, names = load_rig(rig).columns, _file_columns(header, rig)
    scale = {name: table[h][1] for h, name in zip(header, names) if h in table and table[h][1] != 1.0}
    cols = {n: (x * scale[n] if n in scale else x) for n, x in cols.items() if not n.startswith(IGNORED)}
    return (time * scale["time"] if "time" in scale else time), cols


def _check_header(header: list[str], rig: str, source) -> None:
    if "" in header:
        raise RecordingError(source, f"empty column name in header (column {header.index('') + 1})")
    if len(set(header)) < len(header):
        dup = next(h for j, h in enumerate(header) if h in header[:j])
        raise RecordingError(source, f"duplicate column {_show(dup)} in header")
    if "time" not in header:
        raise RecordingError(source, "no 'time' column in header (a rig's [columns] may name it)")
    _check_names([h for h in header if h != "time" and not h.startswith(IGNORED)], rig, source)


def _rows(f, delimiter: str | None, source):
    """(line number, cells) of a text file's lines: csv.reader for a delimiter, else split at spaces;
    RecordingError at the line the CSV parser stops on."""
    if delimiter is not None:
        reader = csv.reader(f, strict=True, delimiter=delimiter)
        try:
            for row in reader:
                yield reader.line_num, row
        except csv.Error as err:
            raise RecordingError(source, f"malformed CSV at line {reader.line_num}: {err}") from None
    else:
        for n, line in enumerate(f, 1):
            yield n, line.split()


def _read_csv_lines(path: Path, rig: str, source):
    """Parse the text line by line, stopping at the first bad line; return (time, channels, where)."""
    raw_header, _, delimiter = _csv_header(path, source)
    header, rows, lines = None, [], []
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            for n, row in _rows(f, delimiter, source):
                if not row or (len(row) == 1 and not row[0].strip()) or row[0].lstrip().startswith(COMMENTS):
                    continue  # blank or comment line
                if header is None:
                    header = _file_columns([c.strip() for c in row], rig)
                    _check_header(header, rig, source)
                    continue
                if len(row) != len(header):
                    raise RecordingError(source, f"line {n} has {len(row)} fields, header has {len(header)}")
                cells = [c.strip() for c in row]
                bad = [j for j, c in enumerate(cells) if c and not _NUMBER.fullmatch(c)]
                if bad:
                    raise RecordingError(source, f"line {n}, column {raw_header[bad[0]]!r}: "
                                                 f"{_show(row[bad[0]])} is not a number")
                rows.append([float(c) if c else np.nan for c in cells])
                lines.append(n)
    except UnicodeDecodeError as err:
        raise RecordingError(source, f"not UTF-8 text (byte {err.start} of a block)") from None
    if header is None:
        raise RecordingError(source, "empty file (no header line)")
    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    cols = {h: np.ascontiguousarray(data[:, j]) for j, h in enumerate(header)}
    time, cols = _scaled(cols.pop("time"), cols, raw_header, rig)
    return time, cols, lambda i: f"line {lines[i]}"


# MAT v5 data types -> bytes per element, for real numeric data (miINT8 .. miUINT64).
_MAT_NUMERIC = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8}
_MAT_TEXT = {2: 1, 4: 2, 16: 1, 17: 2}  # a char array's data types (bytes a character: exactly, or at least in UTF)
_V73_NUMERIC = ("double", "single", "logical", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")


def _mat_elements(buf: bytes, order: str, source) -> list[tuple[int, bytes]]:
    """Split a MAT v5 byte stream into (type, payload) data elements."""
    pos, out = 0, []
    while pos < len(buf):
        if len(buf) - pos < 8:
            raise RecordingError(source, "truncated MATLAB file")
        mdtype, nbytes = struct.unpack_from(order + "II", buf, pos)
        if mdtype >> 16:  # small element: size and type share the first word
            mdtype, nbytes = mdtype & 0xFFFF, mdtype >> 16
            out.append((mdtype, buf[pos + 4: pos + 4 + min(nbytes, 4)]))
            pos += 8
            continue
        if pos + 8 + nbytes > len(buf):
            raise RecordingError(source, "truncated MATLAB file")
        out.append((mdtype, buf[pos + 8: pos + 8 + nbytes]))
        pos += 8 + (nbytes if mdtype == 15 else -(-nbytes // 8) * 8)
    return out


def _load_mat(raw: bytes, source) -> dict:
    """A MATLAB file's variables as scipy.io.loadmat gives them (arrays in MATLAB's shape, text as str; None for a
    struct, cell, object or sparse array, left unread): a v5/v7 file checked first (_check_mat), a v7.3 file (HDF5,
    `save -v7.3`, MATLAB's choice past 2 GB) read by h5py."""
    if raw[124:128] in (b"\x00\x02IM", b"\x02\x00MI") and raw[512:520] == b"\x89HDF\r\n\x1a\n":
        return _load_v73(raw, source)
    readable, other = _check_mat(raw, source)
    import scipy.io

    try:
        return dict.fromkeys(other) | (scipy.io.loadmat(io.BytesIO(raw), variable_names=readable) if readable else {})
    except Exception as err:  # scipy raises a zoo of types on corrupt files
        cause = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise RecordingError(source, f"cannot read MATLAB file: {_show(cause, 120)}") from None


def _load_v73(raw: bytes, source) -> dict:
    """A v7.3 file's top-level variables: numeric arrays transposed back to MATLAB's shape (HDF5 keeps MATLAB's
    column-major order), char arrays as str, structs and cells None (left unread), MATLAB's own groups (#refs#) left
    out; a complex array refused by name."""
    import h5py

    out = {}
    try:
        with h5py.File(io.BytesIO(raw), "r") as f:
            for name, item in f.items():
                kind = item.attrs.get("MATLAB_class", b"")
                kind = kind.decode() if isinstance(kind, bytes) else str(kind)
                if name.startswith("#"):
                    continue
                if kind == "char" and isinstance(item, h5py.Dataset):
                    codes = np.asarray(item).T.ravel(order="F") if "MATLAB_empty" not in item.attrs else []
                    out[name] = "".join(map(chr, codes))
                elif not isinstance(item, h5py.Dataset) or kind not in _V73_NUMERIC:
                    out[name] = None
                elif "MATLAB_empty" in item.attrs:  # its dimensions stored in place of data
                    out[name] = np.zeros((0, 0))
                elif item.dtype.kind not in "fiub":  # complex: a compound of real and imag
                    raise RecordingError(source, f"MATLAB variable {_show(name)} is not a plain real numeric array")
                else:
                    out[name] = np.asarray(item).T
    except RecordingError:
        raise
    except Exception as err:  # h5py: OSError on a corrupt file, others on odd layouts
        cause = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise RecordingError(source, f"cannot read MATLAB v7.3 file: {_show(cause, 120)}") from None
    return out


def _check_mat(raw: bytes, source) -> tuple[list[str], list[str]]:
    """The variables of a MAT v5/v7 file scipy.io.loadmat may read (plain real numeric arrays, text) and those it may
    not (structs, cells, objects, sparse arrays: their contents never parsed): scipy can crash the interpreter
    (segfault) on malformed ones, so the structure is checked first; a malformed or complex variable is refused."""
    order = {b"IM": "<", b"MI": ">"}.get(raw[126:128])
    if len(raw) < 128 or not order or struct.unpack_from(order + "H", raw, 124)[0] != 0x0100:
        raise RecordingError(source, "not a MATLAB v5, v7 or v7.3 file (v4 is not supported)")
    readable, other = [], []
    for mdtype, payload in _mat_elements(raw[128:], order, source):
        if mdtype == 15:  # miCOMPRESSED: one zlib-compressed element
            try:
                inner = _mat_elements(zlib.decompress(payload), order, source)
            except zlib.error as err:
                raise RecordingError(source, f"corrupt compressed MATLAB data: {err}") from None
            mdtype, payload = inner[0] if len(inner) == 1 else (0, b"")
        parts = _mat_elements(payload, order, source) if mdtype == 14 else []  # miMATRIX
        if [kind for kind, _ in parts[:3]] != [6, 5, 1] or len(parts[0][1]) != 8 \
                or len(parts[1][1]) < 8 or len(parts[1][1]) % 4:
            raise RecordingError(source, "malformed MATLAB variable")
        flags = struct.unpack_from(order + "I", parts[0][1])[0]
        dims = struct.unpack(order + f"{len(parts[1][1]) // 4}i", parts[1][1])
        name = parts[2][1].decode("latin-1")
        kind, data = parts[3] if len(parts) == 4 else (0, b"")
        if flags & 0xFF in (1, 2, 3, 5):  # cell, struct, object, sparse: left unread
            other.append(name)
            continue
        if flags & 0xFF == 4 and kind in _MAT_TEXT and min(dims) >= 0 and not flags & 0x800:
            size = math.prod(dims) * _MAT_TEXT[kind]
            if len(data) >= size if kind in (16, 17) else len(data) == size:
                readable.append(name)  # text (a note, a controller's name): read, never a channel
                continue
        if not 6 <= flags & 0xFF <= 15 or flags & 0x800 or kind not in _MAT_NUMERIC \
                or min(dims) < 0 or len(data) != math.prod(dims) * _MAT_NUMERIC[kind]:
            raise RecordingError(source, f"MATLAB variable {_show(name)} is not a plain real "
                                         "numeric array or text")
        readable.append(name)
    return readable, other


def _read_mat(raw: bytes, rig: str, source):
    """Load a MATLAB file; return (time, channels, where, scalars) with ``where(i)`` = 'sample i'.

    The time variable and the 1x1 scalars a rig exports beside its channels (e.g. EMPS's
    controller gains) are named by the rig description (`time_variable`, `mat_scalars`).
    """
    from .rigdesc import load_rig

    description = load_rig(rig)
    mat = _load_mat(raw, source)
    time_name = description.time_variable
    scalars = {n: float(np.asarray(mat[n]).ravel()[0]) for n in description.mat_scalars
               if mat.get(n) is not None and np.asarray(mat[n]).size == 1 and np.asarray(mat[n]).dtype.kind in "fiub"}
    text = {k for k in mat if not k.startswith("__") and (mat[k] is None or np.asarray(mat[k]).dtype.kind == "U")}
    if text & {time_name, *description.channels}:  # notes, names, structs: never a channel
        name = min(text & {time_name, *description.channels})
        raise RecordingError(source, f"MATLAB variable {_show(name)} is not a plain real numeric array")
    names = [k for k in mat if not k.startswith("__") and k not in scalars and k not in text]
    if time_name not in names:
        raise RecordingError(source, f"no {time_name!r} variable")
    _check_names([n for n in names if n != time_name], rig, source)
    time = _as_vector(mat[time_name], time_name, source, squeeze=True)
    chans = {n: _as_vector(mat[n], f"variable {n!r}", source, squeeze=True)
             for n in names if n != time_name}
    return time, chans, lambda i: f"sample {i}", scalars


def read_recording(path, sidecar: dict | None = None) -> Recording:
    """Read ``X.csv`` or ``X.mat`` with its sidecar ``X.json`` (or the given ``sidecar``).

    Time in s, channels in the units of :data:`CHANNELS`, empty cells as NaN. Raises
    RecordingError (one line, naming the file) for any unreadable or invalid input.
    """
    path = Path(path)
    source = str(path)
    suffix = path.suffix.lower()
    if suffix not in (*TEXT_SUFFIXES, ".mat"):
        raise RecordingError(source, f"not a recording ({', '.join(TEXT_SUFFIXES)} text or .mat)")
    if suffix == ".mat":
        raw = _read_bytes(path, source)
    elif not path.is_file():
        _read_bytes(path, source)  # the same messages: not found, not readable, a directory
    meta = _load_sidecar(path) if sidecar is None else copy.deepcopy(sidecar)
    rig = _check_meta(meta, path.with_suffix(".json") if sidecar is None else source, True)
    if suffix in TEXT_SUFFIXES:
        try:
            time, chans, where = _read_csv(path, rig, source)
        except OSError as err:
            raise RecordingError(source, f"cannot read {path.name}: {err.strerror or err}") from None
    elif _split_mat(rig):
        time, chans, where = _read_mat_split(path, rig)
    else:
        time, chans, where, scalars = _read_mat(raw, rig, source)
        meta = _fill_scalars(meta, scalars, source)
    chans = _mounted(chans, meta, source)
    unit = meta.get("time_unit", "s") if isinstance(meta, dict) else "s"
    if unit not in ("s", "ms"):
        raise RecordingError(source, f"sidecar time_unit must be \"s\" or \"ms\", got {_show(unit)}")
    if unit == "ms":  # declared milliseconds: the contract's seconds from here on
        time = time / 1000.0
        meta = {k: v for k, v in meta.items() if k != "time_unit"}
    try:
        _check_samples(time, chans, source, where or (lambda i: f"sample {i}"))
    except RecordingError:
        if where is not None:
            raise
        time, chans, where = _read_csv_lines(path, rig, source)  # to name the line
        _check_samples(time / (1000.0 if unit == "ms" else 1.0), chans, source, where)
        raise
    return Recording(time, chans, meta)


def _split_mat(rig: str) -> bool:
    from .rigdesc import load_rig

    return load_rig(rig).mat_channels is not None


def _read_mat_split(path: Path, rig: str):
    """A recording kept as one .mat file per signal (the rig's `mat_channels`, `mat_time`): each
    entry names its file (a pattern with {run}, matched against `path`'s name), variable, column
    (1-based, of an N x k array) and scale (to the channel's unit, to s for the time)."""
    from .rigdesc import load_rig

    description = load_rig(rig)
    specs = {"time": description.mat_time, **description.mat_channels}
    run = None
    for spec in specs.values():
        head, _, tail = spec["file"].partition("{run}")
        name = path.name
        if name.startswith(head) and name.endswith(tail) and len(name) > len(head) + len(tail):
            run = name[len(head): len(name) - len(tail)]
            break
    if run is None:
        patterns = sorted({spec["file"] for spec in specs.values()})
        raise RecordingError(path, f"file name matches none of the rig's .mat files ({', '.join(patterns)})")
    loaded, columns = {}, {}
    for channel, spec in specs.items():
        source = path.with_name(spec["file"].replace("{run}", run))
        if source not in loaded:
            loaded[source] = _load_mat(_read_bytes(source, source), source)
        mat, variable = loaded[source], spec["variable"]
        if variable not in mat:
            raise RecordingError(source, f"no variable {variable!r} (for {channel!r})")
        array = np.asarray(mat[variable])
        if array.dtype.kind in "UO":
            raise RecordingError(source, f"variable {variable!r} (for {channel!r}) is text or a struct, not numbers")
        column = int(spec.get("column", 1))
        if array.ndim != 2 or not 1 <= column <= array.shape[1]:
            raise RecordingError(source, f"variable {variable!r} (shape {array.shape}) has no column {column} (for {channel!r})")
        columns[channel] = _as_vector(array[:, column - 1], f"variable {variable!r} column {column}", source) \
            * float(spec.get("scale", 1.0))
        if columns[channel].size != columns["time"].size:
            raise RecordingError(source, f"variable {variable!r} has {columns[channel].size} samples, "
                                         f"the time ({description.mat_time['file'].replace('{run}', run)}) has {columns['time'].size}")
    time = columns.pop("time")
    return time, columns, lambda i: f"sample {i}"


def _fill_scalars(meta, scalars: dict, source):
    """Replace sidecar strings "mat:NAME" (at any depth) by the .mat scalar NAME."""
    if isinstance(meta, dict):
        return {k: _fill_scalars(v, scalars, source) for k, v in meta.items()}
    if isinstance(meta, list):
        return [_fill_scalars(v, scalars, source) for v in meta]
    if isinstance(meta, str) and meta.startswith("mat:"):
        if meta[4:] not in scalars:
            raise RecordingError(source, f"the sidecar asks for {meta!r} but the file has no such scalar")
        return scalars[meta[4:]]
    return meta
