"""The output_dir's sweep lock: one sweep writes into an output_dir at a time, and anyone may ask
whether one does.

:func:`output_dir_lock` holds ``<output_dir>/.vasc_pipeline.lock`` (an ``fcntl`` lock through
:func:`vasc_pipeline.store.run_store.file_lock`, released by the kernel even on SIGKILL) while a
sweep runs; :func:`sweep_in_progress` tells the reduction who holds it; :func:`check_output_dir`
creates the directory and proves it writable.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Iterator

from .layout import LOCK_NAME, RUNS_DIR
from .run_store import file_lock

__all__ = ["OutputDirLocked", "output_dir_lock", "sweep_in_progress", "check_output_dir"]


class OutputDirLocked(OSError):
    """Another sweep holds the output_dir."""


@contextlib.contextmanager
def output_dir_lock(output_dir: str | os.PathLike) -> Iterator[Path]:
    """Hold ``<output_dir>/.vasc_pipeline.lock`` for the duration of a sweep.

    Raises :class:`OutputDirLocked` (an OSError) if another sweep holds it, and OSError
    naming ``output_dir`` if the directory cannot be created or written.
    """
    out = check_output_dir(output_dir)
    with contextlib.ExitStack() as stack:
        try:
            (out / RUNS_DIR).mkdir(exist_ok=True)
            fh = stack.enter_context(file_lock(out / LOCK_NAME, wait=False))
        except BlockingIOError:
            try:
                holder = json.loads((out / LOCK_NAME).read_text() or "{}")
            except (OSError, ValueError):
                holder = {}
            raise OutputDirLocked(
                f"output_dir {str(out)!r} is in use by another sweep (pid {holder.get('pid', '?')} on "
                f"{holder.get('host', '?')}, started {holder.get('started', '?')}). Two sweeps never write "
                "into one output_dir at once: wait for that one to finish (or stop it; rerunning the same "
                "command resumes it), or choose another output_dir=..."
            ) from None
        except OSError as exc:
            raise OSError(
                f"output_dir: cannot create or write {str(out)!r} ({exc.strerror or exc}); choose a "
                "writable directory with output_dir=..."
            ) from exc
        fh.seek(0)
        fh.truncate()
        fh.write(
            json.dumps(
                {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "started": time.strftime("%Y-%m-%d %H:%M:%S"),
                    "argv": sys.argv,
                }
            )
        )
        fh.flush()
        yield out


def sweep_in_progress(output_dir: str | os.PathLike) -> str | None:
    """Who holds ``output_dir``'s sweep lock (``"pid N on HOST, started T"``), or None when no sweep does.

    Read-only for a directory without a lock file (none is created); the lock is tried, never waited for.
    """
    path = Path(output_dir) / LOCK_NAME
    if not path.is_file():
        return None
    try:
        with file_lock(path, wait=False):
            return None
    except BlockingIOError:
        pass
    except OSError:  # unreadable lock file: nothing known about a sweep
        return None
    try:
        holder = json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        holder = {}
    return f"pid {holder.get('pid', '?')} on {holder.get('host', '?')}, started {holder.get('started', '?')}"


def check_output_dir(output_dir: str | os.PathLike) -> Path:
    """Create ``output_dir`` if needed and prove it writable; OSError naming the field otherwise."""
    out = Path(output_dir)
    if out.exists() and not out.is_dir():
        raise OSError(
            f"output_dir: {str(out)!r} is a file, not a directory; choose a directory for the results with "
            "output_dir=..."
        )
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OSError(
            f"output_dir: cannot create or write {str(out)!r} ({exc.strerror or exc}); choose a "
            "writable directory with output_dir=..."
        ) from exc
    return out
