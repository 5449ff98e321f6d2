"""The whole tree: a CCO subtree grown below every annealed terminal, in that terminal's territory.

An annealed terminal stands for a whole subtree of the finest orders. Given a complete run (its
tree, physics and voxelised tissue, :class:`Source`), :func:`plan_extension` divides the tissue
into **territories**, the tissue voxels whose centre lies nearest to each annealed terminal (a
Voronoi partition of the voxel centres by scipy's ``cKDTree``), and gives every territory the same
number m = round(n_fine / N) of fine terminals (so the fine total is m N, the requested count
rounded to a multiple of N). :func:`grow_batch` grows the subtrees of a batch of territories.

A territory's subtree is a plain CCO growth (:func:`vasc_pipeline.engine.cco.grow_arrays`) of m
terminals with one inlet at the annealed terminal, sites drawn uniformly in the territory's
voxels, with the inlet radius of an annealed terminal segment (r_t = r_in N^(-1/gamma)) and the
flow Q0 / N it carries: its weights w(n) are then those of the whole tree's radius law
r = r_in (m N)^(-1/gamma) n^(1/gamma), so a partial subtree's cost is its final cost, as in CCO.
Its generator is seeded from (seed, territory index) alone (:func:`growth_rng`): a subtree is
what ``method=cco`` grows on a mask of its territory with that generator, and batches may run in
any order, on any worker, to the same tree.

Node layout of the whole tree (:class:`ExtensionPlan`): the annealed tree's nodes first, as they
were (indices, positions, topology), each annealed terminal now of kind
:data:`KIND_TERRITORY_ROOT` with one child, the root segment of its subtree; then territory i's
2m - 1 nodes at ``node_start + i (2m - 1)``: its m fine terminals (kind 2) in the order they were
added, then its m - 1 bifurcations (kind 1). Every radius follows r = r_t' n^(1/gamma) with
r_t' = r_in (m N)^(-1/gamma) and n the fine terminals downstream; an annealed segment carries m
times its annealed count, so its radius is the annealed one.

Diagnostics per territory (:func:`grow_batch`): C_v and C_w of the subtree; a uniform random sample
of the territory's tissue (as many points as it has voxels) and how many lie within twice the
fine supply radius of one of its fine terminals (a lower bound of the coverage: a point may be
nearer to a neighbour's terminal); the fine segments that cross a cavity (the exclusion domain
outside the tissue, exact voxel traversal) or leave the tissue, and their lengths.

The source run is read by :mod:`vasc_pipeline.engine.source` (:func:`read_source`, re-exported
here). Pure NumPy and one small numba kernel (:func:`vasc_pipeline.kernel.voxel_code_lengths`); no Hydra, no Dask, no
store: :mod:`vasc_pipeline.pipeline.extend` fans the batches out and
:mod:`vasc_pipeline.store.extended` writes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernel import voxel_code_lengths
from ..model.physics import CostTables, Physics, cost_tables, segment_factors
from ..model.rng import seed_state
from ..model.topology import KIND_TERMINAL, KIND_TERRITORY_ROOT, segment_lengths, terminals_downstream
from .cco import SiteDomain, grow_arrays
from .source import ExtendError, Source, read_source, source_digest

__all__ = [
    "KIND_TERRITORY_ROOT",
    "CODE_OUTSIDE",
    "CODE_TERRITORY",
    "CODE_TISSUE",
    "CODE_CAVITY",
    "ExtendError",
    "Source",
    "read_source",
    "source_digest",
    "Growth",
    "ExtensionPlan",
    "TerritoryInput",
    "plan_extension",
    "territory_labels",
    "per_territory",
    "growth_rng",
    "coverage_rng",
    "grow_territory",
    "grow_batch",
    "segment_voxel_lengths",
    "TERRITORY_FIELDS",
]

# tree/kind of an annealed terminal in the whole tree (KIND_TERRITORY_ROOT, a pass-through node of
# vasc_pipeline.model.topology): the root of its territory's subtree, one child
# The voxel codes of a territory's box (TerritoryInput.box)
CODE_OUTSIDE, CODE_TERRITORY, CODE_TISSUE, CODE_CAVITY = 0, 1, 2, 3

# Per-territory diagnostics (name, dtype, units, long name): the columns grow_batch returns
TERRITORY_FIELDS = (
    ("n_voxels", "int64", "1", "tissue voxels of the territory"),
    ("volume", "float64", "W", "C_v of the territory's subtree"),
    ("power", "float64", "W", "C_w of the territory's subtree"),
    ("drawn", "int64", "1", "fine sites drawn (the distance criterion rejects some)"),
    ("samples", "int64", "1", "uniform tissue points sampled in the territory"),
    ("covered", "int64", "1", "sampled points within twice the fine supply radius of a fine terminal of the territory"),
    ("cavity_segments", "int64", "1", "fine segments crossing a cavity voxel"),
    ("cavity_length", "float64", "m", "length of the fine segments inside cavity voxels"),
    ("outside_length", "float64", "m", "length of the fine segments outside the tissue (cavities included)"),
    ("length", "float64", "m", "length of the fine segments"),
)


# --------------------------------------------------------------------------------------------
# Territories and the plan


def per_territory(n_fine: int, n_annealed: int) -> int:
    """m = round(n_fine / N), the fine terminals of every territory (ExtendError below 1)."""
    m = int(math.floor(n_fine / n_annealed + 0.5))
    if m < 1:
        raise ExtendError(
            f"extend.n_terminals={n_fine} is too few for the run's {n_annealed} annealed terminals: every one "
            f"needs at least one fine terminal below it, and the count is rounded to the nearest multiple of "
            f"N = {n_annealed}; accepted: extend.n_terminals >= {(n_annealed + 1) // 2}"
        )
    return m


def growth_rng(seed: int, index: int) -> np.ndarray:
    """The generator of territory ``index``'s growth: a stream of its own (stream 0 is the run's)."""
    return seed_state(int(seed), 1 + 2 * int(index))


def coverage_rng(seed: int, index: int) -> np.ndarray:
    """The generator of territory ``index``'s coverage sample (never the growth's)."""
    return seed_state(int(seed), 2 + 2 * int(index))


def territory_labels(voxels: np.ndarray, shape, origin, voxel_size: float, points: np.ndarray) -> np.ndarray:
    """int64 (n_voxels,): the index of the point (row of ``points``, m) nearest to each voxel's centre."""
    from scipy.spatial import cKDTree

    z, y, x = np.unravel_index(voxels, shape)
    centres = origin + voxel_size * np.stack([x, y, z], axis=1)
    _, label = cKDTree(points).query(centres)
    return np.asarray(label, dtype=np.int64)


