"""Full (non-incremental) evaluation of every cost term, in plain NumPy.

This is the reference the numba kernel's incremental running sums are checked against
(the tests compare them after every kind of move): it shares no code with
:mod:`vasc_pipeline.kernel`. Terms follow Keelan, Chung & Hague's definitions; the voxel
traversal here is the "all plane crossings, sorted" form of
Amanatides-Woo, the supply map a brute-force distance test per terminal.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .physics import TABLE_FLOW, TABLE_RESISTANCE, Physics, cost_tables, segment_factors
from .tissue import ExclusionGrid, Tissue
from .topology import KIND_BIFURCATION, KIND_INLET, KIND_TERMINAL, path_sums, terminals_downstream
from .topology import segment_lengths as _segment_lengths
from .tree import Tree

__all__ = [
    "COST_TERMS",
    "COST_TERM_LABELS",
    "ActiveTerms",
    "active_terms",
    "segment_lengths",
    "voxel_pieces",
    "exclusion_sum",
    "cavity_share",
    "LARGE_VESSEL_FRACTION",
    "supply_counts",
    "supply_cost",
    "node_pressures",
    "Poiseuille",
    "poiseuille",
    "tree_pressures",
    "full_costs",
    "total_cost",
    "vascular_cost",
    "vascular_exclusion_cost",
]

COST_TERMS = ("volume", "power", "supply", "exclusion", "pressure")  # the one list: kernel sums, trace, stores
# Per term of COST_TERMS: units and long name (the run store's trace labels).
COST_TERM_LABELS = {
    "volume": ("W", "C_v, metabolic cost of blood volume"),
    "power": ("W", "C_w, pumping power"),
    "supply": ("1", "C_s, supply cost (voxel count score)"),
    "exclusion": ("m2", "C_o, large-vessel exclusion cost"),
    "pressure": ("Pa2", "C_p, terminal pressure cost"),
}


class ActiveTerms(tuple):
    """(supply, exclusion, pressure): which optional terms a run evaluates."""

    @property
    def supply(self) -> bool:
        return self[0]

    @property
    def exclusion(self) -> bool:
        return self[1]

    @property
    def pressure(self) -> bool:
        return self[2]


def active_terms(physics: Physics, terminals_fixed: bool = False) -> ActiveTerms:
    """Terms with zero weight (or supply with fixed terminals) are neither annealed nor reported."""
    return ActiveTerms((physics.A_s > 0 and not terminals_fixed, physics.A_o > 0, physics.A_p > 0))


def segment_lengths(tree: Tree) -> np.ndarray:
    """Length [m] of the segment ending at every node (0 at inlets)."""
    return _segment_lengths(tree.parent, tree.position)


def voxel_pieces(u0: np.ndarray, u1: np.ndarray, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Voxels crossed by the segment u0 -> u1 and the length inside each (voxel units).

    Points are in voxel coordinates [x, y, z] (voxel centres at integers). Returns
    ((n, 3) integer (z, y, x) indices inside the grid, (n,) lengths).
    """
    u0 = np.asarray(u0, dtype=np.float64)
    d = np.asarray(u1, dtype=np.float64) - u0
    length = math.sqrt(float(d @ d))
    if length == 0.0:
        return np.empty((0, 3), dtype=np.int64), np.empty(0)
    crossings = [np.array([0.0, 1.0])]
    for a in range(3):
        if d[a] != 0.0:
            lo, hi = sorted((u0[a], u0[a] + d[a]))
            planes = np.arange(math.ceil(lo - 0.5), math.floor(hi - 0.5) + 1) + 0.5
            crossings.append((planes - u0[a]) * (1.0 / d[a]))  # as the kernel computes it
    t = np.unique(np.clip(np.concatenate(crossings), 0.0, 1.0))
    mid = 0.5 * (t[:-1] + t[1:])
    idx = np.floor(u0 + mid[:, None] * d + 0.5).astype(np.int64)[:, ::-1]
    pieces = np.diff(t) * length
    inside = np.all((idx >= 0) & (idx < np.array(shape)), axis=1)
    return idx[inside], pieces[inside]


def exclusion_sum(p0: np.ndarray, p1: np.ndarray, grid: ExclusionGrid) -> float:
    """sum_v (D_v L_v)^6 over the voxels of ``grid`` (a :class:`~vasc_pipeline.model.tissue.ExclusionGrid`,
    or anything with its ``distance``, ``origin``, ``voxel_size`` and ``shape``: a ``Tissue``
    for its own grid) that the centre-line p0 -> p1 [m] crosses, D and L in that grid's voxels."""
    u0 = (np.asarray(p0, dtype=np.float64) - grid.origin) / grid.voxel_size
    u1 = (np.asarray(p1, dtype=np.float64) - grid.origin) / grid.voxel_size
    idx, pieces = voxel_pieces(u0, u1, grid.shape)
    depth = grid.distance[idx[:, 0], idx[:, 1], idx[:, 2]].astype(np.float64)
    return float(np.sum((depth * pieces) ** 6))


