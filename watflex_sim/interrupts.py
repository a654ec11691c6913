"""Outputs that appear whole or not at all, and Ctrl-C that stops worker processes at once.

`writable(dir)` checks an output directory before any work; `staged(dir)` gives a hidden
staging directory inside it whose files are moved into place only when the block succeeds
(an error or Ctrl-C removes them); `worker_init` makes pool workers ignore SIGINT (the parent
decides), and `stop_pool` terminates a ProcessPoolExecutor's processes instead of waiting
for their running jobs.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import tempfile
import uuid
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Iterator

from .model import ConfigError

STAGE_PREFIX = ".watflex-partial-"


def writable(directory, what: str = "output directory", keep: bool = False) -> Path:
    """Prove `directory` writable with a probe file, before any work; ConfigError (one line) if a
    file is in the way, permission is missing or the file system is read-only. Directories
    it had to create are removed again unless `keep`."""
    directory = Path(directory)
    missing = []
    for parent in [directory, *directory.parents]:
        if parent.exists():
            if not parent.is_dir():
                raise ConfigError(f"{what} {directory}: {parent} is a file, not a directory")
            break
        missing.append(parent)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".watflex-probe-{uuid.uuid4().hex}"
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"{what} {directory} is not writable: {exc.strerror or exc}") from None
    finally:
        for made in [] if keep else missing:  # deepest first
            with contextlib.suppress(OSError):
                made.rmdir()
    return directory


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold Ctrl-C during a few renames; it is raised when the block ends."""
    caught = []
    try:
        previous = signal.signal(signal.SIGINT, lambda *a: caught.append(a))
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            raise KeyboardInterrupt


@contextlib.contextmanager
def staged(directory) -> Iterator[Path]:
    """A staging directory inside `directory` (created): files written there are moved to
    `directory` (same names) when the block ends without error, else removed with it."""
    directory = writable(directory, keep=True)
    stage = Path(tempfile.mkdtemp(dir=directory, prefix=STAGE_PREFIX))
    try:
        yield stage
        with sigint_deferred():
            for path in sorted(stage.iterdir()):
                os.replace(path, directory / path.name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def move(source: Path, target: Path) -> None:
    """Rename `source` to `target`, across file systems through a temporary copy beside it."""
    try:
        os.replace(source, target)
    except OSError:
        tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
        try:
            shutil.copyfile(source, tmp)
            os.replace(tmp, target)
        finally:
            tmp.unlink(missing_ok=True)


def worker_init(initializer=None, *args) -> None:
    """Pool-worker initializer: ignore Ctrl-C (the parent stops the pool), then `initializer(*args)`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer(*args)


def stop_pool(pool: ProcessPoolExecutor, timeout_s: float = 1.0) -> None:
    """Cancel queued jobs and end the pool's processes now (SIGTERM, then SIGKILL after `timeout_s`).

    On return every future is done (cancelled, or failed with BrokenProcessPool): the pool's
    manager thread, which settles the futures of jobs already handed to a worker, is joined."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    for p in processes:
        with contextlib.suppress(Exception):
            p.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        with contextlib.suppress(Exception):
            p.join(timeout_s)
            if p.is_alive():
                p.kill()
                p.join(timeout_s)
    if manager is not None:
        manager.join(timeout_s)
