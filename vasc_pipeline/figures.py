"""Figures of a reduced sweep (matplotlib, Agg backend, PNG into ``<output_dir>/figures/``).

:func:`make_figures` draws everything from the summary DataTree of
:mod:`vasc_pipeline.reduce` (and, for the tree pictures, the best runs' stores)::

    import xarray as xr
    from vasc_pipeline.figures import make_figures
    make_figures(xr.open_datatree("results/smoke/summary.zarr", engine="zarr"), "results/smoke")

Files (each only when the sweep has what it needs):

- ``morphometry_vs_kassab.png``: element diameter and length against order (log y, SE
  bars) with Kassab's RCA, LAD and LCX; left the largest N, right every N.
- ``asymmetry.png``: D_s/D_p and D_l/D_p against parent order, every N, with the symmetric
  value 2^(-1/gamma).
- ``mb_effect.png`` (several m_b): diameter, length and both ratios against order for
  every m_b at the largest N.
- ``cost_traces.png``: annealed total cost against step, all seeds, one panel per cell.
- ``convergence.png`` (a steps axis): mean final cost ± standard error against steps.
- ``tree_<run_id>.png``: the best tree of every cell in projection, line width by radius,
  colour by inlet, tissue outline from the mask.

Units in the plots follow Kassab's tables (diameter in um, length in mm); the data stay SI.
"""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

import matplotlib
import matplotlib.ticker
import numpy as np
import xarray as xr
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

__all__ = [
    "make_figures",
    "plot_morphometry",
    "plot_asymmetry",
    "plot_mb_effect",
    "plot_cost_traces",
    "plot_convergence",
    "plot_tree",
    "REFERENCE_M_B",
]

REFERENCE_M_B = 641.3  # W m^-3, the physiological value: the m_b shown when a figure shows one
FIGURES_DIR = "figures"
_DPI = 200
_KASSAB_STYLE = {
    "RCA": dict(marker="o", color="0.15"),
    "LAD": dict(marker="s", color="0.45"),
    "LCX": dict(marker="^", color="0.65"),
}
_UM, _MM = 1e6, 1e3

# Our figures' style, applied inside each plotting function only (rc_context): importing this
# module or drawing a figure changes neither the caller's backend nor their rcParams. Figures
# are plain Figure objects (no pyplot state); savefig renders PNG with Agg, no display needed.
_STYLE = {
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 7.5,
    "legend.frameon": False,
    "savefig.bbox": "tight",
}


def _styled(func):
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(_STYLE):
            return func(*args, **kwargs)

    return wrapper


def _subplots(nrows: int = 1, ncols: int = 1, *, figsize, **kwargs):
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


# --------------------------------------------------------------------------------------------
# Selecting cells


def _cell_dims(summary: xr.DataTree) -> list[str]:
    return list(summary.attrs["cell_dims"])


def _reference_point(ds: xr.Dataset, dims: list[str], exclude: tuple[str, ...] = ()) -> dict:
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


def _present(morph: xr.Dataset, point: dict) -> bool:
    return bool(str(morph["best_run_id"].sel(point).values))


def _n_values(morph: xr.Dataset, point: dict) -> list[int]:
    """N values with a reduced tree at ``point`` (other dims fixed)."""
    return [int(n) for n in morph["n_terminals"].values if _present(morph, {**point, "n_terminals": n})]


def _colors(n: int, cmap: str = "viridis") -> list:
    cm = matplotlib.colormaps[cmap]
    if cmap == "tab10":
        return [cm(i % 10) for i in range(n)]
    # the light end of viridis/plasma is hard to see on white: stop at 0.8
    return [cm(0.05 + 0.75 * i / max(n - 1, 1)) for i in range(n)]


def _order_axis(ax, orders) -> None:
    lo, hi = int(min(orders)), int(max(orders))
    ax.set_xticks(range(lo, hi + 1))
    ax.set_xlim(lo - 0.5, hi + 0.5)
    ax.set_xlabel("order (diameter-defined Strahler; trunk = 11)")