@dataclass(frozen=True)
class Growth:
    """What every territory's growth shares (small: shipped with each batch).

    ``tables`` are the cost tables of a territory, :func:`~vasc_pipeline.model.physics.cost_tables`
    of ``territory_physics``; ``candidates``, ``max_tries``, ``shrink`` the CCO settings
    (``method.*``); ``fine_radius`` r_t' [m] and ``gamma`` the whole tree's radius law;
    ``supply_radius`` the fine supply radius [m] (the coverage test's 2 R).
    """

    per_territory: int
    seed: int
    voxel_size: float
    ndim: int
    territory_physics: Physics
    tables: CostTables
    candidates: int
    max_tries: int
    shrink: float
    fine_radius: float
    gamma: float
    supply_radius: float
    node_start: int

    @property
    def nodes_per_territory(self) -> int:
        return 2 * self.per_territory - 1


@dataclass(frozen=True)
class TerritoryInput:
    """One territory, as a task needs it.

    ``box``: uint8, the smallest box of the grid holding the territory's voxels and its root's
    voxel, coded CODE_TERRITORY (the territory), CODE_TISSUE (other tissue), CODE_CAVITY
    (exclusion domain outside the tissue) or CODE_OUTSIDE; ``box_origin`` the centre of its voxel
    [0, 0, 0] [m]; ``root`` the annealed terminal's position [m] and ``root_node`` its node index.
    """

    index: int
    root_node: int
    root: np.ndarray
    box: np.ndarray
    box_origin: np.ndarray
    n_voxels: int


