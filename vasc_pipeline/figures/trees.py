"""The picture of a tree: a run store's final tree in projection, line width by radius, colour by inlet.

``tree_<run_id>.png`` (:func:`plot_tree`), read from the run store itself (tree and tissue
mask), so any run can be drawn, not only a cell's best.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from .style import MM, save, styled, subplots

__all__ = ["plot_tree"]


@styled
def plot_tree(store_path, path, title: str | None = None) -> Path:
    """The final tree of a run store in projection: line width by radius, colour by inlet, tissue outline.

    A 3-D tree gets three panels (x-y, x-z, y-z); a 2-D one (single voxel layer) one.
    """
    from ..morphometry import inlet_of
    from ..store import RunStore

    store = RunStore.open(store_path, mode="r")
    tree = store.read_tree()
    mask_arr = store.group["tissue/mask"]
    mask = mask_arr[...].astype(bool)  # (z, y, x)
    t_attrs = dict(store.group["tissue"].attrs)
    h = float(t_attrs["voxel_size"])
    origin = np.asarray(t_attrs["origin"], dtype=float)
    parent, pos, radius = tree["parent"], tree["position"] * MM, tree["radius"]
    seg = np.flatnonzero(parent >= 0)
    inlet = inlet_of(parent)
    inlets = np.flatnonzero(parent < 0)
    flat = mask.shape[0] == 1
    views = [("x", "y", 0)] if flat else [("x", "y", 0), ("x", "z", 1), ("y", "z", 2)]
    axis_of = {"x": 0, "y": 1, "z": 2}
    # mask axes are (z, y, x): project along the axis not shown
    mask_axis = {0: 0, 1: 1, 2: 2}  # view index -> mask axis to collapse (z for x-y, y for x-z, x for y-z)
    fig, axes = subplots(1, len(views), figsize=(3.4 * len(views) + 0.6, 3.6), squeeze=False)
    rmax = float(radius[seg].max())
    widths = 0.25 + 3.5 * radius[seg] / rmax
    colors = matplotlib.colormaps["tab10"]
    for ax, (a, b, vi) in zip(axes[0], views):
        proj = mask.any(axis=mask_axis[vi])  # 2-D array (rows, cols)
        # rows/cols of the projection: x-y -> (y, x); x-z -> (z, x); y-z -> (z, y)
        col_axis, row_axis = axis_of[a], axis_of[b]
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
        f"line width ∝ vessel radius (thickest: {2 * rmax * MM:.2g} mm diameter); grey: tissue "
        "(projection of the voxel mask)",
        ha="center",
        fontsize=7,
    )
    fig.tight_layout()
    return save(fig, path)
