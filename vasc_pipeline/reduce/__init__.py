"""Stage 6, the reduction: complete runs -> orders, morphometry against Kassab 1993, ``summary.zarr``, exports.

:mod:`~vasc_pipeline.reduce.stage` (:func:`reduce`, the stage), :mod:`~vasc_pipeline.reduce.runs`
(the complete runs, the best seed per cell), :mod:`~vasc_pipeline.reduce.summary` (the DataTree),
:mod:`~vasc_pipeline.reduce.ordering` and :mod:`~vasc_pipeline.reduce.morphometry` (vessel
orders, elements, statistics), :mod:`~vasc_pipeline.reduce.reference` (Kassab 1993),
:mod:`~vasc_pipeline.reduce.similarity` (trunks), :mod:`~vasc_pipeline.reduce.export` (VTP, CSV).
"""

from . import stage as _stage
from .stage import *  # noqa: F403
from .stage import remove_superseded_outputs

__all__ = [*_stage.__all__, "remove_superseded_outputs"]
