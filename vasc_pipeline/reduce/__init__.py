"""Stage 6, the reduction: complete runs -> orders, morphometry against Kassab 1993, ``summary.zarr``, exports.

:mod:`~vasc_pipeline.reduce.stage` (:func:`reduce`, the stage), :mod:`~vasc_pipeline.reduce.runs`
(the complete runs, the best seed per cell), :mod:`~vasc_pipeline.reduce.summary` (the DataTree),
:mod:`~vasc_pipeline.reduce.ordering` and :mod:`~vasc_pipeline.reduce.morphometry` (vessel
orders, elements, statistics), :mod:`~vasc_pipeline.reduce.reference` (Kassab 1993),
:mod:`~vasc_pipeline.reduce.similarity` (trunks), :mod:`~vasc_pipeline.reduce.export` (VTP, CSV).
"""

from .stage import (
    ANATOMY_CSV,
    COMPARISON_CSV,
    COMPARISON_LEVEL,
    COMPARISON_SCHEME,
    COMPARISON_SUMMARY_CSV,
    SUMMARY_NAME,
    Reduction,
    ReductionError,
    RunInfo,
    anatomy_frame,
    best_runs,
    build_summary,
    check_one_configuration,
    comparison_frame,
    find_runs,
    format_anatomy,
    format_comparison,
    reduce,
    remove_superseded_outputs,
    write_summary,
)

__all__ = [
    "RunInfo",
    "Reduction",
    "ReductionError",
    "find_runs",
    "check_one_configuration",
    "best_runs",
    "build_summary",
    "write_summary",
    "comparison_frame",
    "anatomy_frame",
    "format_comparison",
    "format_anatomy",
    "reduce",
    "SUMMARY_NAME",
    "COMPARISON_CSV",
    "COMPARISON_SUMMARY_CSV",
    "ANATOMY_CSV",
    "COMPARISON_SCHEME",
    "COMPARISON_LEVEL",
    "remove_superseded_outputs",
]
