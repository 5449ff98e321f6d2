"""The output_dir of a sweep: the writability check, the one-sweep-at-a-time lock, the Hydra callback.

:func:`output_dir_lock` holds ``<output_dir>/.vasc_pipeline.lock`` (an ``fcntl`` lock through
:func:`vasc_pipeline.store.file_lock`, released by the kernel even on SIGKILL) while
:func:`vasc_pipeline.pipeline.orchestrate.run_sweep` runs; :func:`check_output_dir` creates the
directory and proves it writable; :class:`OutputDirCallback` runs that check before Hydra
writes its logs there. All three are re-exported by :mod:`vasc_pipeline.pipeline.orchestrate`.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any, Iterator

from ..store.layout import LOCK_NAME, RUNS_DIR
from ..store.run_store import file_lock

__all__ = [
    "LOCK_NAME",
    "OutputDirLocked",
    "output_dir_lock",
    "check_output_dir",
    "sweep_in_progress",
    "OutputDirCallback",
    "forget_refused_run",
]


class OutputDirLocked(OSError):
    """Another sweep holds the output_dir."""


# --------------------------------------------------------------------------------------------
# The output_dir lock


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


# What existed of output_dir before Hydra made its run directory (OutputDirCallback fills it):
# a refused run removes exactly what it created (forget_refused_run).
_BEFORE_RUN: dict[str, Any] = {}


def forget_refused_run(run_dir: str | os.PathLike) -> None:
    """Remove the Hydra run directory ``run_dir`` of a run refused as bad input, and
    ``output_dir/.hydra_logs`` and ``output_dir`` themselves when this run created them and they
    are now empty: a refused input leaves nothing behind."""
    import shutil

    run_dir = Path(run_dir)
    if run_dir.is_dir():
        shutil.rmtree(run_dir, ignore_errors=True)
    for key in ("logs", "output_dir"):
        path = _BEFORE_RUN.get(key)
        if path is not None and not _BEFORE_RUN.get(f"{key}_existed", True):
            with contextlib.suppress(OSError):  # not empty (something else wrote there): kept
                path.rmdir()


class OutputDirCallback:
    """Hydra callback (conf/config.yaml ``hydra.callbacks``): check output_dir before Hydra writes its logs there.

    Hydra creates its run directory (under output_dir) before the task function runs, so an
    unwritable output_dir would otherwise surface as a bare traceback from Hydra.
    """

    def on_run_start(self, config: Any, **kwargs: Any) -> None:
        # An empty output_dir would put results in the working directory and Hydra's logs at the
        # filesystem root; a reduction must not create the directory it was asked to read.
        out = Path(str(config.output_dir or "")).expanduser()
        logs = out / ".hydra_logs"
        _BEFORE_RUN.update(output_dir=out, output_dir_existed=out.exists(), logs=logs, logs_existed=logs.exists())
        try:
            if not str(config.output_dir or "").strip():
                raise OSError("output_dir is empty: give the directory for the results with output_dir=...")
            if config.get("stage") == "reduce":
                if not (Path(config.output_dir) / RUNS_DIR).is_dir():
                    raise OSError(
                        f"output_dir {str(config.output_dir)!r} holds no runs/ directory: nothing to "
                        "reduce. Give the output_dir of a sweep (output_dir=...)"
                    )
            else:
                check_output_dir(config.output_dir)
        except OSError as exc:
            sys.stderr.write(f"vasc_pipeline: error: {exc}\nExisting results were left as they were.\n")
            sys.exit(2)

    # The rest of Hydra's callback interface: nothing to do.
    def on_run_end(self, config: Any, **kwargs: Any) -> None: ...
    def on_multirun_start(self, config: Any, **kwargs: Any) -> None: ...
    def on_multirun_end(self, config: Any, **kwargs: Any) -> None: ...
    def on_job_start(self, config: Any, **kwargs: Any) -> None: ...
    def on_job_end(self, config: Any, job_return: Any, **kwargs: Any) -> None: ...
    def on_compose_config(self, config: Any, config_name: Any, overrides: Any) -> None: ...