def _mb_text(m_b: float) -> str:
    return f"m_b = {m_b:.4g} W m$^{{-3}}$"


def _point_text(point: dict) -> str:
    parts = []
    if "tissue" in point:
        parts.append(str(point["tissue"]))
    if "method" in point:
        parts.append(str(point["method"]))
    if "m_b" in point:
        parts.append(_mb_text(float(point["m_b"])))
    if "steps" in point:
        parts.append(f"{float(point['steps']):.3g} steps")
    return ", ".join(parts)


# --------------------------------------------------------------------------------------------
# Morphometry against Kassab


def _kassab(ax, kassab: xr.Dataset, what: str, scale: float, orders) -> None:
    ref = kassab.sel(level="element")
    for artery, style in _KASSAB_STYLE.items():
        r = ref.sel(artery=artery)
        mean, sd, n = r[f"{what}_mean"].values, r[f"{what}_sd"].values, r[f"{what}_n"].values
        ok = np.isfinite(mean) & np.isin(r.order.values, orders)
        with np.errstate(invalid="ignore", divide="ignore"):
            se = np.where(n > 1, sd / np.sqrt(np.maximum(n, 1)), np.nan)
        ax.errorbar(
            r.order.values[ok] + {"RCA": -0.12, "LAD": 0.0, "LCX": 0.12}[artery],
            mean[ok] * scale,
            yerr=np.nan_to_num(se[ok] * scale),
            linestyle="none",
            markersize=4,
            markerfacecolor="white",
            capsize=1.5,
            elinewidth=0.7,
            label=f"Kassab 1993 {artery}",
            **style,
        )


def _model(ax, morph: xr.Dataset, point: dict, what: str, scale: float, color, label: str) -> None:
    m = morph.sel(point).sel(scheme="diameter_defined")
    mean, se = m[f"element_{what}_mean"].values, m[f"element_{what}_se"].values
    ok = np.isfinite(mean)
    ax.errorbar(
        m.order.values[ok],
        mean[ok] * scale,
        yerr=np.nan_to_num(se[ok] * scale),
        color=color,
        marker="o",
        markersize=3.5,
        linewidth=1.4,
        capsize=2,
        elinewidth=0.9,
        label=label,
    )


_WHAT = {"diameter": ("D", _UM, "element diameter [µm]"), "length": ("L", _MM, "element length [mm]")}