# Vessels with r >= this fraction of the tree's largest radius count as "large" in
# cavity_share (the fidelity issue's definition).
LARGE_VESSEL_FRACTION = 0.25


def cavity_share(
    parent: np.ndarray,
    position: np.ndarray,
    radius: np.ndarray,
    tissue: Tissue,
    large_fraction: float = LARGE_VESSEL_FRACTION,
) -> float:
    """Share of the length of the large vessels that lies in the tissue's cavities.

    Cavities are the voxels of the exclusion domain outside the tissue (the heart's
    ventricles, :attr:`Tissue.cavity`); large vessels are the segments with radius
    >= ``large_fraction`` times the largest. Lengths per voxel come from the exact
    traversal the exclusion term uses, so the share is exact for the voxelised domains.
    Returns NaN when the tissue has no cavity or the tree no segment.

    Parameters
    ----------
    parent : int64 (node,), -1 at inlets
    position : float64 (node, 3), m
    radius : float64 (node,), m; radius of the segment ending at each node
    tissue : Tissue
    """
    cavity = tissue.cavity
    seg = np.flatnonzero(np.asarray(parent) >= 0)
    if not cavity.any() or seg.size == 0:
        return math.nan
    radius = np.asarray(radius, dtype=np.float64)
    large = seg[radius[seg] >= large_fraction * radius[seg].max()]
    inside = total = 0.0
    for i in large:
        u0 = (position[i] - tissue.origin) / tissue.voxel_size
        u1 = (position[parent[i]] - tissue.origin) / tissue.voxel_size
        idx, pieces = voxel_pieces(u0, u1, tissue.shape)
        total += float(np.linalg.norm(u1 - u0))
        inside += float(pieces[cavity[idx[:, 0], idx[:, 1], idx[:, 2]]].sum())
    return inside / total if total > 0 else math.nan


def supply_counts(terminals: np.ndarray, tissue: Tissue, supply_radius: float) -> np.ndarray:
    """int32 (z, y, x): how many supply spheres cover each tissue voxel centre."""
    counts = np.zeros(tissue.shape, dtype=np.int32)
    rho = supply_radius / tissue.voxel_size
    rho2 = rho * rho
    shape = np.array(tissue.shape)
    for p in np.atleast_2d(terminals):
        u = (p - tissue.origin) / tissue.voxel_size  # x, y, z
        lo = np.maximum(np.floor(u[::-1] - rho).astype(int), 0)
        hi = np.minimum(np.ceil(u[::-1] + rho).astype(int), shape - 1)
        k, j, i = np.meshgrid(*(np.arange(lo[a], hi[a] + 1) for a in range(3)), indexing="ij")
        dx, dy, dz = i - u[0], j - u[1], k - u[2]
        inside = (dx * dx + dy * dy) + dz * dz <= rho2
        counts[k[inside], j[inside], i[inside]] += 1
    counts *= tissue.mask
    return counts


def supply_cost(counts: np.ndarray, mask: np.ndarray, target: np.ndarray | None = None) -> float:
    """C_s = sum over tissue voxels of s(b) = 10 (t - b) for b < t, else (b - t)^2, b the voxel's
    coverage and t its target (``target``, from a demand map: :attr:`Tissue.supply_target`;
    None: t = 1 everywhere, so s(0) = 10 and s(b) = (b - 1)^2)."""
    tissue = mask == 1
    b = counts[tissue].astype(np.int64)
    t = 1 if target is None else np.asarray(target)[tissue].astype(np.int64)
    return float(np.sum(np.where(b < t, 10 * (t - b), (b - t) ** 2)))


def node_pressures(tree: Tree, physics: Physics, lengths: np.ndarray | None = None) -> np.ndarray:
    """Pressure [Pa] at every node from Poiseuille drops along the paths from the inlets."""
    tables = cost_tables(physics)
    lengths = segment_lengths(tree) if lengths is None else lengths
    n = tree.n_downstream
    drop = tables.flow[n] * tables.resistance[n] * lengths
    return path_sums(tree.parent, -drop, physics.pressure_inlet)


