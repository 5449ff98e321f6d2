"""Stage 5, storage: one Zarr run store per run with atomic checkpoints, and the output dir's layout.

:mod:`~vasc_pipeline.store.run_store` (:class:`RunStore`), :mod:`~vasc_pipeline.store.checkpoints`
(write, verify, fall back), :mod:`~vasc_pipeline.store.trace` (the cost trace's columns and records).
"""

from .run_store import (
    FORMAT,
    RUNS_DIR,
    STATUS_COMPLETE,
    STATUS_RUNNING,
    SWEEP_AXES,
    TRACE_CHUNK,
    Checkpoint,
    CheckpointWarning,
    GroupStore,
    RunStore,
    StoreDamaged,
    StoreError,
    config_differences,
    config_hash,
    file_lock,
    hashed_config,
    identity_differences,
    is_empty_leftover,
    run_lock,
    run_path,
    verify_store,
)
from .trace import TRACE_FIELDS, TRACE_NAMES, Trace, TraceRecord

__all__ = [
    "RunStore",
    "GroupStore",
    "Checkpoint",
    "CheckpointWarning",
    "StoreError",
    "StoreDamaged",
    "verify_store",
    "is_empty_leftover",
    "run_path",
    "run_lock",
    "file_lock",
    "config_hash",
    "hashed_config",
    "config_differences",
    "identity_differences",
    "SWEEP_AXES",
    "TRACE_FIELDS",
    "TRACE_NAMES",
    "TraceRecord",
    "Trace",
    "STATUS_RUNNING",
    "STATUS_COMPLETE",
    "RUNS_DIR",
    "FORMAT",
    "TRACE_CHUNK",
]
