"""The output_dir of a command line run: the Hydra callback that checks it before Hydra writes its
logs there, and the clean-up of a run refused as bad input.

The writability check and the one-sweep-at-a-time lock live with the store
(:mod:`vasc_pipeline.store.sweep_lock`), where the reduction reads the lock too.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path
from typing import Any

from ..store.layout import RUNS_DIR
from ..store.sweep_lock import check_output_dir

__all__ = ["OutputDirCallback", "forget_refused_run"]


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
