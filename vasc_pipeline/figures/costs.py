"""Cost figures: the cost traces of every seed, and the convergence of the final cost with the step count.

``cost_traces.png`` (:func:`plot_cost_traces`, from the summary's ``/traces`` and ``/costs``)
and ``convergence.png`` (:func:`plot_convergence`, a sweep with a steps axis);
:func:`plot_convergence_studies` puts the convergence of several sweeps (say the paper's
schedule and ``fast``, one output_dir each) on one plot.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import matplotlib.ticker
import numpy as np
import xarray as xr

from .style import cell_dims, cell_points, cell_title, palette, save, styled, subplots

__all__ = ["plot_cost_traces", "plot_convergence", "plot_convergence_studies"]


@styled
def plot_cost_traces(summary: xr.DataTree, path, max_panels: int = 24) -> Path | None:
    """Annealed total cost against step, every seed, one panel per cell (the best seed drawn bold).
    None for a summary kept without its traces (``results/paper``'s)."""
    if "traces" not in summary.children:
        return None
    traces = summary["traces"].to_dataset()
    costs = summary["costs"].to_dataset()
    dims = cell_dims(summary)
    cells = [p for p in cell_points(traces, dims) if (traces["trace_length"].sel(p) > 0).any()][:max_panels]
    if not cells:
        return None
    ncols = min(4, len(cells))
    nrows = math.ceil(len(cells) / ncols)
    fig, axes = subplots(nrows, ncols, figsize=(2.9 * ncols + 0.4, 2.5 * nrows + 0.3), squeeze=False)
    seeds = traces.seed.values
    colors = palette(len(seeds), "tab10" if len(seeds) <= 10 else "viridis")
    for ax, point in zip(axes.flat, cells):
        t = traces.sel(point)
        best = costs["is_best"].sel(point).values
        for i, s in enumerate(seeds):
            k = int(t["trace_length"].sel(seed=s))
            if k == 0:
                continue
            step = t["step"].sel(seed=s).values[:k]
            total = t["total"].sel(seed=s).values[:k]
            keep = step > 0  # log step axis: the initial record (step 0) is left out
            step, total = step[keep], total[keep]
            ax.plot(
                step,
                total,
                color=colors[i],
                linewidth=1.8 if best[i] else 0.8,
                label=f"seed {int(s)}" + (" (best)" if best[i] else ""),
            )
        positive = t["total"].values[np.isfinite(t["total"].values)]
        if positive.size and positive.min() > 0 and positive.max() / positive.min() > 20:
            ax.set_yscale("log")
        ax.set_title(cell_title(point), fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.legend(loc="upper right", fontsize=6.5)
    for ax in axes.flat[len(cells) :]:
        ax.set_visible(False)
    units = traces["total"].attrs.get("units", "")
    for ax in axes[:, 0]:
        ax.set_ylabel(f"annealed total cost C [{units}]")
    for ax in axes[-1]:
        ax.set_xlabel("proposed moves (step, log)")
    fig.suptitle("Cost against step, all seeds", fontsize=9)
    fig.tight_layout()
    return save(fig, path)


def _sci(value: float) -> str:
    """1e5 -> '$10^{5}$', 3e5 -> '$3{\\times}10^{5}$' (tick labels)."""
    exp = int(math.floor(math.log10(value)))
    mant = value / 10**exp
    if abs(mant - 1) < 1e-9:
        return f"$10^{{{exp}}}$"
    return f"${mant:.3g}{{\\times}}10^{{{exp}}}$"


def _convergence_series(summary: xr.DataTree, prefix: str = "") -> list[tuple[str, np.ndarray, list]]:
    """(label, steps, [per panel: (n, mean, se) over seeds]) for every cell group without the steps axis."""
    costs = summary["costs"].to_dataset()
    dims = cell_dims(summary)
    if "steps" not in dims or costs.sizes["steps"] < 2:
        return []
    others = [d for d in dims if d != "steps"]
    steps = costs.steps.values.astype(float)
    series = []
    for point in cell_points(costs, others) if others else [{}]:
        panels = []
        for values in (costs["cost_total"], costs["cost_volume"] + costs["cost_power"]):
            v = values.sel(point)
            n = v.notnull().sum("seed")
            se = v.std("seed", ddof=1) / np.sqrt(n.where(n > 0))
            panels.append((n.values, v.mean("seed").values, se.values))
        label = cell_title({**point, "n_terminals": point.get("n_terminals", 0), "m_b": point.get("m_b", math.nan)})
        series.append((f"{prefix}{label}", steps, panels))
    return series


def _draw_convergence(series, path, units: str, title: str) -> Path | None:
    fig, axes = subplots(1, 2, figsize=(8.2, 3.4))
    colors = palette(len(series), "tab10" if len(series) <= 10 else "viridis")  # categories, not a scale
    ylabels = (f"final annealed total cost C [{units}]", "final C$_v$ + C$_w$ [W]")
    drawn, all_steps = False, set()
    for (label, steps, panels), c in zip(series, colors):
        for ax, (n, mean, se) in zip(axes, panels):
            ok = n > 0
            if not ok.any():
                continue
            drawn = True
            all_steps.update(steps[ok].tolist())
            ax.errorbar(
                steps[ok],
                mean[ok],
                yerr=np.nan_to_num(se[ok]),
                color=c,
                marker="o",
                markersize=4,
                capsize=2.5,
                linewidth=1.2,
                label=f"{label} (n = {int(n.max())} seeds)",
            )
    if not drawn:
        return None
    ticks = sorted(all_steps)
    for ax, ylabel in zip(axes, ylabels):
        ax.set_xscale("log")
        # ticks at the sweep's step counts (minor log labels crowd, major ones may be absent)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xticks(ticks, [_sci(v) for v in ticks])
        ax.set_xlabel("proposed moves per run")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(2, len(labels)))
    return save(fig, path)


_CONVERGENCE_TITLE = "Convergence: mean final cost ± standard error over seeds"


@styled
def plot_convergence(summary: xr.DataTree, path) -> Path | None:
    """Mean final cost ± standard error over seeds against the number of steps (the paper's appendix)."""
    units = summary["costs"]["cost_total"].attrs.get("units", "")
    return _draw_convergence(_convergence_series(summary), path, units, _CONVERGENCE_TITLE)


@styled
def plot_convergence_studies(summaries: Mapping[str, xr.DataTree], path) -> Path | None:
    """:func:`plot_convergence` of several sweeps on one plot, e.g. ``{"paper": ..., "fast": ...}``.

    Each sweep's cells are labelled with its key; the sweeps should share the tissue and N
    (different schedules on one problem), or the costs are not comparable.
    """
    series = [s for label, summary in summaries.items() for s in _convergence_series(summary, f"{label}: ")]
    if not series:
        return None
    units = next(iter(summaries.values()))["costs"]["cost_total"].attrs.get("units", "")
    return _draw_convergence(series, path, units, _CONVERGENCE_TITLE + ", " + " vs ".join(summaries))
