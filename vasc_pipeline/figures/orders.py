"""Order-wise figures: morphometry against Kassab 1993, bifurcation asymmetry, and the effect of m_b.

``morphometry_vs_kassab.png`` (:func:`plot_morphometry`; ``morphometry.png`` for a tissue
that is no heart), ``asymmetry.png`` (:func:`plot_asymmetry`) and ``mb_effect.png``
(:func:`plot_mb_effect`), drawn from the summary's ``/morphometry``, ``/asymmetry`` and
``/kassab`` groups (Kassab's arteries only where the summary has them: a heart's).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from .style import (
    MM,
    UM,
    cell_dims,
    mb_text,
    n_values,
    order_axis,
    palette,
    point_text,
    present,
    reference_point,
    save,
    styled,
    subplots,
)

__all__ = ["plot_morphometry", "plot_asymmetry", "plot_mb_effect"]

KASSAB_STYLE = {
    "RCA": dict(marker="o", color="0.15"),
    "LAD": dict(marker="s", color="0.45"),
    "LCX": dict(marker="^", color="0.65"),
}


def kassab_of(summary: xr.DataTree) -> xr.Dataset | None:
    """The summary's ``/kassab`` group, or None for a tissue that is no heart (``tissue.organ``)."""
    return summary["kassab"].to_dataset() if "kassab" in summary.children else None


def against(kassab: xr.Dataset | None) -> str:
    """The words a title adds when Kassab's arteries are drawn."""
    return " against pig coronary arteries" if kassab is not None else ""


def kassab_points(ax, kassab: xr.Dataset | None, what: str, scale: float, orders) -> None:
    """Kassab's RCA, LAD and LCX element means ± SE; nothing for a tissue that is no heart (None)."""
    if kassab is None:
        return
    ref = kassab.sel(level="element")
    for artery, style in KASSAB_STYLE.items():
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


def _mean_se(
    ax, ds: xr.Dataset, point: dict, name: str, scale: float, color, label: str, linewidth: float, elinewidth: float
) -> None:
    """``<name>_mean`` ± ``<name>_se`` (times ``scale``) against order: the diameter-defined orders at ``point``."""
    d = ds.sel(point).sel(scheme="diameter_defined")
    mean, se = d[f"{name}_mean"].values, d[f"{name}_se"].values
    ok = np.isfinite(mean)
    ax.errorbar(
        d.order.values[ok],
        mean[ok] * scale,
        yerr=np.nan_to_num(se[ok] * scale),
        color=color,
        marker="o",
        markersize=3.5,
        linewidth=linewidth,
        capsize=2,
        elinewidth=elinewidth,
        label=label,
    )


def model_points(ax, morph: xr.Dataset, point: dict, what: str, scale: float, color, label: str) -> None:
    _mean_se(ax, morph, point, f"element_{what}", scale, color, label, linewidth=1.4, elinewidth=0.9)


WHAT = {"diameter": ("D", UM, "element diameter [µm]"), "length": ("L", MM, "element length [mm]")}


def every_n(summary: xr.DataTree) -> tuple[xr.Dataset, dict, list[int]]:
    """The summary's ``/morphometry``, its reference cell without N and the N values with a tree there.

    What the figures drawn for every N start from (:func:`reference_point`, :func:`n_values`).
    """
    morph = summary["morphometry"].to_dataset()
    point = reference_point(morph, cell_dims(summary), exclude=("n_terminals",))
    return morph, point, n_values(morph, point)