@dataclass
class ExtensionPlan:
    """The territories of a source and the layout of its whole tree (held by the driver)."""

    source: Source
    growth: Growth
    n_requested: int
    voxels: np.ndarray  # int64: tissue voxels (flat), grouped by territory, increasing within each
    starts: np.ndarray  # int64 (N + 1,): territory i's voxels are voxels[starts[i]:starts[i + 1]]
    codes: np.ndarray  # uint8 (z, y, x): CODE_TISSUE, CODE_CAVITY or CODE_OUTSIDE

    @property
    def n_territories(self) -> int:
        return self.source.n_terminals

    @property
    def per_territory(self) -> int:
        return self.growth.per_territory

    @property
    def n_fine(self) -> int:
        return self.per_territory * self.n_territories

    @property
    def n_nodes(self) -> int:
        return self.growth.node_start + self.n_territories * self.growth.nodes_per_territory

    def node_offset(self, territory: int) -> int:
        return self.growth.node_start + int(territory) * self.growth.nodes_per_territory

    @property
    def whole_physics(self) -> Physics:
        """The whole tree's physics: N = m N_annealed, the supply radius of a fine terminal."""
        p = self.source.physics
        return Physics(**{**p.as_attrs(), "n_terminals": self.n_fine, "supply_radius": self.growth.supply_radius})

    def annealed_part(self) -> dict[str, np.ndarray]:
        """The annealed tree in the whole tree's layout: positions and topology as they were, the
        annealed terminals of kind :data:`KIND_TERRITORY_ROOT`, radii from the whole tree's law."""
        s = self.source
        kind = s.kind.copy()
        kind[s.terminals] = KIND_TERRITORY_ROOT
        n = terminals_downstream(s.parent, s.kind) * self.per_territory
        radius = np.where(s.parent >= 0, self.growth.fine_radius * n ** (1.0 / self.growth.gamma), 0.0)
        return {"parent": s.parent.copy(), "position": s.position.copy(), "radius": radius, "kind": kind}

    def annealed_costs(self) -> tuple[float, float]:
        """(C_v, C_w) [W] of the annealed segments under the whole tree's law (their annealed cost)."""
        s = self.source
        seg = np.flatnonzero(s.parent >= 0)
        n = (terminals_downstream(s.parent, s.kind) * self.per_territory)[seg]
        factors = segment_factors(self.whole_physics, n)
        length = segment_lengths(s.parent, s.position)[seg]
        return float(np.sum(factors[0] * length)), float(np.sum(factors[1] * length))

    def batch(self, lo: int, hi: int) -> list[TerritoryInput]:
        """The inputs of territories ``lo`` .. ``hi - 1``."""
        s = self.source
        shape = np.array(s.mask.shape)
        roots = s.terminals
        out = []
        for i in range(lo, hi):
            own = self.voxels[self.starts[i] : self.starts[i + 1]]
            root = s.position[roots[i]]
            u = (root - s.origin) / s.voxel_size
            root_zyx = np.clip(np.floor(u[::-1] + 0.5).astype(np.int64), 0, shape - 1)
            zyx = np.stack(np.unravel_index(own, s.mask.shape), axis=1) if own.size else np.empty((0, 3), np.int64)
            first = np.minimum(zyx.min(axis=0), root_zyx) if own.size else root_zyx
            last = np.maximum(zyx.max(axis=0), root_zyx) + 1 if own.size else root_zyx + 1
            box = self.codes[first[0] : last[0], first[1] : last[1], first[2] : last[2]].copy()
            if own.size:
                local = zyx - first
                box[local[:, 0], local[:, 1], local[:, 2]] = CODE_TERRITORY
            else:  # no voxel centre nearest to it: its sites are drawn in its own voxel
                local = root_zyx - first
                box[local[0], local[1], local[2]] = CODE_TERRITORY
            box_origin = s.origin + s.voxel_size * first[::-1].astype(np.float64)
            out.append(TerritoryInput(i, int(roots[i]), root.copy(), box, box_origin, int(own.size)))
        return out


