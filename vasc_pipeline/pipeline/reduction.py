"""The reduction as the pipeline runs it: the summary and tables (:mod:`vasc_pipeline.reduce`), then
the figures drawn from them (:mod:`vasc_pipeline.figures`), in that order.

The reduction itself draws nothing, so it runs without matplotlib's import and a script may
reduce without figures; this is the one place that calls the two together.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TextIO

from ..store.layout import FIGURES_DIR

__all__ = ["reduce_and_draw"]


def reduce_and_draw(
    output_dir: str | os.PathLike,
    *,
    figures: bool = True,
    exports: bool = True,
    stream: TextIO | None = None,
    extended_zerod: str = "lumped",
):
    """:func:`vasc_pipeline.reduce.reduce` of ``output_dir``, then its figures into ``<output_dir>/figures/``.

    Returns the :class:`~vasc_pipeline.reduce.stage.Reduction` with ``figures`` filled in. A failure
    while drawing is recorded in its ``errors`` and printed, never raised: the summary and tables
    are written first and stay valid. ``ReductionError`` (nothing to reduce) is raised as by the
    reduction.
    """
    from .. import reduce as reduction  # the package's attribute: what a caller (or a test) replaces

    stream = stream or sys.stdout
    result = reduction.reduce(output_dir, exports=exports, stream=stream, extended_zerod=extended_zerod)
    if figures:
        from ..figures import make_figures
        from ..figures.extended import draw_extended

        _draw(lambda: make_figures(result.summary, output_dir), result, "figures", stream)
        whole = result.extended
        if whole is not None and whole.summary is not None:
            whole.figures = _draw(lambda: draw_extended(whole), result, "extended figures", stream)
    return result


def _draw(draw, result, stage: str, stream: TextIO) -> list:
    """The figures ``draw`` makes, added to ``result.figures``; a failure goes to ``result.errors``."""
    try:
        paths = draw()
    except Exception as exc:
        result.errors[stage] = f"{type(exc).__name__}: {exc}"
        stream.write(f"  {stage} FAILED: {result.errors[stage]}\n")
        return []
    result.figures.extend(paths)
    stream.write(f"  {stage}: {len(paths)} PNG in {Path(result.output_dir) / FIGURES_DIR}\n")
    stream.flush()
    return paths
