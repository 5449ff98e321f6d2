"""Figures of a reduced sweep (matplotlib, Agg backend, PNG into ``<output_dir>/figures/``).

:func:`make_figures` draws everything from the summary DataTree of
:mod:`vasc_pipeline.reduce.summary` (and, for the tree pictures, the best runs' stores)::

    import xarray as xr
    from vasc_pipeline.figures import make_figures
    make_figures(xr.open_datatree("results/smoke/summary.zarr", engine="zarr"), "results/smoke")

Files (each only when the sweep has what it needs):

- ``morphometry_vs_kassab.png``: element diameter and length against order (log y, SE
  bars) with Kassab's RCA, LAD and LCX; left the largest N, right every N. For a tissue
  that is no heart (``tissue.organ``) ``morphometry.png``, without Kassab's arteries (as the
  other figures), and no ``agreement_vs_n.png``.
- ``asymmetry.png``: D_s/D_p and D_l/D_p against parent order, every N, with the symmetric
  value 2^(-1/gamma).
- ``mb_effect.png`` (several m_b): diameter, length and both ratios against order for
  every m_b at the largest N.
- ``cost_traces.png``: annealed total cost against step, all seeds, one panel per cell.
- ``convergence.png`` (a steps axis): mean final cost ± standard error against steps.
- ``consistency.png`` (a steps axis, two or more seeds): the trees of up to four seeds at
  every step count, each row with its ``trunk_spread`` (how far apart the seeds' main trunks are).
- ``size_scan.png`` and ``agreement_vs_n.png`` (two or more N): diameter and length against
  order, one column per N, with Kassab's arteries; mean |log10 model/Kassab| against N.
- ``anatomy.png``: each inlet's share of the terminals, bifurcations off the organ, terminal
  pressures and the crowns' scaling exponents, every seed of every cell.
- ``tree_<run_id>.png``: the best tree of every cell in projection, line width by radius,
  colour by inlet, tissue outline from the mask.

Units in the plots follow Kassab's tables (diameter in um, length in mm); the data stay SI.
The figures live in :mod:`~vasc_pipeline.figures.orders`, :mod:`~vasc_pipeline.figures.costs` and
:mod:`~vasc_pipeline.figures.trees` and :mod:`~vasc_pipeline.figures.anatomy`, their shared style in
:mod:`~vasc_pipeline.figures.style`.
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from ..store.layout import FIGURES_DIR
from .anatomy import plot_anatomy
from .costs import plot_convergence, plot_convergence_studies, plot_cost_traces
from .orders import plot_asymmetry, plot_mb_effect, plot_morphometry
from .sizes import plot_agreement, plot_size_scan
from .style import REFERENCE_M_B, cell_dims, cell_points, cell_title
from .trees import plot_consistency, plot_tree

__all__ = [
    "make_figures",
    "plot_morphometry",
    "plot_asymmetry",
    "plot_mb_effect",
    "plot_cost_traces",
    "plot_convergence",
    "plot_convergence_studies",
    "plot_size_scan",
    "plot_agreement",
    "plot_consistency",
    "plot_tree",
    "plot_anatomy",
    "REFERENCE_M_B",
]


def make_figures(summary: xr.DataTree, output_dir) -> list[Path]:
    """Draw every figure that the sweep supports into ``<output_dir>/figures/``; returns the paths.

    Parameters
    ----------
    summary : xarray.DataTree
        From :func:`vasc_pipeline.reduce.summary.build_summary` or ``xarray.open_datatree(summary.zarr)``.
    output_dir : path
        The sweep's output directory (the tree pictures read ``runs/<run_id>.zarr``).
    """
    from ..store.layout import run_path

    out = Path(output_dir) / FIGURES_DIR
    paths = []
    heart = "kassab" in summary.children  # tissue.organ: Kassab's pig coronaries drawn for a heart only
    for func, name in (
        (plot_morphometry, "morphometry_vs_kassab.png" if heart else "morphometry.png"),
        (plot_asymmetry, "asymmetry.png"),
        (plot_mb_effect, "mb_effect.png"),
        (plot_cost_traces, "cost_traces.png"),
        (plot_convergence, "convergence.png"),
        (plot_size_scan, "size_scan.png"),
        (plot_agreement, "agreement_vs_n.png"),
        (plot_anatomy, "anatomy.png"),
    ):
        p = func(summary, out / name)
        if p is not None:
            paths.append(p)
    p = plot_consistency(summary, output_dir, out / "consistency.png")
    if p is not None:
        paths.append(p)
    morph = summary["morphometry"].to_dataset()
    for point in cell_points(morph, cell_dims(summary)):
        run_id = str(morph["best_run_id"].sel(point).values)
        if not run_id:
            continue
        cost = float(morph["best_cost"].sel(point))
        title = f"{run_id}: best of {int(morph['n_seeds'].sel(point))} seeds, cost {cost:.4g} ({cell_title(point)})"
        paths.append(plot_tree(run_path(output_dir, run_id), out / f"tree_{run_id}.png", title))
    return paths