@_styled
def plot_morphometry(summary: xr.DataTree, path) -> Path | None:
    """Element diameter and length against order with Kassab's RCA/LAD/LCX; largest N and every N."""
    morph = summary["morphometry"].to_dataset()
    kassab = summary["kassab"].to_dataset()
    dims = _cell_dims(summary)
    point = _reference_point(morph, dims, exclude=("n_terminals",))
    ns = _n_values(morph, point)
    if not ns:
        return None
    orders = morph.order.values
    orders = orders[orders >= 1]
    ncols = 2 if len(ns) > 1 else 1
    fig, axes = _subplots(2, ncols, figsize=(3.6 * ncols + 0.4, 6.2), squeeze=False, sharex=True, sharey="row")
    colors = _colors(len(ns))
    for row, what in enumerate(("diameter", "length")):
        key, scale, ylabel = _WHAT[what]
        ax = axes[row, 0]
        _kassab(ax, kassab, key, scale, orders)
        _model(ax, morph, {**point, "n_terminals": ns[-1]}, what, scale, "C3", f"model, N = {ns[-1]}")
        if ncols == 2:
            ax2 = axes[row, 1]
            _kassab(ax2, kassab, key, scale, orders)
            for n, c in zip(ns, colors):
                _model(ax2, morph, {**point, "n_terminals": n}, what, scale, c, f"model, N = {n}")
        axes[row, 0].set_ylabel(ylabel)
        for a in axes[row]:
            a.set_yscale("log")
            a.grid(True, which="major", alpha=0.3)
    for a in axes[-1]:
        _order_axis(a, orders)
    axes[0, 0].set_title(f"largest tree (N = {ns[-1]})")
    if ncols == 2:
        axes[0, 1].set_title("every N")
    for a in axes[0]:
        a.legend(loc="upper left")
    fig.suptitle(f"Best tree per cell against pig coronary arteries ({_point_text(point)}); mean ± SE", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def _ratio(ax, asym: xr.Dataset, point: dict, which: str, color, label: str) -> None:
    a = asym.sel(point).sel(scheme="diameter_defined")
    mean, se = a[f"diameter_ratio_{which}_mean"].values, a[f"diameter_ratio_{which}_se"].values
    ok = np.isfinite(mean)
    ax.errorbar(
        a.order.values[ok],
        mean[ok],
        yerr=np.nan_to_num(se[ok]),
        color=color,
        marker="o",
        markersize=3.5,
        linewidth=1.2,
        capsize=2,
        elinewidth=0.8,
        label=label,
    )


_RATIO_LABEL = {"small": ("smaller daughter", "D$_s$/D$_p$"), "large": ("larger daughter", "D$_l$/D$_p$")}


def _ratio_panels(axes, asym, points_labels, colors, orders) -> None:
    for ax, which in zip(axes, ("small", "large")):
        for (point, label), c in zip(points_labels, colors):
            _ratio(ax, asym, point, which, c, label)
        sym = float(asym["symmetric_ratio"].sel(points_labels[0][0]))
        ax.axhline(sym, color="0.4", linestyle="--", linewidth=0.9, label=f"symmetric, 2$^{{-1/\\gamma}}$ = {sym:.3f}")
        ax.set_title(f"{_RATIO_LABEL[which][0]} / parent diameter")
        ax.set_ylabel(_RATIO_LABEL[which][1] + " [1]")
        ax.set_ylim(0, 1.05)
        ax.grid(True, alpha=0.3)
        _order_axis(ax, orders)
        ax.set_xlabel("parent order (diameter-defined Strahler; trunk = 11)")


@_styled
def plot_asymmetry(summary: xr.DataTree, path) -> Path | None:
    """D_s/D_p and D_l/D_p against parent order for every N (m_b nearest 641.3)."""
    asym = summary["asymmetry"].to_dataset()
    morph = summary["morphometry"].to_dataset()
    dims = _cell_dims(summary)
    point = _reference_point(morph, dims, exclude=("n_terminals",))
    ns = _n_values(morph, point)
    if not ns:
        return None
    counts = asym["bifurcation_count"].sel(point).sel(scheme="diameter_defined")
    orders = asym.order.values[(counts > 0).any("n_terminals").values]
    fig, axes = _subplots(1, 2, figsize=(8.2, 3.4))
    _ratio_panels(axes, asym, [({**point, "n_terminals": n}, f"N = {n}") for n in ns], _colors(len(ns)), orders)
    axes[0].legend(loc="lower left")
    fig.suptitle(f"Bifurcation asymmetry of the best trees ({_point_text(point)}); mean ± SE", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


@_styled
def plot_mb_effect(summary: xr.DataTree, path) -> Path | None:
    """Diameter, length and both ratios against order for every m_b at the largest N."""
    morph = summary["morphometry"].to_dataset()
    if "m_b" not in morph.dims or morph.sizes["m_b"] < 2:
        return None
    asym = summary["asymmetry"].to_dataset()
    kassab = summary["kassab"].to_dataset()
    dims = _cell_dims(summary)
    base = _reference_point(morph, dims, exclude=("m_b", "n_terminals"))
    n = int(morph.n_terminals.values.max())
    mbs = [float(m) for m in morph.m_b.values if _present(morph, {**base, "n_terminals": n, "m_b": m})]
    if len(mbs) < 2:
        return None
    colors = _colors(len(mbs), "plasma")
    orders = morph.order.values[morph.order.values >= 1]
    fig, axes = _subplots(2, 2, figsize=(8.2, 6.6))
    for ax, what in zip(axes[0], ("diameter", "length")):
        key, scale, ylabel = _WHAT[what]
        _kassab(ax, kassab, key, scale, orders)
        for m, c in zip(mbs, colors):
            _model(ax, morph, {**base, "n_terminals": n, "m_b": m}, what, scale, c, _mb_text(m))
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        _order_axis(ax, orders)
    axes[0, 0].legend(loc="upper left")
    counts = asym["bifurcation_count"].sel({**base, "n_terminals": n}).sel(scheme="diameter_defined")
    ratio_orders = asym.order.values[(counts > 0).any("m_b").values]
    _ratio_panels(
        axes[1], asym, [({**base, "n_terminals": n, "m_b": m}, _mb_text(m)) for m in mbs], colors, ratio_orders
    )
    axes[1, 0].legend(loc="lower left")
    fig.suptitle(
        f"Effect of the blood cost m_b on the best tree (N = {n}"
        + (f", {_point_text(base)}" if base else "")
        + "); mean ± SE",
        fontsize=9,
    )
    fig.tight_layout()
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# Costs


def _cells(ds: xr.Dataset, dims: list[str]) -> list[dict]:
    """Every cell point of the grid, in coordinate order."""
    import itertools

    return [dict(zip(dims, values)) for values in itertools.product(*(ds[d].values for d in dims))]


def _cell_title(point: dict) -> str:
    parts = [str(point["tissue"])] if "tissue" in point else []
    if "method" in point:
        parts.append(str(point["method"]))
    parts.append(f"N = {int(point['n_terminals'])}")
    parts.append(f"m_b = {float(point['m_b']):.4g}")
    if "steps" in point:
        parts.append(f"{float(point['steps']):.3g} steps")
    return ", ".join(parts)


@_styled
def plot_cost_traces(summary: xr.DataTree, path, max_panels: int = 24) -> Path | None:
    """Annealed total cost against step, every seed, one panel per cell (the best seed drawn bold)."""
    traces = summary["traces"].to_dataset()
    costs = summary["costs"].to_dataset()
    dims = _cell_dims(summary)
    cells = [p for p in _cells(traces, dims) if (traces["trace_length"].sel(p) > 0).any()][:max_panels]
    if not cells:
        return None
    ncols = min(4, len(cells))
    nrows = math.ceil(len(cells) / ncols)
    fig, axes = _subplots(nrows, ncols, figsize=(2.9 * ncols + 0.4, 2.5 * nrows + 0.3), squeeze=False)
    seeds = traces.seed.values
    colors = _colors(len(seeds), "tab10" if len(seeds) <= 10 else "viridis")
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
        ax.set_title(_cell_title(point), fontsize=8)
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
    return _save(fig, path)


def _sci(value: float) -> str:
    """1e5 -> '$10^{5}$', 3e5 -> '$3{\\times}10^{5}$' (tick labels)."""
    exp = int(math.floor(math.log10(value)))
    mant = value / 10**exp
    if abs(mant - 1) < 1e-9:
        return f"$10^{{{exp}}}$"
    return f"${mant:.3g}{{\\times}}10^{{{exp}}}$"


@_styled
def plot_convergence(summary: xr.DataTree, path) -> Path | None:
    """Mean final cost ± standard error over seeds against the number of steps (the paper's appendix)."""
    costs = summary["costs"].to_dataset()
    dims = _cell_dims(summary)
    if "steps" not in dims or costs.sizes["steps"] < 2:
        return None
    others = [d for d in dims if d != "steps"]
    groups = _cells(costs, others) if others else [{}]
    fig, axes = _subplots(1, 2, figsize=(8.2, 3.4))
    colors = _colors(len(groups), "tab10" if len(groups) <= 10 else "viridis")  # categories, not a scale
    steps = costs.steps.values.astype(float)
    panels = (
        (costs["cost_total"], f"final annealed total cost C [{costs['cost_total'].attrs.get('units', '')}]"),
        (costs["cost_volume"] + costs["cost_power"], "final C$_v$ + C$_w$ [W]"),
    )
    drawn = False
    for ax, (values, ylabel) in zip(axes, panels):
        for point, c in zip(groups, colors):
            v = values.sel(point)
            n = v.notnull().sum("seed")
            mean = v.mean("seed")
            se = v.std("seed", ddof=1) / np.sqrt(n.where(n > 0))
            ok = (n > 0).values
            if not ok.any():
                continue
            drawn = True
            label = ", ".join(
                p
                for p in (
                    _cell_title(
                        {**point, "n_terminals": point.get("n_terminals", 0), "m_b": point.get("m_b", math.nan)}
                    ),
                )
                if p
            )
            ax.errorbar(
                steps[ok],
                mean.values[ok],
                yerr=np.nan_to_num(se.values[ok]),
                color=c,
                marker="o",
                markersize=4,
                capsize=2.5,
                linewidth=1.2,
                label=f"{label} (n = {int(n.max())} seeds)",
            )
        ax.set_xscale("log")
        # ticks at the sweep's step counts (minor log labels crowd, major ones may be absent)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xticks(steps, [_sci(v) for v in steps])
        ax.set_xlabel("proposed moves per run")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    if not drawn:
        return None
    fig.suptitle("Convergence: mean final cost ± standard error over seeds", fontsize=9)
    fig.tight_layout()
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(2, len(labels)))
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# Trees


@_styled
def plot_tree(store_path, path, title: str | None = None) -> Path:
    """The final tree of a run store in projection: line width by radius, colour by inlet, tissue outline.

    A 3-D tree gets three panels (x-y, x-z, y-z); a 2-D one (single voxel layer) one.
    """
    from .morphometry import inlet_of
    from .store import RunStore

    store = RunStore.open(store_path, mode="r")
    tree = store.read_tree()
    mask_arr = store.group["tissue/mask"]
    mask = mask_arr[...].astype(bool)  # (z, y, x)
    t_attrs = dict(store.group["tissue"].attrs)
    h = float(t_attrs["voxel_size"])
    origin = np.asarray(t_attrs["origin"], dtype=float)
    parent, pos, radius = tree["parent"], tree["position"] * _MM, tree["radius"]
    seg = np.flatnonzero(parent >= 0)
    inlet = inlet_of(parent)
    inlets = np.flatnonzero(parent < 0)
    flat = mask.shape[0] == 1
    views = [("x", "y", 0)] if flat else [("x", "y", 0), ("x", "z", 1), ("y", "z", 2)]
    axis_of = {"x": 0, "y": 1, "z": 2}
    # mask axes are (z, y, x): project along the axis not shown
    mask_axis = {0: 0, 1: 1, 2: 2}  # view index -> mask axis to collapse (z for x-y, y for x-z, x for y-z)
    fig, axes = _subplots(1, len(views), figsize=(3.4 * len(views) + 0.6, 3.6), squeeze=False)
    rmax = float(radius[seg].max())
    widths = 0.25 + 3.5 * radius[seg] / rmax
    colors = matplotlib.colormaps["tab10"]
    for ax, (a, b, vi) in zip(axes[0], views):
        proj = mask.any(axis=mask_axis[vi])  # 2-D array (rows, cols)
        # rows/cols of the projection: x-y -> (y, x); x-z -> (z, x); y-z -> (z, y)
        col_axis, row_axis = axis_of[a], axis_of[b]
        cols = (origin[col_axis] + h * np.arange(proj.shape[1])) * _MM
        rows = (origin[row_axis] + h * np.arange(proj.shape[0])) * _MM
        if proj.any() and not proj.all() and min(proj.shape) > 1:
            ax.contourf(cols, rows, proj.astype(float), levels=[0.5, 1.5], colors=["0.93"])
            ax.contour(cols, rows, proj.astype(float), levels=[0.5], colors=["0.55"], linewidths=0.7)
        elif proj.any():  # a full rectangle: draw its frame
            ax.add_patch(
                Rectangle(
                    (cols[0] - h * _MM / 2, rows[0] - h * _MM / 2),
                    cols[-1] - cols[0] + h * _MM,
                    rows[-1] - rows[0] + h * _MM,
                    facecolor="0.93",
                    edgecolor="0.55",
                    linewidth=0.7,
                )
            )
        # thin vessels first so that trunks stay on top
        order = np.argsort(radius[seg])
        s = seg[order]
        lines = np.stack([pos[parent[s]][:, [col_axis, row_axis]], pos[s][:, [col_axis, row_axis]]], axis=1)
        lc = LineCollection(
            lines,
            linewidths=widths[order],
            colors=[colors(int(np.searchsorted(inlets, inlet[v])) % 10) for v in s],
            capstyle="round",
        )
        ax.add_collection(lc)
        ax.plot(pos[inlets, col_axis], pos[inlets, row_axis], "k*", markersize=7, zorder=5)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel(f"{a} [mm]")
        ax.set_ylabel(f"{b} [mm]")
    # The store names the inlets (stores older than that: the heart's, known by its name).
    names = t_attrs.get("inlet_names") or {"heart": ("LCA", "RCA")}.get(str(t_attrs.get("name")), ())
    handles = [
        Line2D(
            [], [], color=colors(i % 10), linewidth=2, label=f"{names[i]} tree" if i < len(names) else f"inlet {i} tree"
        )
        for i in range(len(inlets))
    ]
    handles.append(Line2D([], [], color="k", marker="*", linestyle="none", label="inlet"))
    axes[0, -1].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7)
    fig.suptitle(title or store.run_id, fontsize=9)
    fig.text(
        0.5,
        -0.02,
        f"line width ∝ vessel radius (thickest: {2 * rmax * _MM:.2g} mm diameter); grey: tissue "
        "(projection of the voxel mask)",
        ha="center",
        fontsize=7,
    )
    fig.tight_layout()
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# All of them


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}.png")
    fig.savefig(tmp, dpi=_DPI)
    os.replace(tmp, path)
    return path


