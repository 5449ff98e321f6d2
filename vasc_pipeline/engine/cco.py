"""Constrained constructive optimisation (CCO): the constructive baseline on our tissue and cost.

Schreiner & Buxbaum (1993) and Karch et al. (1999) grow a tree one terminal at a time:
each new terminal is joined to the best of the nearest existing segments by a new
bifurcation placed at the optimum of the local connection, and nothing already built is
changed again except the flows and radii upstream. Here the substrate and the cost are the
anneal's own (:func:`vasc_pipeline.engine.build_problem`): the same tissue, Murray radii
r = r_t n^(1/gamma) with the *final* N (so a partial tree's cost is exactly the final
tree's cost of its segments), equal terminal flows, and the vascular cost

    C_v + C_w = sum_i w(n_i) L_i,   w(n) = volume[n] + power[n]   (physics.cost_tables).

Adding a terminal t below segment j (node j, parent p, n_j terminals below) replaces the
segment p-j by p-b, b-j and b-t (weights w(n_j + 1), w(n_j), w(1)) and raises n by one on
every segment from p up to the inlet, so

    dC = w(n_j+1)|b-p| + w(n_j)|b-j| + w(1)|b-t| - w(n_j) L_j
         + sum over the ancestors a of j of (w(n_a + 1) - w(n_a)) L_a,

with b the weighted Fermat-Weber point of (p, j, t) (:func:`vasc_pipeline.kernel.fermat.fermat_point`:
the vertex optimality test, then Weiszfeld iterations; exact up to 1e-12 of the triangle's
size).
``method.candidates`` segments nearest the new terminal (point-segment distance) are
evaluated and the cheapest is taken; which inlet's tree a terminal joins follows from the
cost, since the candidates span every tree.

Terminal sites: given (``terminals.path``, in file order, or in a seeded random order with
``method.order=random``), or drawn uniformly in the tissue (the draw of
:func:`vasc_pipeline.model.tree.random_terminal_sites`, one site at a time) subject to the
distance criterion of Schreiner's CCO: a site closer than d_crit to any existing segment is
rejected, d_crit = f (V / k)^(1/3) (in 2-D (A / k)^(1/2)) with k the terminals already in
the tree; f starts at 1 and is multiplied by ``method.shrink`` after every
``method.max_tries`` consecutive rejections (and stays lowered: the criterion calibrates
itself once and keeps shrinking with the tree). The first K terminals (K inlets) are
joined straight to the inlets, matched to them by the cheapest assignment.

Cavities (``method.avoid_cavities=true``): no new segment may cross a voxel of the tissue's
cavities (its exclusion domain outside the tissue, :attr:`~vasc_pipeline.model.tissue.Tissue.cavity`;
:func:`~vasc_pipeline.kernel.growth.crosses`, a voxel walk). A connection that would is not made and the cheapest other
candidate is; a site none of whose candidates can be joined is drawn again (not counted against
the distance criterion), and random first sites are drawn again until their joins to the inlets
are clear. Off by default (the earlier trees, bit for bit); the whole tree's territories
(:mod:`vasc_pipeline.engine.extend`) always grow with it.

Supply, exclusion and pressure are not seen by the growth; :func:`grow` evaluates them on
the final tree with :func:`vasc_pipeline.model.costs.full_costs`, so the stored costs compare
with the anneal's. Randomness comes from the run's xoshiro state (``rng``): a run is a pure
function of (config, seed).

One growth serves every caller: :func:`grow_arrays` grows from given inlets over a
:class:`SiteDomain` (any set of voxels) with given cost tables, and :func:`grow_tree` is it on a
run's problem; the whole tree below an annealed one (:mod:`vasc_pipeline.engine.extend`) grows
each territory with it, rooted at the annealed terminal.

Usable without Hydra or Dask::

    from vasc_pipeline import cco, config, costs, engine
    problem = engine.build_problem(config.compose(["method=cco", "tissue=plane2d"]))
    result = cco.grow(problem, seed=0)
    result.tree, costs.vascular_cost(result.costs)
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from ..kernel.fermat import fermat_point
from ..kernel.growth import MAX_FORBIDDEN_REFUSALS, connection_cost, crosses, grow_terminals
from ..kernel.state import _add
from ..model.costs import full_costs, total_cost
from ..model.physics import cost_tables
from ..model.rng import next_below, seed_state
from ..model.tree import Tree, sites_in_voxels
from ..store.trace import TRACE_NAMES

# The numba kernel lives in vasc_pipeline.kernel.growth (fermat_point in kernel.fermat); its public
# names stay importable from here, where tests and callers have always found them.
__all__ = [
    "CCOResult",
    "Grown",
    "SiteDomain",
    "grow",
    "grow_arrays",
    "grow_tree",
    "fermat_point",
    "connection_cost",
    "crosses",
    "TRACE_NAMES",
]

# A CCO run's trace has the anneal's columns (TRACE_NAMES): "step" counts terminals in the
# tree, "temperature" is NaN, "acceptance" is the fraction of drawn sites the distance
# criterion accepted for that terminal.


@dataclass
class CCOResult:
    """The outcome of :func:`grow`.

    Attributes
    ----------
    tree : Tree
        Layout of :class:`~vasc_pipeline.model.tree.Tree`; terminal K + i is the i-th added.
    costs : dict
        The growth's running sums of C_v and C_w [W]; supply, exclusion and pressure
        evaluated on the final tree; ``total`` the annealed, scaled C.
    costs_recomputed : dict
        :func:`~vasc_pipeline.model.costs.full_costs` of the final tree (every term).
    trace : dict of float64 / int64 arrays
        One record per terminal added (``TRACE_NAMES``): C_v, C_w of the partial tree.
    tries : int
        Sites drawn (random sites only; equals N with given sites).
    distance_factor : float
        The final factor f of the distance criterion (1 with given sites).
    wall_seconds : float
    """

    tree: Tree
    costs: dict
    costs_recomputed: dict
    trace: dict = field(repr=False)
    tries: int = 0
    distance_factor: float = 1.0
    wall_seconds: float = 0.0


# --------------------------------------------------------------------------------------------
# Public wrappers


def _site_order(problem, rng: np.ndarray) -> np.ndarray | None:
    """Given sites in the order they are added (file order, or a seeded shuffle)."""
    if problem.sites is None:
        return None
    sites = np.ascontiguousarray(problem.sites, dtype=np.float64)
    if problem.config.method.order == "random":
        order = np.arange(len(sites))
        for i in range(order.size - 1, 0, -1):  # Fisher-Yates with the run's generator
            j = next_below(rng, i + 1)
            order[i], order[j] = order[j], order[i]
        sites = sites[order]
    return sites


@dataclass(frozen=True)
class SiteDomain:
    """Where random terminal sites are drawn: a set of voxels of an isotropic grid.

    Attributes
    ----------
    voxels : int64 (n_voxels,)
        Flat (z, y, x) indices of the voxels, increasing.
    shape : (nz, ny, nx)
    origin : float64 (3,)
        [x, y, z] of the centre of voxel [0, 0, 0] [m].
    voxel_size : float
        Edge of the voxels [m].
    ndim : int
        3, or 2 for one voxel layer (no offset in z).
    """

    voxels: np.ndarray
    shape: tuple
    origin: np.ndarray
    voxel_size: float
    ndim: int

    @classmethod
    def of_tissue(cls, tissue) -> "SiteDomain":
        """The tissue voxels of a :class:`~vasc_pipeline.model.tissue.Tissue`."""
        voxels = np.flatnonzero(tissue.mask.reshape(-1)).astype(np.int64)
        return cls(voxels, tuple(tissue.shape), tissue.origin, float(tissue.voxel_size), int(tissue.ndim))

    @property
    def measure(self) -> float:
        """Volume [m^3] (area [m^2] when ``ndim`` is 2) of the voxels, as Tissue.measure counts it."""
        return self.voxels.size * self.voxel_size**self.ndim

    def draw(self, n: int, rng: np.ndarray) -> np.ndarray:
        """``n`` uniform points in the voxels (:func:`~vasc_pipeline.model.tree.sites_in_voxels`)."""
        return sites_in_voxels(self.voxels, self.shape, self.origin, self.voxel_size, self.ndim, n, rng)


@dataclass
class Grown:
    """The arrays of a CCO growth (:func:`grow_arrays`), in the layout of :class:`~vasc_pipeline.model.tree.Tree`."""

    parent: np.ndarray  # int64 (2N,)
    children: np.ndarray  # int64 (2N, 2)
    position: np.ndarray  # float64 (2N, 3), m
    n_down: np.ndarray  # int64 (2N,)
    trace: np.ndarray  # float64 (N, 3): C_v, C_w after each terminal, sites drawn for it
    costs: np.ndarray  # float64 (2,): C_v, C_w of the grown tree [W], the running sums
    drawn: int
    factor: float


def grow_arrays(
    inlets: np.ndarray,
    n_terminals: int,
    tables,
    domain: SiteDomain,
    method,
    rng: np.ndarray,
    sites: np.ndarray | None = None,
    forbidden: np.ndarray | None = None,
) -> Grown:
    """Grow N terminals from fixed inlets: the CCO growth on plain arrays, without a Problem.

    Parameters
    ----------
    inlets : float64 (K, 3)
        Inlet positions [m].
    n_terminals : int
        N.
    tables : CostTables
        :func:`~vasc_pipeline.model.physics.cost_tables` of the physics whose radius law the
        weights w(n) follow (rows up to n = N at least).
    domain : SiteDomain
        Where random sites are drawn (and whose measure sets the distance criterion).
    method
        ``candidates``, ``max_tries`` and ``shrink`` (a :class:`~vasc_pipeline.config.MethodConfig`).
    rng : uint64 (4,)
        The generator, advanced in place.
    sites : float64 (N, 3), optional
        Given sites in the order they are added (then ``domain`` draws nothing).
    forbidden : uint8 (z, y, x), optional
        On the domain's grid: voxels no new segment may cross (cavities). A connection that
        would is not made (the cheapest other candidate is; a site with none is drawn again),
        and random first sites are drawn again until their straight joins to the inlets cross
        none (given ones are taken as they are).
    """
    inlets = np.atleast_2d(np.asarray(inlets, dtype=np.float64))
    n, k = int(n_terminals), len(inlets)
    w_vol = np.ascontiguousarray(tables.volume)
    w_pow = np.ascontiguousarray(tables.power)
    tree = _empty_tree(n, inlets)
    avoid = forbidden is not None and bool(np.any(forbidden))
    if avoid:
        forbidden = np.ascontiguousarray(forbidden, dtype=np.uint8)
    else:  # numba's argument types stay those of the unconstrained growth
        forbidden = np.zeros((1, 1, 1), dtype=np.uint8)
    first = _first_sites(inlets, domain, rng, sites, forbidden if avoid else None)
    sums = _join_first_terminals(tree, inlets, first, w_vol, w_pow, n)
    drawn, factor = _grow_the_rest(tree, sums, rng, w_vol, w_pow, domain, method, sites, k, forbidden, avoid)
    parent, children, position, n_down, _ = tree
    costs, compensation, trace = sums
    return Grown(parent, children, position, n_down, trace, costs + compensation, int(drawn) + k, float(factor))


def _empty_tree(n: int, inlets: np.ndarray) -> tuple[np.ndarray, ...]:
    """(parent, children, position, n_down, seg_length) of 2N nodes, the inlets placed, nothing joined."""
    m = 2 * n
    parent = np.full(m, -1, dtype=np.int64)
    children = np.full((m, 2), -1, dtype=np.int64)
    position = np.zeros((m, 3))
    n_down = np.zeros(m, dtype=np.int64)
    seg_length = np.zeros(m)
    position[: len(inlets)] = inlets
    return parent, children, position, n_down, seg_length


def _first_sites(inlets, domain: SiteDomain, rng, sites, forbidden) -> np.ndarray:
    """The first K sites (one per inlet): given, or drawn, and with ``forbidden`` drawn again until
    no straight join to an inlet crosses it (at most MAX_FORBIDDEN_REFUSALS times)."""
    k = len(inlets)
    if sites is not None:
        return sites[:k]
    first = domain.draw(k, rng)
    if forbidden is None:
        return first
    grid_origin = np.ascontiguousarray(domain.origin, dtype=np.float64)
    for _ in range(MAX_FORBIDDEN_REFUSALS):
        if not any(crosses(forbidden, grid_origin, domain.voxel_size, inlets[j], first[j]) for j in range(k)):
            break
        first = domain.draw(k, rng)
    return first


def _join_first_terminals(tree, inlets, first, w_vol, w_pow, n: int) -> tuple[np.ndarray, ...]:
    """Join the first K terminals straight to the inlets, by the cheapest assignment (in place).

    Returns (costs, compensation, trace): the running sums of C_v and C_w (compensated) and
    the trace (N, 3) with its first K rows written.
    """
    parent, children, position, n_down, seg_length = tree
    k = len(inlets)
    best = min(
        itertools.permutations(range(k)),
        key=lambda perm: sum(np.linalg.norm(first[perm[j]] - inlets[j]) for j in range(k)),
    )
    costs, compensation = np.zeros(2), np.zeros(2)
    trace = np.zeros((n, 3))
    for j in range(k):
        t = k + j
        position[t] = first[best[j]]
        parent[t] = j
        children[j, 0] = t
        n_down[t] = n_down[j] = 1
        seg_length[t] = np.linalg.norm(position[t] - position[j])
        _add(costs, compensation, 0, float(w_vol[1]) * seg_length[t])
        _add(costs, compensation, 1, float(w_pow[1]) * seg_length[t])
        trace[j] = (costs[0] + compensation[0], costs[1] + compensation[1], 1.0)
    return costs, compensation, trace


def _grow_the_rest(tree, sums, rng, w_vol, w_pow, domain: SiteDomain, method, sites, k, forbidden, avoid):
    """Terminals K .. N - 1 by the kernel (in place); returns (sites drawn, final distance factor)."""
    parent, children, position, n_down, seg_length = tree
    costs, compensation, trace = sums
    # one argument per flat array, as grow_terminals' signature lists them (numba takes no struct)
    return grow_terminals(
        parent,
        children,
        position,
        n_down,
        seg_length,
        costs,
        compensation,
        rng,
        w_vol,
        w_pow,
        sites if sites is not None else np.zeros((0, 3)),
        sites is None,
        domain.voxels,
        np.array(domain.shape, dtype=np.int64),
        np.ascontiguousarray(domain.origin, dtype=np.float64),
        float(domain.voxel_size),
        domain.ndim == 2,
        float(domain.measure),
        int(domain.ndim),
        int(method.candidates),
        int(method.max_tries),
        float(method.shrink),
        1.0,
        trace,
        k,
        forbidden,
        avoid,
    )


def grow_tree(problem, rng: np.ndarray) -> tuple[Tree, np.ndarray, int, float]:
    """The CCO tree of ``problem``, drawing from ``rng`` (uint64 (4,), advanced in place).

    Returns (tree, trace (N, 3): C_v, C_w after each terminal and sites drawn for it,
    sites drawn in all, final distance factor). The anneal's ``anneal.init=cco`` uses this.
    """
    physics, tissue, method = problem.physics, problem.tissue, problem.config.method
    sites = _site_order(problem, rng)
    grown = grow_arrays(
        tissue.inlets,
        physics.n_terminals,
        cost_tables(physics),
        SiteDomain.of_tissue(tissue),
        method,
        rng,
        sites,
        forbidden=tissue.cavity.astype(np.uint8) if method.avoid_cavities else None,
    )
    tree = Tree(grown.parent, grown.children, grown.position, grown.n_down, physics.n_inlets)
    return tree, grown.trace, grown.drawn, grown.factor


def grow(problem, seed: int | None = None, rng: np.ndarray | None = None) -> CCOResult:
    """Grow the CCO tree of (problem, seed) and evaluate every cost term on it.

    Parameters
    ----------
    problem : vasc_pipeline.engine.Problem
        From :func:`~vasc_pipeline.engine.build_problem` (any tissue, method settings in
        ``problem.config.method``).
    seed : int, optional
        Default ``problem.config.seed``; the generator is ``rng.seed_state(seed)``.
    rng : uint64 (4,), optional
        Draw from this generator state instead (advanced in place).
    """
    start = time.perf_counter()
    if rng is None:
        rng = seed_state(problem.config.seed if seed is None else int(seed))
    tree, rows, drawn, factor = grow_tree(problem, rng)
    recomputed = full_costs(tree, problem.tissue, problem.physics, problem.terms)
    costs = dict(recomputed)
    costs["volume"], costs["power"] = float(rows[-1, 0]), float(rows[-1, 1])  # the growth's running sums
    costs["total"] = total_cost(costs, problem.physics)
    k = problem.physics.n_inlets
    steps = np.arange(1, tree.n_terminals + 1, dtype=np.int64)[k - 1 :]
    body = rows[k - 1 :]
    zeros = np.zeros(body.shape[0])
    trace = {
        "step": steps,
        "temperature": np.full(body.shape[0], np.nan),
        "volume": body[:, 0].copy(),
        "power": body[:, 1].copy(),
        "supply": zeros.copy(),
        "exclusion": zeros.copy(),
        "pressure": zeros.copy(),
        "total": body[:, 0] + body[:, 1],
        "acceptance": 1.0 / body[:, 2],
    }
    trace["acceptance"][0] = 1.0
    return CCOResult(
        tree=tree,
        costs=costs,
        costs_recomputed=recomputed,
        trace=trace,
        tries=drawn,
        distance_factor=factor,
        wall_seconds=time.perf_counter() - start,
    )