def plan_extension(
    source: Source, n_fine: int, seed: int | None = None, method=None, labels: np.ndarray | None = None
) -> ExtensionPlan:
    """Territories, fine count and layout of ``source``'s whole tree of about ``n_fine`` terminals.

    ``seed``: default the source run's; ``method``: ``candidates``, ``max_tries``, ``shrink``
    (default :class:`~vasc_pipeline.config.MethodConfig`'s); ``labels``: the territory of every
    tissue voxel, if known (:func:`territory_labels`).
    """
    from ..config.schema import MethodConfig

    method = method or MethodConfig()
    n_annealed = source.n_terminals
    if source.terminals.size != n_annealed:
        raise ExtendError(
            f"run store {str(source.path)!r}: its tree holds {source.terminals.size} terminals (kind 2), its physics "
            f"{n_annealed}: not a tree this version can extend"
        )
    m = per_territory(n_fine, n_annealed)
    p = source.physics
    voxels = np.flatnonzero(source.mask.reshape(-1)).astype(np.int64)
    if labels is None:
        labels = territory_labels(
            voxels, source.mask.shape, source.origin, source.voxel_size, source.position[source.terminals]
        )
    order = np.argsort(labels, kind="stable")  # stable: increasing flat index within a territory
    starts = np.concatenate(([0], np.cumsum(np.bincount(labels, minlength=n_annealed)))).astype(np.int64)
    codes = np.where(source.mask != 0, CODE_TISSUE, np.where(source.exclusion != 0, CODE_CAVITY, CODE_OUTSIDE))
    # A territory's own problem: m terminals fed through an annealed terminal segment (r_t, Q0 / N).
    territory_physics = Physics(
        **{
            **p.as_attrs(),
            "n_terminals": m,
            "n_inlets": 1,
            "inlet_radius": p.terminal_radius,
            "total_flow": p.total_flow / n_annealed,
            "supply_radius": p.supply_radius * m ** (-1.0 / source.ndim),
        }
    )
    whole = Physics(**{**p.as_attrs(), "n_terminals": m * n_annealed})
    growth = Growth(
        per_territory=m,
        seed=source.seed if seed is None else int(seed),
        voxel_size=source.voxel_size,
        ndim=source.ndim,
        territory_physics=territory_physics,
        tables=cost_tables(territory_physics),
        candidates=int(method.candidates),
        max_tries=int(method.max_tries),
        shrink=float(method.shrink),
        fine_radius=whole.terminal_radius,
        gamma=float(p.gamma),
        supply_radius=territory_physics.supply_radius,
        node_start=int(source.parent.size),
    )
    return ExtensionPlan(source, growth, int(n_fine), voxels[order], starts, codes.astype(np.uint8))


# --------------------------------------------------------------------------------------------
# Growing territories


