"""Stage 4, the sweep: grid expansion, jobs, planning, the Dask fan-out, progress, the output dir.

:mod:`~vasc_pipeline.pipeline.sweep` (config -> jobs), :mod:`~vasc_pipeline.pipeline.job`
(one job into its store), :mod:`~vasc_pipeline.pipeline.planning` (what is on disk, stores of
new runs), :mod:`~vasc_pipeline.pipeline.orchestrate` (``python -m vasc_pipeline``),
:mod:`~vasc_pipeline.pipeline.cluster` (the Dask client), :mod:`~vasc_pipeline.pipeline.progress`
(the live line), :mod:`~vasc_pipeline.pipeline.outdir` (lock, writability, Hydra callback).
"""

__all__ = ["sweep", "job", "planning", "orchestrate", "cluster", "progress", "outdir", "extend", "reduction"]
