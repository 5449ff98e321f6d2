"""Stage 5, storage: one Zarr run store per run with atomic checkpoints, and the output dir's layout.

:mod:`~vasc_pipeline.store.run_store` (:class:`RunStore`), :mod:`~vasc_pipeline.store.checkpoints`
(write, verify, fall back).
"""

from . import run_store as _run_store
from .run_store import *  # noqa: F403

__all__ = list(_run_store.__all__)
