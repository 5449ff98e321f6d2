"""Stage 5, storage: one Zarr run store per run with atomic checkpoints, and the output dir's layout.

:mod:`~vasc_pipeline.store.run_store` (:class:`RunStore`), :mod:`~vasc_pipeline.store.checkpoints`
(write, verify, fall back).
"""

from . import run_store as _run_store
from .run_store import *  # noqa: F403
from .run_store import FORMAT, TRACE_CHUNK

__all__ = [*_run_store.__all__, "FORMAT", "TRACE_CHUNK"]