class Poiseuille(NamedTuple):
    """The model's Poiseuille solution of a tree (:func:`poiseuille`), node-indexed (segment
    values at a segment's child node, 0 at inlets).

    Attributes
    ----------
    n_downstream : int64 (node,)   terminals downstream (their flows add up)
    length : float64 (node,)       segment length [m]
    flow : float64 (node,)         n Q0 / N [m^3 s^-1]
    resistance : float64 (node,)   8 mu L / (pi r^4) of the segment [Pa s m^-3], mu = mu(2 r) under
                                   ``physics.viscosity_law``
    pressure : float64 (node,)     [Pa], ``physics.pressure_inlet`` at the inlets
    """

    n_downstream: np.ndarray
    length: np.ndarray
    flow: np.ndarray
    resistance: np.ndarray
    pressure: np.ndarray


def poiseuille(parent: np.ndarray, position: np.ndarray, physics: Physics) -> Poiseuille:
    """The Poiseuille solution of a tree in any node layout (a run store's, an extended store's
    with its pass-through nodes): every node without children is a terminal, flows and radii
    follow from the terminals downstream under ``physics``, pressures drop from
    ``physics.pressure_inlet`` at the inlets (:func:`node_pressures`, for arrays: the same
    values on a run's tree, bit for bit)."""
    parent = np.asarray(parent, dtype=np.int64)
    childless = np.bincount(parent[parent >= 0], minlength=parent.size) == 0
    kind = np.where(parent < 0, KIND_INLET, np.where(childless, KIND_TERMINAL, KIND_BIFURCATION))
    n = terminals_downstream(parent, kind)
    factors = segment_factors(physics, n)
    length = _segment_lengths(parent, position)
    resistance = factors[TABLE_RESISTANCE] * length
    drop = factors[TABLE_FLOW] * factors[TABLE_RESISTANCE] * length
    pressure = path_sums(parent, -drop, physics.pressure_inlet)
    return Poiseuille(n, length, factors[TABLE_FLOW], resistance, pressure)


def tree_pressures(parent: np.ndarray, position: np.ndarray, physics: Physics) -> np.ndarray:
    """Pressure [Pa] at every node of a tree in any node layout (:func:`poiseuille`)."""
    return poiseuille(parent, position, physics).pressure


def full_costs(tree: Tree, tissue: Tissue, physics: Physics, terms: ActiveTerms | None = None) -> dict[str, float]:
    """Every cost term recomputed from scratch, unscaled, plus the annealed ``total``.

    Inactive terms (see :func:`active_terms`) are reported as 0, as the kernel does.
    """
    terms = active_terms(physics) if terms is None else terms
    tables = cost_tables(physics)
    lengths = segment_lengths(tree)
    seg = np.flatnonzero(tree.parent >= 0)
    n = tree.n_downstream[seg]
    out = dict.fromkeys(COST_TERMS, 0.0)
    out["volume"] = float(np.sum(tables.volume[n] * lengths[seg]))
    out["power"] = float(np.sum(tables.power[n] * lengths[seg]))
    k, nt = tree.n_inlets, tree.n_terminals
    if terms.supply:
        counts = supply_counts(tree.position[k : k + nt], tissue, physics.supply_radius)
        out["supply"] = supply_cost(counts, tissue.mask, tissue.supply_target)
    if terms.exclusion:
        out["exclusion"] = float(
            sum(
                tables.exclusion[tree.n_downstream[i]]
                * exclusion_sum(tree.position[i], tree.position[tree.parent[i]], tissue.exclusion_grid)
                for i in seg
                if tables.exclusion[tree.n_downstream[i]] > 0
            )
        )
    if terms.pressure:
        pressure = node_pressures(tree, physics, lengths)
        out["pressure"] = float(np.sum((pressure[k : k + nt] - physics.pressure_terminal) ** 2))
    out["total"] = total_cost(out, physics)
    return out


def vascular_cost(terms: dict[str, float]) -> float:
    """C_v + C_w [W]: blood volume and pumping power, the cost a tree's geometry alone sets
    (the polish report's ``vascular_*``; :func:`vasc_pipeline.model.geometry.vascular_cost`
    is the same sum from positions)."""
    return terms["volume"] + terms["power"]


def vascular_exclusion_cost(terms: dict[str, float], w_exclusion: float) -> float:
    """C_v + C_w + (A_o / A_wv) C_o [W], with ``w_exclusion`` = A_o / A_wv: the annealed cost
    without the supply and pressure terms, the "vascular part" the benchmarks report
    (``cost_vascular`` in their rows)."""
    return vascular_cost(terms) + w_exclusion * terms["exclusion"]


def total_cost(terms: dict[str, float], physics: Physics) -> float:
    """The annealed cost C = (C_w + C_v) + (A_o C_o + A_p C_p + A_s C_s) / A_wv."""
    w_o, w_p, w_s = physics.weights
    return vascular_cost(terms) + w_o * terms["exclusion"] + w_p * terms["pressure"] + w_s * terms["supply"]
