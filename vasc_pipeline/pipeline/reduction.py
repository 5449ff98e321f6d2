"""The reduction as the pipeline runs it: the summary and tables (:mod:`vasc_pipeline.reduce`), then
the figures drawn from them (:mod:`vasc_pipeline.figures`), in that order.

The reduction itself draws nothing, so it runs without matplotlib's import and a script may
reduce without figures; this is the one place that calls the two together. :func:`reduce_stage`
is ``+stage=reduce``: the reduction of runs already made, refused when the command line asks
for values other than theirs.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any, TextIO

from .. import config as _config
from ..config.schema import ConfigError
from ..store.layout import FIGURES_DIR, RUNS_DIR
from ..store.run_store import StoreError

__all__ = ["reduce_and_draw", "reduce_stage"]


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


def reduce_stage(cfg: Any, stream: TextIO | None = None) -> int:
    """``+stage=reduce``: reduce the complete runs already in ``cfg.output_dir``; returns the exit status."""
    from ..reduce import ReductionError

    stream = stream or sys.stderr
    try:  # the same checks as a run: a typo'd value is reported, not silently ignored
        _config.validate(_config.to_run_config(cfg))
    except ConfigError as exc:
        stream.write(f"vasc_pipeline: error: {exc}\nNothing was reduced; existing results were left as they were.\n")
        return 2
    output_dir = Path(cfg.output_dir)
    if not (output_dir / RUNS_DIR).is_dir():
        stream.write(
            f"vasc_pipeline: error: output_dir {str(output_dir)!r} holds no runs/ directory: nothing to "
            "reduce. Give the output_dir of a sweep (output_dir=...).\n"
        )
        return 2
    ignored = _overrides_unlike_the_runs(cfg, output_dir)
    if ignored:
        stream.write(
            f"vasc_pipeline: error: +stage=reduce reduces the runs of {str(output_dir)!r} as they were made, and "
            f"they were made with other values: {'; '.join(ignored)}. Drop those overrides (or run a sweep with "
            "them into a new output_dir=...). Nothing was reduced.\n"
        )
        return 2
    try:
        reduction = reduce_and_draw(output_dir, stream=stream, extended_zerod=cfg.extend.zerod)
    except (ReductionError, OSError) as exc:
        stream.write(f"vasc_pipeline: error: {exc}\n")
        return 2
    return 1 if reduction.errors or reduction.damaged else 0


def _overrides_unlike_the_runs(cfg: Any, output_dir: Path) -> list[str]:
    """The command-line ``key=value`` overrides (Hydra's, when it runs) of keys the stored runs
    hold with another value: ``+stage=reduce physics.gamma=3`` on runs made with 2.1 would
    otherwise be ignored without a word. Sweep axes, output_dir, stage, sweep, cluster and
    checkpoint keys, and group choices, are not compared."""
    from omegaconf import OmegaConf

    from ..store import SWEEP_AXES, RunStore

    try:
        from hydra.core.hydra_config import HydraConfig

        overrides = list(HydraConfig.get().overrides.task)
    except (ImportError, ValueError):  # not under Hydra (a test, a script): nothing typed
        return []
    stored = None
    for path in sorted((output_dir / RUNS_DIR).glob("*.zarr")):
        try:
            stored = RunStore.open(path, mode="r").attrs.get("config") or {}
            break
        except StoreError:
            continue
    out = []
    for o in overrides:
        key = o.lstrip("+~").partition("=")[0]
        if "." not in key or key in SWEEP_AXES or key.split(".")[0] in ("sweep", "cluster", "checkpoint", "hydra"):
            continue
        node: Any = stored
        for part in key.split("."):
            node = node.get(part, KeyError) if isinstance(node, dict) else KeyError
        requested = OmegaConf.select(cfg, key, default=KeyError) if OmegaConf.is_config(cfg) else KeyError
        if node is not KeyError and requested is not KeyError and node != requested:
            out.append(f"{key}={requested} (the runs: {node})")
    return out