@styled
def plot_morphometry(summary: xr.DataTree, path) -> Path | None:
    """Element diameter and length against order with Kassab's RCA/LAD/LCX (a heart's); largest N and every N."""
    morph, point, ns = every_n(summary)
    if not ns:
        return None
    kassab = kassab_of(summary)
    orders = morph.order.values
    orders = orders[orders >= 1]
    ncols = 2 if len(ns) > 1 else 1
    fig, axes = subplots(2, ncols, figsize=(3.6 * ncols + 0.4, 6.2), squeeze=False, sharex=True, sharey="row")
    colors = palette(len(ns))
    for row, what in enumerate(("diameter", "length")):
        key, scale, ylabel = WHAT[what]
        ax = axes[row, 0]
        kassab_points(ax, kassab, key, scale, orders)
        model_points(ax, morph, {**point, "n_terminals": ns[-1]}, what, scale, "C3", f"model, N = {ns[-1]}")
        if ncols == 2:
            ax2 = axes[row, 1]
            kassab_points(ax2, kassab, key, scale, orders)
            for n, c in zip(ns, colors):
                model_points(ax2, morph, {**point, "n_terminals": n}, what, scale, c, f"model, N = {n}")
        axes[row, 0].set_ylabel(ylabel)
        for a in axes[row]:
            a.set_yscale("log")
            a.grid(True, which="major", alpha=0.3)
    for a in axes[-1]:
        order_axis(a, orders)
    axes[0, 0].set_title(f"largest tree (N = {ns[-1]})")
    if ncols == 2:
        axes[0, 1].set_title("every N")
    for a in axes[0]:
        a.legend(loc="upper left")
    fig.suptitle(f"Best tree per cell{against(kassab)} ({point_text(point)}); mean ± SE", fontsize=9)
    fig.tight_layout()
    return save(fig, path)


def _ratio(ax, asym: xr.Dataset, point: dict, which: str, color, label: str) -> None:
    _mean_se(ax, asym, point, f"diameter_ratio_{which}", 1.0, color, label, linewidth=1.2, elinewidth=0.8)


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
        order_axis(ax, orders)
        ax.set_xlabel("parent order (diameter-defined Strahler; trunk = 11)")


@styled
def plot_asymmetry(summary: xr.DataTree, path) -> Path | None:
    """D_s/D_p and D_l/D_p against parent order for every N (m_b nearest 641.3)."""
    _, point, ns = every_n(summary)
    if not ns:
        return None
    asym = summary["asymmetry"].to_dataset()
    counts = asym["bifurcation_count"].sel(point).sel(scheme="diameter_defined")
    orders = asym.order.values[(counts > 0).any("n_terminals").values]
    fig, axes = subplots(1, 2, figsize=(8.2, 3.4))
    _ratio_panels(axes, asym, [({**point, "n_terminals": n}, f"N = {n}") for n in ns], palette(len(ns)), orders)
    axes[0].legend(loc="lower left")
    fig.suptitle(f"Bifurcation asymmetry of the best trees ({point_text(point)}); mean ± SE", fontsize=9)
    fig.tight_layout()
    return save(fig, path)


@styled
def plot_mb_effect(summary: xr.DataTree, path) -> Path | None:
    """Diameter, length and both ratios against order for every m_b at the largest N."""
    morph = summary["morphometry"].to_dataset()
    if "m_b" not in morph.dims or morph.sizes["m_b"] < 2:
        return None
    asym = summary["asymmetry"].to_dataset()
    kassab = kassab_of(summary)
    dims = cell_dims(summary)
    base = reference_point(morph, dims, exclude=("m_b", "n_terminals"))
    n = int(morph.n_terminals.values.max())
    mbs = [float(m) for m in morph.m_b.values if present(morph, {**base, "n_terminals": n, "m_b": m})]
    if len(mbs) < 2:
        return None
    colors = palette(len(mbs), "plasma")
    orders = morph.order.values[morph.order.values >= 1]
    fig, axes = subplots(2, 2, figsize=(8.2, 6.6))
    for ax, what in zip(axes[0], ("diameter", "length")):
        key, scale, ylabel = WHAT[what]
        kassab_points(ax, kassab, key, scale, orders)
        for m, c in zip(mbs, colors):
            model_points(ax, morph, {**base, "n_terminals": n, "m_b": m}, what, scale, c, mb_text(m))
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        order_axis(ax, orders)
    axes[0, 0].legend(loc="upper left")
    counts = asym["bifurcation_count"].sel({**base, "n_terminals": n}).sel(scheme="diameter_defined")
    ratio_orders = asym.order.values[(counts > 0).any("m_b").values]
    _ratio_panels(
        axes[1], asym, [({**base, "n_terminals": n, "m_b": m}, mb_text(m)) for m in mbs], colors, ratio_orders
    )
    axes[1, 0].legend(loc="lower left")
    fig.suptitle(
        f"Effect of the blood cost m_b on the best tree (N = {n}"
        + (f", {point_text(base)}" if base else "")
        + "); mean ± SE",
        fontsize=9,
    )
    fig.tight_layout()
    return save(fig, path)
