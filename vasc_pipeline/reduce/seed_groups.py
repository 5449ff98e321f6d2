"""The summary's groups on the (cell..., seed) grid, one entry per complete run: ``/costs``,
``/anatomy`` and ``/traces`` (:mod:`vasc_pipeline.reduce.summary` describes them).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..store.run_store import RunStore
from ..store.trace import TRACE_META, TRACE_NAMES
from .anatomy import ANATOMY_FIELDS, HUO_KASSAB_EXPONENTS, anatomy_of_store
from .cell_grid import CELL_META, COST_META, coord_values
from .runs import COST_KEYS

__all__ = ["cost_group", "anatomy_group", "trace_group"]


def _seed_grid(runs, dims, cell_coords) -> tuple[list[int], dict, dict]:
    """The (cell..., seed) grid of every run: its shape, each run's index in it (by path) and its coordinates."""
    seeds = sorted({r.seed for r in runs})
    index = {d: {v: i for i, v in enumerate(cell_coords[d])} for d in dims}
    at = {r.path: tuple(index[d][v] for d, v in zip(dims, r.cell(dims))) + (seeds.index(r.seed),) for r in runs}
    coords = {d: (d, coord_values(cell_coords[d]), CELL_META[d]) for d in dims}
    coords["seed"] = ("seed", np.asarray(seeds, dtype=np.int64), CELL_META["seed"])
    return [len(cell_coords[d]) for d in dims] + [len(seeds)], at, coords


def cost_group(runs, best, dims, cell_coords) -> xr.Dataset:
    """``/costs``: final costs, steps, wall time, run id, whether the best, cavity share of every run."""
    shape, where, coords = _seed_grid(runs, dims, cell_coords)
    values = {k: np.full(shape, np.nan) for k in COST_KEYS}
    steps_done = np.zeros(shape, dtype=np.int64)
    wall = np.full(shape, np.nan)
    run_id = np.full(shape, "", dtype=object)
    is_best = np.zeros(shape, dtype=np.int8)
    cavity = np.full(shape, np.nan)
    for r in runs:
        at = where[r.path]
        for k in COST_KEYS:
            values[k][at] = r.cost[k]
        cavity[at] = r.statistics.get("cavity_share", np.nan)
        steps_done[at], wall[at], run_id[at] = r.steps_done, r.wall_seconds, r.run_id
        is_best[at] = best[r.cell(dims)] is r
    full = dims + ["seed"]
    data = {
        f"cost_{k}": (
            full,
            values[k],
            {
                "units": COST_META[k][0],
                "long_name": "final " + COST_META[k][1] + ("" if k == "total" else " (unscaled)"),
            },
        )
        for k in COST_KEYS
    }
    data["steps_done"] = (full, steps_done, {"units": "1", "long_name": "proposed moves done (0: no run)"})
    data["wall_seconds"] = (full, wall, {"units": "s", "long_name": "wall-clock time of the run, all sessions"})
    data["run_id"] = (full, run_id, {"long_name": "run id (empty: no complete run)"})
    data["is_best"] = (full, is_best, {"units": "1", "long_name": "1 for the lowest-cost run of the cell"})
    data["cavity_share"] = (
        full,
        cavity,
        {
            "units": "1",
            "long_name": "share of the large vessels' length (r >= r_max/4) inside the tissue's cavities "
            "(NaN: no cavity, e.g. not the heart)",
        },
    )
    return xr.Dataset(data, coords=coords, attrs={"title": "Final costs of every complete run"})


def anatomy_group(runs, dims, cell_coords) -> xr.Dataset:
    """Every complete run's :func:`~vasc_pipeline.reduce.anatomy.anatomy`, on (cell..., seed) and,
    for the inlet shares, (cell..., seed, inlet)."""
    shape, where, coords = _seed_grid(runs, dims, cell_coords)
    found = {r.path: anatomy_of_store(r.path) for r in runs}
    prefix = "inlet_share_"
    inlets = sorted({k[len(prefix) :] for a in found.values() for k in a if k.startswith(prefix)})
    values = {name: np.full(shape, np.nan) for name, _, _ in ANATOMY_FIELDS}
    shares = np.full(shape + [len(inlets)], np.nan)
    for r in runs:
        at = where[r.path]
        for name in values:
            values[name][at] = found[r.path][name]
        for j, inlet in enumerate(inlets):
            shares[at + (j,)] = found[r.path].get(prefix + inlet, np.nan)
    full = dims + ["seed"]
    data = {name: (full, values[name], {"units": u, "long_name": ln}) for name, u, ln in ANATOMY_FIELDS}
    share_attrs = {"units": "1", "long_name": "share of the terminals fed by the inlet"}
    data["inlet_share"] = (full + ["inlet"], shares, share_attrs)
    coords["inlet"] = ("inlet", np.array(inlets, dtype=object), {"long_name": "inlet (ostium) name"})
    return xr.Dataset(
        data,
        coords=coords,
        attrs={
            "title": "Anatomy of every complete run: arteries, vessels on the organ, pressures, crown scaling",
            **{f"huo_kassab_{k}": v for k, v in HUO_KASSAB_EXPONENTS.items()},
        },
    )


def trace_group(runs, dims, cell_coords) -> xr.Dataset:
    """``/traces``: every run's cost trace on (cell..., seed, record), NaN-padded to the longest."""
    grid, where, coords = _seed_grid(runs, dims, cell_coords)
    traces = {r.run_id: RunStore.open(r.path, mode="r").read_trace() for r in runs}
    n_rec = max((len(t["step"]) for t in traces.values()), default=0)
    shape = grid + [n_rec]
    names = TRACE_NAMES
    # step as float64 with NaN padding: exact for step counts below 2^53, and plots need no mask
    arrays = {n: np.full(shape, np.nan) for n in names}
    length = np.zeros(shape[:-1], dtype=np.int64)
    for r in runs:
        t = traces[r.run_id]
        at = where[r.path]
        k = len(t["step"])
        length[at] = k
        for n in names:
            arrays[n][at + (slice(0, k),)] = t[n]
    full = dims + ["seed", "record"]
    data = {n: (full, arrays[n], {"units": TRACE_META[n][0], "long_name": TRACE_META[n][1]}) for n in names}
    data["trace_length"] = (
        dims + ["seed"],
        length,
        {"units": "1", "long_name": "trace records of the run (0: no run)"},
    )
    coords["record"] = ("record", np.arange(n_rec, dtype=np.int64), {"units": "1", "long_name": "trace record"})
    return xr.Dataset(data, coords=coords, attrs={"title": "Cost traces of every complete run (NaN-padded)"})
