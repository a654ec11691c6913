"""Log a simulated run (1 kHz channels + arm polyline frames) to Rerun (rerun-sdk 0.41).

Everything goes through an explicit ``rr.RecordingStream`` (no global ``rr.init`` state), on a
duration timeline ``sim_time`` (seconds). Channels are grouped into ``angles/``, ``strains/``,
``commands/`` and ``sensors/``; the arm is the ``arm`` entity (one ``LineStrips3D`` strip per frame).
"""

from __future__ import annotations

import os
import sys
import uuid

import numpy as np

GROUPS = ("angles", "strains", "commands", "sensors")
TIMELINE = "sim_time"
_GRPC_PORT = 9876
_DISPLAY_VARS = ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")


def channel_group(name: str) -> str:
    """Entity group of a channel name: 'angles', 'strains', 'commands' or 'sensors'."""
    if name.endswith("_angle") or name == "reference" or name.endswith("_reference") or name == "hub_angle":
        return "angles"
    if name.startswith("strain_"):
        return "strains"
    if name.endswith("_cmd"):
        return "commands"
    return "sensors"


def _one_line(exc: Exception) -> str:
    """First line of an exception message (or its type name)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _time_column(rr, t_s):
    """``rr.TimeColumn`` on ``sim_time`` from seconds, rounded to whole nanoseconds."""
    ns = np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype("timedelta64[ns]")
    return rr.TimeColumn(TIMELINE, duration=ns)


def _blueprint(groups, with_arm: bool):
    """3D view of the arm on the left, one time-series view per channel group stacked on the right."""
    import rerun.blueprint as rrb

    series = [rrb.TimeSeriesView(origin=f"/{g}", name=g) for g in GROUPS if g in groups]
    parts = []
    if with_arm:
        parts.append(rrb.Spatial3DView(origin="/", contents=["/arm/**", "/table/**"], name="arm"))
    if series:
        parts.append(rrb.Vertical(*series))
    if not parts:
        return None
    shares = [1.0, 1.0] if len(parts) == 2 else None
    return rrb.Blueprint(rrb.Horizontal(*parts, column_shares=shares), collapse_panels=True)


def log_run(
    time,
    channels,
    units,
    rrd_path=None,
    spawn=False,
    frames=None,
    frame_time=None,
    app_id="watflex_sim",
    recording_name=None,
) -> None:
    """Log one run to an .rrd file (``rrd_path``) and/or a spawned viewer (``spawn=True``).

    time: (n,) s. channels: name -> (n,) float, NaN samples are dropped per channel.
    units: name -> unit string ("rad", "V", "N m", ...), shown in the series name "name [unit]".
    frames: optional (n_frames, n_points, 3) m, arm polyline root->tip at ``frame_time`` (n_frames,) s.
    Does nothing if neither ``rrd_path`` nor ``spawn`` is given. Raises RuntimeError if the viewer
    cannot be spawned.
    """
    if rrd_path is None and not spawn:
        return
    import rerun as rr

    t = np.asarray(time, dtype=np.float64).ravel()
    data = {}
    for name, y in channels.items():
        y = np.asarray(y, dtype=np.float64).ravel()
        if y.shape != t.shape:
            raise ValueError(f"channel {name!r}: {y.shape[0]} samples, time has {t.shape[0]}")
        data[name] = y
    if frames is not None:
        frames = np.asarray(frames, dtype=np.float64)
        if frame_time is None:
            raise ValueError("frames given without frame_time")
        frame_time = np.asarray(frame_time, dtype=np.float64).ravel()
        if frames.ndim != 3 or frames.shape[2] != 3 or frames.shape[0] != frame_time.shape[0]:
            raise ValueError(f"frames must be (n_frames, n_points, 3) matching frame_time, got {frames.shape}")

    groups = {channel_group(n) for n in data}
    blueprint = _blueprint(groups, frames is not None and len(frames) > 0)

    rec = rr.RecordingStream(app_id, recording_id=uuid.uuid4())
    sinks = []
    if spawn:
        if sys.platform.startswith("linux") and not any(os.environ.get(k) for k in _DISPLAY_VARS):
            raise RuntimeError("cannot spawn the Rerun viewer: no display (DISPLAY/WAYLAND_DISPLAY unset)")
        try:
            rec.spawn(port=_GRPC_PORT, connect=False)  # rr.spawn() would ignore a non-global stream
        except Exception as exc:  # no viewer binary, port in use, ...
            raise RuntimeError(f"could not spawn the Rerun viewer: {_one_line(exc)}") from None
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{_GRPC_PORT}/proxy"))
    if rrd_path is not None:
        sinks.append(rr.FileSink(str(rrd_path)))
    rec.set_sinks(*sinks, default_blueprint=blueprint)
    if recording_name is not None:
        rec.send_recording_name(recording_name)

    for name, y in data.items():
        path = f"{channel_group(name)}/{name}"
        unit = units.get(name, "")
        label = f"{name} [{unit}]" if unit else name
        rec.log(path, rr.SeriesLines(names=label), static=True)
        ok = ~np.isnan(y)
        if ok.any():
            rec.send_columns(path, indexes=[_time_column(rr, t[ok])], columns=rr.Scalars.columns(scalars=y[ok]))

    if frames is not None and len(frames) > 0:
        rec.log("arm", rr.LineStrips3D.from_fields(radii=0.004, colors=[30, 110, 220]), static=True)
        # One strip per frame: default partitioning of .columns() gives one strip per row.
        rec.send_columns(
            "arm", indexes=[_time_column(rr, frame_time)], columns=rr.LineStrips3D.columns(strips=frames)
        )
        pts = frames.reshape(-1, 3)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts):
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            half = np.maximum((hi - lo) / 2 + 0.05, 0.05)
            half[2] = 0.002
            center = (lo + hi) / 2
            center[2] = lo[2] - 0.01
            rec.log("table", rr.Boxes3D(centers=[center], half_sizes=[half], colors=[170, 170, 170]), static=True)

    try:
        rec.flush()  # raises if the spawned viewer never accepted the gRPC connection (e.g. no display)
    except Exception as exc:
        if not spawn:
            raise
        raise RuntimeError(f"could not send the run to the Rerun viewer: {_one_line(exc)}") from None
    finally:
        rec.disconnect()


def read_rrd_channels(rrd_path) -> dict[str, int]:
    """Channel name -> number of scalar samples on ``sim_time`` in an .rrd written by ``log_run``.

    Channels whose samples were all NaN appear with count 0. No viewer needed.
    """
    from rerun.chunk import RrdReader

    counts: dict[str, int] = {}
    for chunk in RrdReader(str(rrd_path)).stream():
        parts = chunk.entity_path.strip("/").split("/")
        if len(parts) != 2 or parts[0] not in GROUPS:
            continue
        name = parts[1]
        counts.setdefault(name, 0)
        if chunk.is_static or TIMELINE not in chunk.timeline_names:
            continue
        batch = chunk.to_record_batch()
        if "Scalars:scalars" not in batch.schema.names:
            continue
        col = batch.column("Scalars:scalars")
        counts[name] += int(col.value_lengths().fill_null(0).to_numpy(zero_copy_only=False).sum())
    return counts
