"""Pictures of trees: a run store's final tree in projection, line width by radius, colour by inlet.

``tree_<run_id>.png`` (:func:`plot_tree`), read from the run store itself (tree and tissue
mask), so any run can be drawn, not only a cell's best; ``consistency.png``
(:func:`plot_consistency`), the trees of several seeds at every step count of a sweep.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from .style import MM, TREE_DPI, cell_dims, reference_point, save, styled, subplots

__all__ = ["plot_tree", "plot_consistency", "load_tree", "draw_tree", "draw_projections", "tree_views", "tree_legend"]

_COLORS = matplotlib.colormaps["tab10"]  # one colour per inlet's tree


_VIEWS_3D = (("x", "y"), ("x", "z"), ("y", "z"))
_AXIS = {"x": 0, "y": 1, "z": 2}
_MASK_AXIS = {("x", "y"): 0, ("x", "z"): 1, ("y", "z"): 2}  # mask axes are (z, y, x): the one not shown


def load_tree(store_path) -> dict:
    """What a tree picture needs from a run store: tree arrays (mm), tissue mask and geometry, inlet names."""
    from ..reduce.morphometry import inlet_of
    from ..store.run_store import RunStore

    store = RunStore.open(store_path, mode="r")
    tree = store.read_tree()
    t_attrs = dict(store.group["tissue"].attrs)
    parent = tree["parent"]
    # The store names the inlets (stores older than that: the heart's, known by its name).
    names = t_attrs.get("inlet_names") or {"heart": ("LCA", "RCA")}.get(str(t_attrs.get("name")), ())
    return {
        "run_id": store.run_id,
        "parent": parent,
        "position_mm": tree["position"] * MM,
        "radius": tree["radius"],
        "inlet": inlet_of(parent),
        "inlets": np.flatnonzero(parent < 0),
        "inlet_names": tuple(names),
        "mask": store.group["tissue/mask"][...].astype(bool),  # (z, y, x)
        "voxel_size": float(t_attrs["voxel_size"]),
        "origin": np.asarray(t_attrs["origin"], dtype=float),
    }


def tree_views(tree: dict) -> tuple[tuple[str, str], ...]:
    """The projections drawn: x-y only for a 2-D tissue (one voxel layer), else (or with no mask)
    x-y, x-z and y-z."""
    return _VIEWS_3D[:1] if tree["mask"] is not None and tree["mask"].shape[0] == 1 else _VIEWS_3D


def draw_tree(
    ax, tree: dict, view: tuple[str, str] = ("x", "y"), width_max: float = 3.5, segments: np.ndarray | None = None
) -> None:
    """One projection of ``tree`` (from :func:`load_tree`) on ``ax``: tissue outline, vessels, inlets.

    ``segments``: the segments drawn (their child nodes; default all), a subsample of a tree too
    large to draw whole; the line widths still scale with the widest of all.
    """
    a, b = view
    parent, pos, radius = tree["parent"], tree["position_mm"], tree["radius"]
    h, origin = tree["voxel_size"], tree["origin"]
    every = np.flatnonzero(parent >= 0)
    seg = every if segments is None else np.asarray(segments)
    col_axis, row_axis = _AXIS[a], _AXIS[b]
    proj = np.zeros((0, 0), bool) if tree["mask"] is None else tree["mask"].any(axis=_MASK_AXIS[view])
    # rows, cols: x-y -> (y, x); x-z -> (z, x); y-z -> (z, y)
    cols = (origin[col_axis] + h * np.arange(proj.shape[1])) * MM
    rows = (origin[row_axis] + h * np.arange(proj.shape[0])) * MM
    if proj.any() and not proj.all() and min(proj.shape) > 1:
        ax.contourf(cols, rows, proj.astype(float), levels=[0.5, 1.5], colors=["0.93"])
        ax.contour(cols, rows, proj.astype(float), levels=[0.5], colors=["0.55"], linewidths=0.7)
    elif proj.any():  # a full rectangle: draw its frame
        ax.add_patch(
            Rectangle(
                (cols[0] - h * MM / 2, rows[0] - h * MM / 2),
                cols[-1] - cols[0] + h * MM,
                rows[-1] - rows[0] + h * MM,
                facecolor="0.93",
                edgecolor="0.55",
                linewidth=0.7,
            )
        )
    # thin vessels first so that trunks stay on top
    s = seg[np.argsort(radius[seg])]
    lines = np.stack([pos[parent[s]][:, [col_axis, row_axis]], pos[s][:, [col_axis, row_axis]]], axis=1)
    inlet_index = np.searchsorted(tree["inlets"], tree["inlet"][s])
    ax.add_collection(
        LineCollection(
            lines,
            linewidths=0.25 + width_max * radius[s] / float(radius[every].max()),
            colors=[_COLORS(int(i) % 10) for i in inlet_index],
            capstyle="round",
        )
    )
    inlets = tree["inlets"]
    ax.plot(pos[inlets, col_axis], pos[inlets, row_axis], "k*", markersize=7, zorder=5)
    ax.set_aspect("equal")
    ax.autoscale_view()


def tree_legend(tree: dict) -> list:
    names = tree["inlet_names"]
    handles = [
        Line2D(
            [],
            [],
            color=_COLORS(i % 10),
            linewidth=2,
            label=f"{names[i]} tree" if i < len(names) else f"inlet {i} tree",
        )
        for i in range(len(tree["inlets"]))
    ]
    handles.append(Line2D([], [], color="k", marker="*", linestyle="none", label="inlet"))
    return handles


@styled
def plot_tree(store_path, path, title: str | None = None) -> Path:
    """The final tree of a run store in projection: line width by radius, colour by inlet, tissue outline.

    A 3-D tree gets three panels (x-y, x-z, y-z); a 2-D one (single voxel layer) one.
    """
    tree = load_tree(store_path)
    seg = tree["parent"] >= 0
    note = (
        f"line width ∝ vessel radius (thickest: {2 * tree['radius'][seg].max() * MM:.2g} mm diameter); grey: tissue "
        "(projection of the voxel mask)"
    )
    return draw_projections(tree, path, title or tree["run_id"], note)


def draw_projections(
    tree: dict, path, title: str, note: str, width_max: float = 3.5, segments: np.ndarray | None = None
) -> Path:
    """A tree (:func:`load_tree`'s dict) in every projection of :func:`tree_views`, with its inlets'
    legend, ``title`` above and ``note`` below; ``segments`` as in :func:`draw_tree`."""
    views = tree_views(tree)
    fig, axes = subplots(1, len(views), figsize=(3.4 * len(views) + 0.6, 3.6), squeeze=False)
    for ax, view in zip(axes[0], views):
        draw_tree(ax, tree, view, width_max=width_max, segments=segments)
        ax.set_xlabel(f"{view[0]} [mm]")
        ax.set_ylabel(f"{view[1]} [mm]")
    axes[0, -1].legend(handles=tree_legend(tree), loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.text(0.5, -0.02, note, ha="center", fontsize=7)
    fig.tight_layout()
    return save(fig, path, dpi=TREE_DPI)


@styled
def plot_consistency(summary, output_dir, path, max_seeds: int = 4) -> Path | None:
    """The paper's consistency figure: the trees of several seeds (columns) at every step count (rows).

    Each row is titled with the cell's ``trunk_spread`` (mean distance between the seeds' main
    trunks, :mod:`vasc_pipeline.reduce.similarity`), the number that says how alike the trees are.
    Drawn for a sweep with a steps axis and two or more seeds; the x-y projection only.
    """
    from ..store.layout import run_path

    costs = summary["costs"].to_dataset()
    dims = cell_dims(summary)
    if "steps" not in dims or costs.sizes["steps"] < 2 or costs.sizes["seed"] < 2:
        return None
    # n_terminals is always a cell dim: the smallest N (a plane study has one)
    point = {**reference_point(costs, dims, exclude=("steps",)), "n_terminals": costs["n_terminals"].values.min()}
    run_ids = costs["run_id"].sel(point)
    seeds = [s for s in costs.seed.values if all(str(r) for r in run_ids.sel(seed=s).values)][:max_seeds]
    if len(seeds) < 2:
        return None
    spread = summary["morphometry"].to_dataset()["trunk_spread"].sel(point)
    steps = costs.steps.values
    fig, axes = subplots(
        len(steps), len(seeds), figsize=(2.3 * len(seeds) + 0.4, 2.3 * len(steps) + 0.4), squeeze=False
    )
    for row, n_steps in enumerate(steps):
        for ax, seed in zip(axes[row], seeds):
            draw_tree(
                ax, load_tree(run_path(output_dir, str(run_ids.sel(steps=n_steps, seed=seed).values))), width_max=2.5
            )
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"seed {int(seed)}", fontsize=8)
        mm = float(spread.sel(steps=n_steps)) * MM
        axes[row, 0].set_ylabel(f"{float(n_steps):.0e} moves\ntrunk spread {mm:.3g} mm", fontsize=8)
    fig.suptitle("Consistency: trees of different seeds as the moves grow (x-y projection)", fontsize=9)
    fig.tight_layout()
    return save(fig, path, dpi=TREE_DPI)
