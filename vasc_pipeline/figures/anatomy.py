"""``anatomy.png``: what a physiologist looks at first, every seed of every cell (the summary's ``/anatomy``).

Four panels against the cells: each inlet's share of the terminals (an artery under a fifth
is all but lost), the share of bifurcations off the organ, the terminal pressures (minimum and
median, with zero marked) and the crowns' scaling exponents beside Huo & Kassab's 3/7 and 3.
The best seed of each cell is drawn filled, the others open.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from ..reduce.anatomy import HUO_KASSAB_EXPONENTS, MMHG
from .style import cell_dims, cell_points, palette, save, styled, subplots

__all__ = ["plot_anatomy"]

ARTERY_FLOOR = 0.2  # an inlet feeding less than this share of the terminals is drawn against a line


def _label(point: dict) -> str:
    extra = [f"{k} {v}" for k, v in point.items() if k not in ("n_terminals", "m_b")]
    return "\n".join([f"N={int(point['n_terminals'])}", f"m_b={float(point['m_b']):.4g}", *extra])


@styled
def plot_anatomy(summary: xr.DataTree, path) -> Path | None:
    """Inlet shares, bifurcations off the organ, terminal pressures and crown exponents per cell and seed."""
    if "anatomy" not in summary.children:
        return None
    anatomy = summary["anatomy"].to_dataset()
    costs = summary["costs"].to_dataset()
    dims = cell_dims(summary)
    cells = [p for p in cell_points(anatomy, dims) if (costs["run_id"].sel(p) != "").any()]
    if not cells:
        return None
    fig, axes = subplots(1, 4, figsize=(max(11.0, 1.1 * len(cells) * 4), 3.2), squeeze=False)
    ax_share, ax_off, ax_pressure, ax_exponent = axes[0]
    x = np.arange(len(cells))
    inlets = list(anatomy.inlet.values)
    colors = palette(max(len(inlets), 3), "tab10")
    for i, point in enumerate(cells):
        a = anatomy.sel(point)
        present = (costs["run_id"].sel(point) != "").values
        best = costs["is_best"].sel(point).values.astype(bool) & present
        jitter = np.linspace(-0.15, 0.15, a.seed.size)
        for mask, fill in ((present & ~best, "none"), (best, None)):
            xs = i + jitter[mask]
            kw = {"s": 18, "linewidths": 0.8}
            for j, inlet in enumerate(inlets):
                share = a["inlet_share"].sel(inlet=inlet).values[mask]
                ax_share.scatter(xs, share, edgecolors=colors[j], facecolors=fill or colors[j], **kw)
            off = 100 * a["bifurcations_off_organ_share"].values[mask]
            ax_off.scatter(xs, off, edgecolors="0.2", facecolors=fill or "0.2", **kw)
            for name, c in (("terminal_pressure_min", "tab:red"), ("terminal_pressure_median", "tab:blue")):
                ax_pressure.scatter(xs, a[name].values[mask] / MMHG, edgecolors=c, facecolors=fill or c, **kw)
            for name, c in (("diameter_crown_length_exponent", "tab:green"), ("crown_volume_diameter_exponent", "k")):
                ax_exponent.scatter(xs, a[name].values[mask], edgecolors=c, facecolors=fill or c, **kw)
    for j, inlet in enumerate(inlets):
        ax_share.scatter([], [], color=colors[j], label=str(inlet))
    ax_share.axhline(ARTERY_FLOOR, color="0.5", linestyle=":", linewidth=0.8)
    ax_share.set(ylim=(-0.02, 1.02), ylabel="share of the terminals", title="arteries")
    ax_share.legend(loc="best")
    ax_off.set(ylabel="bifurcations > 2 mm off the organ [%]", title="vessels on the organ")
    ax_pressure.axhline(0.0, color="0.5", linestyle=":", linewidth=0.8)
    ax_pressure.scatter([], [], color="tab:red", label="minimum")
    ax_pressure.scatter([], [], color="tab:blue", label="median")
    ax_pressure.set(ylabel="terminal pressure [mmHg]", title="blood reaches the terminals")
    ax_pressure.legend(loc="best")
    hk = HUO_KASSAB_EXPONENTS
    ax_exponent.axhline(hk["diameter_crown_length"], color="tab:green", linestyle=":", linewidth=0.8)
    ax_exponent.axhline(hk["crown_volume_diameter"], color="k", linestyle=":", linewidth=0.8)
    ax_exponent.scatter([], [], color="tab:green", label="D_s ~ L_c^b (3/7)")
    ax_exponent.scatter([], [], color="k", label="V_c ~ D_s^b (3)")
    ax_exponent.set(yscale="log", ylabel="fitted exponent b", title="crown scaling (Huo & Kassab)")
    ax_exponent.legend(loc="best")
    for ax in axes[0]:
        ax.set_xticks(x)
        ax.set_xticklabels([_label(p) for p in cells], fontsize=7)
        ax.set_xlim(-0.5, len(cells) - 0.5)
        ax.grid(True, alpha=0.3)
    fig.subplots_adjust(wspace=0.45)
    fig.suptitle("Anatomy of every seed (filled: the cell's best)", fontsize=10, y=1.06)
    return save(fig, path)
