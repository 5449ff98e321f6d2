"""Figures of the whole trees (``figures/extended_*.png``, :mod:`vasc_pipeline.reduce.extended`).

- ``extended_tree_<run_id>.png`` (:func:`plot_whole_tree`): the whole tree in projection, every
  annealed vessel and a uniform sample of the fine ones (a million segments do not draw), line
  width by radius, colour by inlet.
- ``extended_morphometry_<run_id>.png`` (:func:`plot_extended_morphometry`): element diameter and
  length against orders 1-11 for both readings of the ordering, with Kassab's RCA, LAD and LCX.
- ``extended_pressure_<run_id>.png`` (:func:`plot_extended_pressure`): the pressure along every
  order's vessels (mean, lowest) as a share of the inlet pressure, with the published band of
  microvascular pressures over the orders whose diameters it covers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from .orders import WHAT, kassab_points, model_points
from .style import MM, order_axis, save, styled, subplots
from .trees import draw_projections

__all__ = ["plot_whole_tree", "plot_extended_morphometry", "plot_extended_pressure", "draw_extended"]

READING_STYLE = {"range": "C3", "confluence": "C0"}


def _drawn_segments(tree, max_fine: int, seed: int) -> np.ndarray:
    """Every segment of the annealed part and at most ``max_fine`` fine ones, drawn uniformly."""
    from ..reduce.extended import territories

    _, territory = territories(tree.parent, tree.kind)
    seg = np.flatnonzero(tree.parent >= 0)
    fine = seg[territory[seg] >= 0]
    coarse = seg[territory[seg] < 0]
    if fine.size > max_fine:
        fine = np.sort(np.random.default_rng(seed).choice(fine, max_fine, replace=False))
    return np.concatenate([coarse, fine])


@styled
def plot_whole_tree(tree, path, max_fine: int = 40_000, seed: int = 0) -> Path:
    """The whole tree (a :class:`~vasc_pipeline.reduce.extended.WholeTree`) in projection."""
    from ..model.topology import inlet_of
    from ..store.run_store import RunStore

    mask, voxel, origin = None, 1.0, np.zeros(3)
    if tree.source is not None:
        tissue = RunStore.open(tree.source, mode="r").group["tissue"]
        mask = tissue["mask"][...].astype(bool)
        voxel, origin = float(tissue.attrs["voxel_size"]), np.asarray(tissue.attrs["origin"], dtype=float)
    drawn = {
        "run_id": tree.run_id,
        "parent": tree.parent,
        "position_mm": tree.position * MM,
        "radius": tree.radius,
        "inlet": inlet_of(tree.parent),
        "inlets": np.flatnonzero(tree.parent < 0),
        "inlet_names": tree.inlet_names,
        "mask": mask,
        "voxel_size": voxel,
        "origin": origin,
    }
    segments = _drawn_segments(tree, max_fine, seed)
    n_seg = int(np.count_nonzero(tree.parent >= 0))
    return draw_projections(
        drawn,
        path,
        f"{tree.run_id}: the whole tree, {tree.physics.n_terminals} fine terminals",
        f"{segments.size} of {n_seg} segments drawn (every annealed one, a uniform sample of the fine ones); "
        "line width ∝ radius; grey: tissue",
        width_max=3.0,
        segments=segments,
    )


@styled
def plot_extended_morphometry(summary: xr.DataTree, run_id: str, path) -> Path:
    """Element diameter and length against orders 1-11, both readings, with Kassab's arteries (a heart's)."""
    from ..reduce.reference import kassab_dataset

    morph = summary["morphometry"].to_dataset()
    heart = "comparison" in summary.children and run_id in summary["comparison"].run_id.values
    kassab = kassab_dataset() if heart else None
    orders = morph.order.values
    orders = orders[orders >= 1]
    fig, axes = subplots(2, 1, figsize=(4.4, 6.2), sharex=True, squeeze=False)
    for row, what in enumerate(("diameter", "length")):
        key, scale, ylabel = WHAT[what]
        ax = axes[row, 0]
        kassab_points(ax, kassab, key, scale, orders)
        for reading, color in READING_STYLE.items():
            part = morph.sel(order=orders)
            model_points(ax, part, {"run_id": run_id, "reading": reading}, what, scale, color, f"{reading} reading")
        ax.set_ylabel(ylabel)
        ax.set_yscale("log")
        ax.grid(True, which="major", alpha=0.3)
    order_axis(axes[-1, 0], orders)
    axes[0, 0].legend(loc="upper left")
    below = int((morph.sel(run_id=run_id).element_count.sel(order=morph.order.values < 1) > 0).any("order").sum())
    note = f"; {below} reading(s) with orders below 1 (not drawn)" if below else ""
    fig.suptitle(f"{run_id}, the whole tree: mean ± SE by diameter-defined order{note}", fontsize=8)
    fig.tight_layout()
    return save(fig, path)


@styled
def plot_extended_pressure(summary: xr.DataTree, run_id: str, path) -> Path:
    """Pressure along each order's vessels (mean, lowest) over the inlet pressure, both readings,
    with the published band (:data:`vasc_pipeline.reduce.extended.PUBLISHED_PRESSURES`) over the
    orders whose diameters reach into its range: every value (left), and -100 % to 100 % (right,
    where the band is seen whatever the lowest pressures)."""
    press = summary["pressure"].to_dataset()
    attrs = press.attrs
    orders = press.order.values
    p = press.sel(run_id=run_id, reading="range")
    shown = orders[np.isfinite(p.pressure_mean_fraction.values)]
    diameter = (
        summary["morphometry"]
        .to_dataset()
        .element_diameter_mean.sel(run_id=run_id, reading="range", scheme="diameter_defined", order=shown)
    )
    inside = (p.diameter_max.values >= attrs["published_diameter_min"]) & (
        p.diameter_min.values <= attrs["published_diameter_max"]
    )
    fig, axes = subplots(1, 2, figsize=(8.6, 3.8), squeeze=False)
    for ax, zoom in zip(axes[0], (False, True)):
        for reading, color in READING_STYLE.items():
            q = press.sel(run_id=run_id, reading=reading)
            ok = np.isfinite(q.pressure_mean_fraction.values)
            mean, low = 100 * q.pressure_mean_fraction.values[ok], 100 * q.pressure_min_fraction.values[ok]
            ax.plot(orders[ok], mean, "o-", color=color, ms=3.5, label=f"mean, {reading}")
            ax.plot(orders[ok], low, "v--", color=color, ms=3, lw=0.8, label=f"lowest, {reading}")
        if inside.any():
            lo, hi = orders[inside].min() - 0.4, orders[inside].max() + 0.4
            d_lo, d_hi = attrs["published_diameter_min"] * 1e6, attrs["published_diameter_max"] * 1e6
            ax.fill_between(
                [lo, hi],
                100 * attrs["published_fraction_min"],
                100 * attrs["published_fraction_max"],
                color="0.75",
                zorder=0,
                label=f"published, {d_lo:.0f}-{d_hi:.0f} µm",
            )
        ax.axhline(0, color="0.5", lw=0.6)
        if zoom:
            ax.set_ylim(-100, 105)
            ax.set_title("-100 % to 100 %", fontsize=8)
        else:
            ax.set_title("every value", fontsize=8)
        ax.set_xticks(shown)
        ax.set_xticklabels([f"{o}\n{d * 1e6:.0f}" for o, d in zip(shown, diameter.values)], fontsize=6)
        ax.set_xlabel("order (trunk = 11) / mean element diameter [µm]")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_ylabel("pressure [% of the inlet pressure]")
    axes[0, 1].legend(loc="lower right", fontsize=6.5)
    fig.suptitle(f"{run_id}: pressures along the whole tree's vessels (Poiseuille)", fontsize=8)
    fig.text(0.5, -0.03, "published: Chilian et al. 1986 (cat), 1989 (dog)", ha="center", fontsize=6.5)
    fig.tight_layout()
    return save(fig, path)


def draw_extended(reduction) -> list[Path]:
    """Every figure of a whole trees' reduction (:class:`vasc_pipeline.reduce.extended.ExtendedReduction`):
    per tree its picture (read again from its store), its orders against Kassab and its pressures."""
    from ..reduce.extended import extended_stores, read_whole_tree
    from ..store.layout import FIGURES_DIR

    out = reduction.output_dir
    figures = out / FIGURES_DIR
    paths = []
    for path in extended_stores(out)[0]:
        whole = read_whole_tree(path, out)
        paths.append(plot_whole_tree(whole, figures / f"extended_tree_{whole.run_id}.png"))
    if reduction.summary is not None:
        for run_id in reduction.summary["morphometry"].run_id.values:
            for plot, what in ((plot_extended_morphometry, "morphometry"), (plot_extended_pressure, "pressure")):
                paths.append(plot(reduction.summary, run_id, figures / f"extended_{what}_{run_id}.png"))
    return paths
