"""What a physiologist looks at first in a coronary tree, beside Kassab's orders.

Pure functions on a run store's tree arrays (``parent``, ``position`` [m], ``radius`` [m],
``kind``), the run's :class:`~vasc_pipeline.model.physics.Physics` and, for the distance to the
organ, its exclusion domain (the heart: myocardium and cavities). :func:`anatomy` gathers them
into one flat dict of named numbers (:data:`ANATOMY_FIELDS` gives each its unit and meaning);
:func:`anatomy_of_store` reads a run store and calls it. The reduction writes them to
``summary.zarr``'s ``/anatomy`` group, ``anatomy.csv`` and the console table.

- Both arteries present: each inlet's share of the terminals.
- Vessels on the organ: the share of bifurcations more than :data:`OFF_ORGAN_DISTANCE` outside
  the exclusion domain, and their median distance.
- Blood reaches the terminals: terminal pressures of the model's own Poiseuille solution (every
  segment carries n Q0 / N through 8 mu L / (pi r^4), mu = mu(2 r) under
  ``physics.viscosity_law``, from ``physics.pressure_inlet`` at the inlets): minimum, median,
  the mean drop, and how many are below zero.
- Scaling laws of the crowns (Huo & Kassab 2009, 2012): for every stem segment, its crown is the
  stem and everything downstream; the stem diameter D_s grows as L_c^(3/7) with the crown's
  total length L_c, and the crown's volume V_c as D_s^3. The exponents are least-squares slopes
  in log-log over the stems whose crown holds at least one bifurcation (a terminal segment's
  crown is itself and says nothing of the tree). A segment below a pass-through node (kind 3:
  an extended store's annealed terminals) continues its parent's vessel and is no stem of its
  own: the vessel's crown is its upper segment's.

Every function takes the whole tree of an extended store as it is (its annealed terminals of
kind 3, its physics of N = the fine terminals): :mod:`vasc_pipeline.reduce.extended`.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
from scipy import ndimage

from ..model.costs import tree_pressures
from ..model.physics import Physics
from ..model.topology import (
    KIND_BIFURCATION,
    KIND_TERMINAL,
    KIND_TERRITORY_ROOT,
    inlet_of,
    segment_lengths,
    terminals_downstream,
    topological_order,
)

__all__ = [
    "ANATOMY_FIELDS",
    "HUO_KASSAB_EXPONENTS",
    "OFF_ORGAN_DISTANCE",
    "MMHG",
    "anatomy",
    "anatomy_of_store",
    "crown_exponents",
    "distance_outside",
    "inlet_shares",
    "terminal_pressures",
]

OFF_ORGAN_DISTANCE = 2e-3  # m: a bifurcation further than this outside the heart floats in the air
MMHG = 133.322387415  # Pa
# Huo & Kassab: D_s ~ L_c^(3/7) (J R Soc Interface 2012, the diameter-length law of crowns) and
# V_c ~ D_s^3 (Biophys J 2009, V_c ~ D_s^(2/3) L_c with the former).
HUO_KASSAB_EXPONENTS = {"diameter_crown_length": 3.0 / 7.0, "crown_volume_diameter": 3.0}

# name, units, long name: one home for what every field of :func:`anatomy` means.
ANATOMY_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("bifurcations_off_organ_share", "1", f"share of bifurcations more than {OFF_ORGAN_DISTANCE * 1e3:g} mm outside"),
    ("bifurcations_off_organ_median_distance", "m", "median distance outside of those bifurcations (NaN: none)"),
    ("terminal_pressure_min", "Pa", "lowest terminal pressure (Poiseuille, from the inlet pressure)"),
    ("terminal_pressure_median", "Pa", "median terminal pressure"),
    ("pressure_drop_mean", "Pa", "mean pressure drop from the inlet to a terminal"),
    ("terminals_below_zero", "1", "terminals with a pressure below zero"),
    ("diameter_crown_length_exponent", "1", "fitted exponent of D_s ~ L_c^b (Huo-Kassab: 3/7)"),
    ("crown_volume_diameter_exponent", "1", "fitted exponent of V_c ~ D_s^b (Huo-Kassab: 3)"),
)


def inlet_shares(parent, kind, inlet_names) -> dict[str, float]:
    """Per inlet (in node order, named by ``inlet_names``) its share of the terminals."""
    parent, kind = np.asarray(parent), np.asarray(kind)
    terminals = inlet_of(parent)[kind == KIND_TERMINAL]
    return {name: float(np.mean(terminals == inlet)) for name, inlet in zip(inlet_names, np.flatnonzero(parent < 0))}


def terminal_pressures(parent: np.ndarray, position: np.ndarray, physics: Physics) -> np.ndarray:
    """Pressure [Pa] at every terminal (in node order), from the model's Poiseuille solution
    (:func:`~vasc_pipeline.model.costs.tree_pressures`: any node layout)."""
    parent = np.asarray(parent, dtype=np.int64)
    terminal = (parent >= 0) & (np.bincount(parent[parent >= 0], minlength=parent.size) == 0)
    return tree_pressures(parent, position, physics)[terminal]


def distance_outside(points: np.ndarray, domain: np.ndarray, voxel_size: float, origin: np.ndarray) -> np.ndarray:
    """Distance [m] from each point to the nearest voxel of ``domain`` (0 inside).

    ``domain`` is a (z, y, x) boolean voxel map with isotropic ``voxel_size`` [m] and ``origin``
    (the [x, y, z] centre of voxel [0, 0, 0]); a point outside the grid's box adds its distance
    to the box.
    """
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    outside = ndimage.distance_transform_edt(~np.asarray(domain, dtype=bool)) * voxel_size
    shape_xyz = np.asarray(domain.shape[::-1])
    u = (points[:, : len(shape_xyz)] - np.asarray(origin)[: len(shape_xyz)]) / voxel_size
    idx = np.clip(np.rint(u).astype(np.int64), 0, shape_xyz - 1)
    beyond = np.linalg.norm((u - idx) * (np.abs(u - idx) > 0.5), axis=1) * voxel_size
    return outside[tuple(idx[:, ::-1].T)] + beyond


def crown_exponents(parent: np.ndarray, position: np.ndarray, radius: np.ndarray, kind: np.ndarray) -> dict[str, float]:
    """Least-squares exponents of D_s ~ L_c^b and V_c ~ D_s^b over the stems whose crown holds a
    bifurcation (NaN when fewer than three such stems, or their values do not vary)."""
    parent = np.asarray(parent)
    radius = np.asarray(radius, dtype=np.float64)
    length = segment_lengths(parent, position)
    crown_length = length.copy()
    crown_volume = math.pi * radius**2 * length
    for v in reversed(topological_order(parent).tolist()):  # children before parents
        p = parent[v]
        if p >= 0 and parent[p] >= 0:  # an inlet has no segment, hence no crown
            crown_length[p] += crown_length[v]
            crown_volume[p] += crown_volume[v]
    stems = (parent >= 0) & (terminals_downstream(parent, kind) >= 2) & (crown_length > 0) & (radius > 0)
    stems &= np.asarray(kind)[np.maximum(parent, 0)] != KIND_TERRITORY_ROOT  # a vessel's continuation
    log_d = np.log(2.0 * radius[stems])
    out = {}
    for name, x, y in (
        ("diameter_crown_length_exponent", np.log(crown_length[stems]), log_d),
        ("crown_volume_diameter_exponent", log_d, np.log(crown_volume[stems])),
    ):
        out[name] = float(np.polyfit(x, y, 1)[0]) if x.size >= 3 and np.ptp(x) > 0 else math.nan
    return out


def anatomy(
    parent: np.ndarray,
    position: np.ndarray,
    radius: np.ndarray,
    kind: np.ndarray,
    physics: Physics,
    inlet_names: tuple[str, ...] | list[str],
    organ: np.ndarray | None = None,
    voxel_size: float | None = None,
    origin: np.ndarray | None = None,
) -> dict[str, float]:
    """The anatomy of one tree as a flat dict: ``inlet_share_<name>`` per inlet, then the
    fields of :data:`ANATOMY_FIELDS` (SI units). Without ``organ`` (a (z, y, x) voxel map of
    the organ with its ``voxel_size`` and ``origin``) the distances are NaN."""
    parent, kind = np.asarray(parent), np.asarray(kind)
    out: dict[str, float] = {f"inlet_share_{k}": v for k, v in inlet_shares(parent, kind, inlet_names).items()}
    bifurcations = np.flatnonzero(kind == KIND_BIFURCATION)
    if organ is None or bifurcations.size == 0:
        out["bifurcations_off_organ_share"] = math.nan
        out["bifurcations_off_organ_median_distance"] = math.nan
    else:
        distance = distance_outside(np.asarray(position)[bifurcations], organ, voxel_size, origin)
        off = distance[distance > OFF_ORGAN_DISTANCE]
        out["bifurcations_off_organ_share"] = off.size / bifurcations.size
        out["bifurcations_off_organ_median_distance"] = float(np.median(off)) if off.size else math.nan
    pressure = terminal_pressures(parent, position, physics)
    out["terminal_pressure_min"] = float(pressure.min())
    out["terminal_pressure_median"] = float(np.median(pressure))
    out["pressure_drop_mean"] = float(physics.pressure_inlet - pressure.mean())
    out["terminals_below_zero"] = float(np.count_nonzero(pressure < 0))
    out.update(crown_exponents(parent, position, radius, kind))
    return out


def anatomy_of_store(path: str | os.PathLike) -> dict[str, Any]:
    """:func:`anatomy` of a complete run store (its final tree, physics and exclusion domain)."""
    from ..store.run_store import RunStore

    store = RunStore.open(path, mode="r")
    tree = store.read_tree()
    tissue = store.group["tissue"]
    return anatomy(
        tree["parent"],
        tree["position"],
        tree["radius"],
        tree["kind"],
        Physics(**store.attrs["physics"]),
        tuple(tissue.attrs["inlet_names"]),
        organ=tissue["exclusion"][...] > 0,
        voxel_size=float(tissue.attrs["voxel_size"]),
        origin=np.asarray(tissue.attrs["origin"], dtype=np.float64),
    )