def segment_voxel_lengths(box, origin, voxel_size: float, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """float64 (n, 5): the length [m] of each segment p0 -> p1 inside voxels of each code of ``box``
    (columns CODE_OUTSIDE, CODE_TERRITORY, CODE_TISSUE, CODE_CAVITY) and beyond the box (column 4)."""
    p0 = np.ascontiguousarray(p0, dtype=np.float64).reshape(-1, 3)
    p1 = np.ascontiguousarray(p1, dtype=np.float64).reshape(-1, 3)
    out = np.empty((p0.shape[0], 5))
    voxel_code_lengths(
        np.ascontiguousarray(box, dtype=np.uint8),
        np.ascontiguousarray(origin, dtype=np.float64),
        float(voxel_size),
        p0,
        p1,
        out,
    )
    return out


def grow_territory(t: TerritoryInput, g: Growth):
    """Grow one territory's subtree: (grown arrays of :func:`~vasc_pipeline.engine.cco.grow_arrays`,
    the territory's domain). Node 0 of the grown arrays is the root (the annealed terminal). No
    new segment crosses a cavity voxel of the box (``method.avoid_cavities`` of a plain growth)."""
    domain = SiteDomain(
        np.flatnonzero(t.box.reshape(-1) == CODE_TERRITORY).astype(np.int64),
        tuple(t.box.shape),
        t.box_origin,
        g.voxel_size,
        g.ndim,
    )
    cavity = (t.box == CODE_CAVITY).astype(np.uint8)
    grown = grow_arrays(
        t.root[None], g.per_territory, g.tables, domain, g, growth_rng(g.seed, t.index), forbidden=cavity
    )
    return grown, domain


def grow_batch(g: Growth, inputs: list[TerritoryInput]) -> dict[str, np.ndarray]:
    """Grow the subtrees of a batch of territories (consecutive indices); flat arrays for the store.

    Returns
    -------
    dict
        ``start`` (the first territory), the batch's nodes in the whole tree's layout: ``parent``
        int64, ``position`` float64 (n, 3) [m], ``radius`` float64 [m], ``kind`` int8; and one
        entry per :data:`TERRITORY_FIELDS` (one value per territory).
    """
    from scipy.spatial import cKDTree

    m = g.per_territory
    per = g.nodes_per_territory
    kind = np.concatenate([np.full(m, KIND_TERMINAL, np.int8), np.full(m - 1, 1, np.int8)])
    parents, positions, radii, kinds = [], [], [], []
    columns = {name: np.zeros(len(inputs), dtype=dtype) for name, dtype, _, _ in TERRITORY_FIELDS}
    reach = 2.0 * g.supply_radius
    for j, t in enumerate(inputs):
        grown, domain = grow_territory(t, g)
        offset = g.node_start + t.index * per - 1  # local node k >= 1 is node offset + k
        local = grown.parent[1:]
        parents.append(np.where(local == 0, t.root_node, local + offset))
        position = grown.position[1:]
        positions.append(position)
        radii.append(g.fine_radius * grown.n_down[1:].astype(np.float64) ** (1.0 / g.gamma))
        kinds.append(kind)
        columns["n_voxels"][j] = t.n_voxels
        columns["volume"][j], columns["power"][j] = grown.costs
        columns["drawn"][j] = grown.drawn
        sample = domain.draw(max(t.n_voxels, 1), coverage_rng(g.seed, t.index))
        terminals = position[:m]
        near = cKDTree(terminals).query(sample, distance_upper_bound=reach)[0]
        columns["samples"][j] = sample.shape[0]
        columns["covered"][j] = int(np.count_nonzero(near <= reach))
        ends = grown.position[grown.parent[1:]]
        pieces = segment_voxel_lengths(t.box, t.box_origin, g.voxel_size, position, ends)
        cavity = pieces[:, CODE_CAVITY]
        columns["cavity_segments"][j] = int(np.count_nonzero(cavity > 0))
        columns["cavity_length"][j] = float(cavity.sum())
        columns["outside_length"][j] = float((pieces[:, CODE_OUTSIDE] + cavity + pieces[:, 4]).sum())
        columns["length"][j] = float(pieces.sum())
    out = {
        "start": np.int64(inputs[0].index if inputs else 0),
        "parent": np.concatenate(parents) if parents else np.empty(0, np.int64),
        "position": np.concatenate(positions) if positions else np.empty((0, 3)),
        "radius": np.concatenate(radii) if radii else np.empty(0),
        "kind": np.concatenate(kinds) if kinds else np.empty(0, np.int8),
    }
    out.update(columns)
    return out
