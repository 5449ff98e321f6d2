"""Figures across tree sizes: the paper's size scan, one panel per N, and the agreement with Kassab against N.

``size_scan.png`` (:func:`plot_size_scan`): element diameter (top row) and length (bottom
row) against order, one column per N, each with Kassab's RCA, LAD and LCX.
``agreement_vs_n.png`` (:func:`plot_agreement`): one number per N and artery, the mean over
orders of |log10 model/Kassab| (the summary's ``/comparison``), for diameter and length.
Both are drawn only when the sweep has trees at two or more N; the second, and Kassab's
arteries in the first, only for a heart (``tissue.organ``).
"""

from __future__ import annotations

from pathlib import Path

import xarray as xr

from .orders import KASSAB_STYLE, WHAT, against, every_n, kassab_of, kassab_points, model_points
from .style import order_axis, palette, point_text, save, styled, subplots

__all__ = ["plot_size_scan", "plot_agreement"]


@styled
def plot_size_scan(summary: xr.DataTree, path) -> Path | None:
    """Element diameter and length against order, one column per N, with Kassab's three arteries (a heart's)."""
    morph, point, ns = every_n(summary)
    if len(ns) < 2:
        return None
    kassab = kassab_of(summary)
    orders = morph.order.values
    orders = orders[orders >= 1]
    colors = palette(len(ns))
    fig, axes = subplots(2, len(ns), figsize=(2.6 * len(ns) + 0.6, 5.8), squeeze=False, sharex=True, sharey="row")
    for col, (n, color) in enumerate(zip(ns, colors)):
        for row, what in enumerate(("diameter", "length")):
            key, scale, ylabel = WHAT[what]
            ax = axes[row, col]
            kassab_points(ax, kassab, key, scale, orders)
            model_points(ax, morph, {**point, "n_terminals": n}, what, scale, color, f"model, N = {n}")
            ax.set_yscale("log")
            ax.grid(True, which="major", alpha=0.3)
            if col == 0:
                ax.set_ylabel(ylabel)
        axes[0, col].set_title(f"N = {n}")
        order_axis(axes[1, col], orders)
        axes[1, col].set_xlabel("order")
    fig.supxlabel("diameter-defined Strahler order (the model's trunk = 11)", fontsize=9)
    axes[0, 0].legend(loc="upper left", fontsize=6.5)
    fig.suptitle(f"Best tree per N{against(kassab)} ({point_text(point)}); mean ± SE", fontsize=9)
    fig.tight_layout()
    return save(fig, path)


@styled
def plot_agreement(summary: xr.DataTree, path) -> Path | None:
    """Mean |log10 model/Kassab| over orders against N, per artery; diameter and length panels."""
    _, point, ns = every_n(summary)
    if len(ns) < 2 or "comparison" not in summary.children:  # no heart: nothing was compared
        return None
    comparison = summary["comparison"].to_dataset().sel(point).sel(n_terminals=ns)
    fig, axes = subplots(1, 2, figsize=(7.4, 3.2), sharey=True)
    for ax, what in zip(axes, ("diameter", "length")):
        for artery, style in KASSAB_STYLE.items():
            values = comparison[f"mean_abs_log10_ratio_{what}"].sel(artery=artery).values
            ax.plot(ns, values, linewidth=1.2, markersize=5, label=artery, **style)
        ax.set_xscale("log")
        ax.set_xticks(ns, [str(n) for n in ns])
        ax.xaxis.set_minor_formatter("")
        ax.set_xlabel("terminals N")
        ax.set_title(f"element {what}")
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("mean over orders of |log$_{10}$ model/Kassab| [dex]")
    axes[0].set_ylim(bottom=0)
    axes[0].legend(loc="upper right")
    fig.suptitle(f"Agreement of the best tree with Kassab 1993 against N ({point_text(point)})", fontsize=9)
    fig.tight_layout()
    return save(fig, path)
