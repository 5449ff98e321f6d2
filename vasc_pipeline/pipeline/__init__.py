"""Stage 4, the sweep: grid expansion, jobs, planning, the Dask fan-out, progress, the output dir.

:mod:`~vasc_pipeline.pipeline.sweep` (config -> jobs), :mod:`~vasc_pipeline.pipeline.job`
(one job into its store), :mod:`~vasc_pipeline.pipeline.planning` (what is on disk, stores of
new runs), :mod:`~vasc_pipeline.pipeline.orchestrate` (``python -m vasc_pipeline``: the sweep's path
and exit status), :mod:`~vasc_pipeline.pipeline.warmup` (the kernels compiled once),
:mod:`~vasc_pipeline.pipeline.dispatch` (the Dask fan-out), :mod:`~vasc_pipeline.pipeline.task`
(the Dask task, the parts' cluster map), :mod:`~vasc_pipeline.pipeline.sweep_result` (what a
sweep did), :mod:`~vasc_pipeline.pipeline.cluster` (the Dask client),
:mod:`~vasc_pipeline.pipeline.progress` (the live line), :mod:`~vasc_pipeline.pipeline.outdir`
(lock, writability, Hydra callback), :mod:`~vasc_pipeline.pipeline.reduction` (the reduction,
then its figures; ``+stage=reduce``).
"""

__all__ = [
    "sweep",
    "job",
    "planning",
    "orchestrate",
    "warmup",
    "dispatch",
    "task",
    "sweep_result",
    "cluster",
    "progress",
    "outdir",
    "extend",
    "reduction",
]
