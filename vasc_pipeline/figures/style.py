"""What every figure shares: the style (per figure, never global), Figure objects, saving, which cells to show.

Importing the figures or drawing one changes neither the caller's matplotlib backend nor
their rcParams: :func:`styled` applies :data:`STYLE` in an ``rc_context`` around each plotting
function, :func:`subplots` makes a plain ``Figure`` (no pyplot state) and :func:`save` renders it
to PNG with Agg, atomically. The cell helpers pick what a figure shows from the summary's cell
grid (:func:`reference_point`: m_b nearest :data:`REFERENCE_M_B`, most steps, first tissue).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import matplotlib
import numpy as np
import xarray as xr
from matplotlib.figure import Figure

__all__ = [
    "REFERENCE_M_B",
    "STYLE",
    "UM",
    "MM",
    "styled",
    "subplots",
    "save",
    "cell_dims",
    "cell_points",
    "reference_point",
    "present",
    "n_values",
    "palette",
    "order_axis",
    "mb_text",
    "point_text",
    "cell_title",
]

REFERENCE_M_B = 641.3  # W m^-3, the physiological value: the m_b shown when a figure shows one
DPI = 200
# Tree pictures: thousands of thin lines compress badly, and results/paper tracks one per cell.
TREE_DPI = 120
UM, MM = 1e6, 1e3  # plot units of Kassab's tables: diameters in um, lengths in mm (the data stay SI)

# Our figures' style, applied inside each plotting function only (rc_context): importing the
# figures or drawing a figure changes neither the caller's backend nor their rcParams. Figures
# are plain Figure objects (no pyplot state); savefig renders PNG with Agg, no display needed.
STYLE = {
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 7.5,
    "legend.frameon": False,
    "savefig.bbox": "tight",
}


def styled(func):
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(STYLE):
            return func(*args, **kwargs)

    return wrapper


def subplots(nrows: int = 1, ncols: int = 1, *, figsize, **kwargs):
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save(fig, path, dpi: int = DPI) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}.png")
    fig.savefig(tmp, dpi=dpi)
    os.replace(tmp, path)
    return path


def cell_dims(summary: xr.DataTree) -> list[str]:
    return list(summary.attrs["cell_dims"])


def cell_points(ds: xr.Dataset, dims: list[str]) -> list[dict]:
    """Every cell point of the grid, in coordinate order."""
    import itertools

    return [dict(zip(dims, values)) for values in itertools.product(*(ds[d].values for d in dims))]


def reference_point(ds: xr.Dataset, dims: list[str], exclude: tuple[str, ...] = ()) -> dict:
    """The cell shown when a figure shows one: m_b nearest 641.3, most steps, first tissue."""
    point = {}
    if "m_b" in dims and "m_b" not in exclude:
        values = ds["m_b"].values
        point["m_b"] = values[np.argmin(np.abs(np.log(values / REFERENCE_M_B)))]
    if "steps" in dims and "steps" not in exclude:
        point["steps"] = ds["steps"].values.max()
    if "tissue" in dims and "tissue" not in exclude:
        point["tissue"] = ds["tissue"].values[0]
    if "method" in dims and "method" not in exclude:  # "anneal" sorts first
        point["method"] = ds["method"].values[0]
    return point


def present(morph: xr.Dataset, point: dict) -> bool:
    return bool(str(morph["best_run_id"].sel(point).values))


def n_values(morph: xr.Dataset, point: dict) -> list[int]:
    """N values with a reduced tree at ``point`` (other dims fixed)."""
    return [int(n) for n in morph["n_terminals"].values if present(morph, {**point, "n_terminals": n})]


def palette(n: int, cmap: str = "viridis") -> list:
    cm = matplotlib.colormaps[cmap]
    if cmap == "tab10":
        return [cm(i % 10) for i in range(n)]
    # the light end of viridis/plasma is hard to see on white: stop at 0.8
    return [cm(0.05 + 0.75 * i / max(n - 1, 1)) for i in range(n)]


def order_axis(ax, orders) -> None:
    lo, hi = int(min(orders)), int(max(orders))
    ax.set_xticks(range(lo, hi + 1))
    ax.set_xlim(lo - 0.5, hi + 0.5)
    ax.set_xlabel("order (diameter-defined Strahler; trunk = 11)")


def mb_text(m_b: float) -> str:
    return f"m_b = {m_b:.4g} W m$^{{-3}}$"


def point_text(point: dict) -> str:
    parts = []
    if "tissue" in point:
        parts.append(str(point["tissue"]))
    if "method" in point:
        parts.append(str(point["method"]))
    if "m_b" in point:
        parts.append(mb_text(float(point["m_b"])))
    if "steps" in point:
        parts.append(f"{float(point['steps']):.3g} steps")
    return ", ".join(parts)


def cell_title(point: dict) -> str:
    parts = [str(point["tissue"])] if "tissue" in point else []
    if "method" in point:
        parts.append(str(point["method"]))
    parts.append(f"N = {int(point['n_terminals'])}")
    parts.append(f"m_b = {float(point['m_b']):.4g}")
    if "steps" in point:
        parts.append(f"{float(point['steps']):.3g} steps")
    return ", ".join(parts)
