"""PNG plots of recordings: one panel per kind of channel, measured and simulated on the same axes."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .recording import Recording  # noqa: E402
from .rerun_log import channel_group  # noqa: E402

MAX_POINTS = 4000  # per line: a figure ~1000 px wide shows no more; longer series are drawn as min/max envelopes


def envelope(t: np.ndarray, y: np.ndarray, n: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """(t, y) with at most about 2n points: the min and max of each of n equal slices, in time order,
    so a peak of one sample still shows (memory and time of a plot stay bounded for any length)."""
    if t.size <= 2 * n:
        return t, y
    edges = np.linspace(0, t.size, n + 1).astype(int)
    lo = np.minimum.reduceat(y, edges[:-1])
    hi = np.maximum.reduceat(y, edges[:-1])
    tt = np.repeat(t[edges[:-1]], 2)
    yy = np.column_stack([lo, hi]).ravel()
    return tt, yy


def plot_recording(rec: Recording, path, others: dict[str, Recording] | None = None, title: str = "") -> Path:
    """Write a PNG of `rec` (solid) with `others` (label -> recording, dashed) overlaid.

    One panel per group (angles, strains, commands, sensors) and unit; each panel's y label
    carries the unit. Returns the path written.
    """
    from .rigdesc import load_rig

    units = rec.units()
    kinds = {c: spec["kind"] for c, spec in load_rig(rec.rig).channels.items()}
    groups: dict[tuple[str, str], list[str]] = {}
    for name in rec.channels:
        kind = kinds.get(name, channel_group(name))
        groups.setdefault((kind, units.get(name, "")), []).append(name)
    fig, axes = plt.subplots(len(groups), 1, figsize=(10, 2.6 * len(groups)), sharex=True, squeeze=False)
    for ax, ((group, unit), names) in zip(axes[:, 0], groups.items()):
        for i, name in enumerate(names):
            color = f"C{i % 10}"
            y = rec.channels[name]
            ok = np.isfinite(y)
            style = "." if ok.mean() < 0.5 else "-"  # sparse channels (camera) as dots
            ax.plot(*envelope(rec.time[ok], y[ok]), style, color=color, lw=1.2, ms=2, label=name)
            for (label, other), dash in zip((others or {}).items(), ("--", ":", "-.")):
                if name in other.channels and kinds.get(name) not in ("reference", "disturbance"):
                    yo = other.channels[name]
                    ok = np.isfinite(yo)
                    ax.plot(*envelope(other.time[ok], yo[ok]), dash, color=color, lw=1.2, alpha=0.85, label=f"{name} ({label})")
        ax.set_ylabel(f"{group} [{unit}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best", ncol=2)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title or f"{rec.rig}: {rec.meta.get('experiment', '')}")
    return save_figure(fig, path)


def save_figure(fig, path, dpi: int = 110) -> Path:
    """Lay out, write `fig` as a PNG at `path` and close it; returns the path."""
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