def make_figures(summary: xr.DataTree, output_dir) -> list[Path]:
    """Draw every figure that the sweep supports into ``<output_dir>/figures/``; returns the paths.

    Parameters
    ----------
    summary : xarray.DataTree
        From :func:`vasc_pipeline.reduce.build_summary` or ``xarray.open_datatree(summary.zarr)``.
    output_dir : path
        The sweep's output directory (the tree pictures read ``runs/<run_id>.zarr``).
    """
    from .store import run_path

    out = Path(output_dir) / FIGURES_DIR
    paths = []
    for func, name in (
        (plot_morphometry, "morphometry_vs_kassab.png"),
        (plot_asymmetry, "asymmetry.png"),
        (plot_mb_effect, "mb_effect.png"),
        (plot_cost_traces, "cost_traces.png"),
        (plot_convergence, "convergence.png"),
    ):
        p = func(summary, out / name)
        if p is not None:
            paths.append(p)
    morph = summary["morphometry"].to_dataset()
    for point in _cells(morph, _cell_dims(summary)):
        run_id = str(morph["best_run_id"].sel(point).values)
        if not run_id:
            continue
        cost = float(morph["best_cost"].sel(point))
        title = f"{run_id}: best of {int(morph['n_seeds'].sel(point))} seeds, cost {cost:.4g} ({_cell_title(point)})"
        paths.append(plot_tree(run_path(output_dir, run_id), out / f"tree_{run_id}.png", title))
    return paths
