"""One tree annealed in parts: a round of a phase of the anneal as independent anneals of parts.

Two kinds of part (:func:`make_parts`), both cut from the tree by :func:`cut`:

- *parts of subtrees*: whole subtrees of about N/k terminals, hanging from fixed
  pseudo-inlets (their parents in the whole tree); their bifurcations move and their nodes
  swap, a swap between two pseudo-inlets' trees keeping their terminal counts, so that no
  segment above the parts changes; their terminals stay put;
- *parts of terminals*: terminals grouped by place, each hanging from its fixed parent; they
  move and trade parents, but only where their supply sphere stays inside their group's region
  (:func:`part_regions`: every tissue voxel belongs to the group of its nearest terminal), so
  that no voxel's supply count changes in two parts.

Every cost term is a sum over segments, voxels or terminals that the parts change in disjoint
pieces: their changes add up to the whole tree's, exactly (:func:`merge_parts` recomputes the
whole tree's sums). For C_p, each pseudo-inlet keeps its pressure in the whole tree (no segment
above a part changes), so a part's terminal pressures are the whole tree's. Within a part the
moves are the kernel's own, so for every move a part allows, its decision is the whole tree's.

Each part draws from its own generator, seeded from (phase seed, part index), so the result
is a function of the tree, the phase seed and ``k``, not of how many workers ran the parts or
in which order they finished (``map`` is any order-preserving map: the builtin, a thread
pool's, as the kernel releases the GIL, or a cluster's). The phases themselves are
:func:`vasc_pipeline.engine.run.run_phase`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .. import kernel
from ..kernel.margins import mark_margins
from ..model.rng import seed_state
from .problem import Problem, restore_state

__all__ = [
    "Part",
    "cut",
    "part_regions",
    "make_parts",
    "part_model",
    "part_state",
    "anneal_parts",
    "anneal_part",
    "PART_RESULT",
    "merge_parts",
    "phase_ends",
]


@dataclass
class Part:
    """One part of a phase: its nodes in the part state's order and where its terminals may be.

    ``nodes``: global node ids, pseudo-inlets first (the parents of the subtree roots
    ``roots``, one for each parent), then the terminals, then the bifurcations of the subtrees;
    ``n_inlets`` and ``n_terminals`` count the first two groups. ``mask``: for a part of
    terminals, uint8 on the box ``corner`` (z, y, x index of its first voxel) of the supply
    grid, 1 where its terminals may be; the box holds every voxel their supply spheres may
    reach (:data:`MARGIN_SLACK` beyond the supply radius), and the part's kernel sees the
    supply map and the tissue only there. None for a part of subtrees, whose terminals stay
    put and which sees neither. ``inlet_pressure``: float64 (n_inlets,) [Pa], each
    pseudo-inlet's pressure in the whole tree.
    """

    nodes: np.ndarray
    roots: np.ndarray
    n_inlets: int
    n_terminals: int
    mask: np.ndarray | None
    inlet_pressure: np.ndarray
    corner: np.ndarray | None = None

    @property
    def box(self) -> tuple[slice, ...]:
        """The slices of the supply grid that ``mask`` covers (a part of terminals)."""
        return tuple(slice(a, a + n) for a, n in zip(self.corner, self.mask.shape))


def _subtree_nodes(children: np.ndarray, roots) -> np.ndarray:
    """Every node of the subtrees under ``roots`` (the roots included), sorted."""
    nodes, stack = [], [int(r) for r in roots]
    while stack:
        node = stack.pop()
        nodes.append(node)
        if children[node, 0] >= 0:
            stack.extend(children[node].tolist())
    return np.sort(np.array(nodes, dtype=np.int64))


def cut(
    parent, children, n_downstream, position, n_inlets: int, k: int, shift: np.ndarray, leaves: bool = False
) -> list[np.ndarray]:
    """The roots of whole subtrees grouped into ``k`` parts of about N/k terminals each.

    The largest subtree is split into its two children until none holds more than N/(4k)
    terminals; the subtrees are then ordered along a Morton curve of their terminals' centroid
    (the cloud placed at ``shift`` in [0, 1)^3 within a grid twice its size, so that the cut
    moves from phase to phase) and the curve is cut into ``k`` runs of about N/k terminals.
    Returns one int64 array of roots per part, in curve order.
    """
    n_terminals = int(sum(n_downstream[children[i, 0]] for i in range(n_inlets)))
    limit = 1 if leaves else max(1, n_terminals // (4 * k))
    roots = [int(children[i, 0]) for i in range(n_inlets)]
    final = []
    while roots:
        r = roots.pop()
        if n_downstream[r] > limit and children[r, 0] >= 0:
            roots.extend((int(children[r, 0]), int(children[r, 1])))
        else:
            final.append(r)
    if leaves:  # each root a terminal: its own position
        centroids = position[final]
    else:
        centroids = np.empty((len(final), 3))
        for i, r in enumerate(final):
            nodes = _subtree_nodes(children, [r])
            centroids[i] = position[nodes[children[nodes, 0] < 0]].mean(axis=0)
    lo, hi = centroids.min(axis=0), centroids.max(axis=0)
    cells = 1024
    # the cloud fills half of each axis of the curve's grid, placed at ``shift`` along it
    grid = np.floor(((centroids - lo) / np.maximum(hi - lo, 1e-300) + shift) * (cells / 2 - 1)).astype(np.int64)
    keys = np.zeros(len(final), dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            keys |= ((grid[:, axis] >> bit) & 1) << (3 * bit + axis)
    order = np.lexsort((np.array(final), keys))
    counts = np.cumsum([n_downstream[final[i]] for i in order])
    part_of = np.minimum((counts - 1) * k // n_terminals, k - 1)
    return [np.array([final[i] for i in order[part_of == p]], dtype=np.int64) for p in range(k)]


# How far beyond the supply radius (voxels) another part's voxels are kept from a movable
# terminal's voxel: its offset from the voxel centre (√3/2), and a hair for rounding.
MARGIN_SLACK = 0.5 * np.sqrt(3.0) + 1e-9


def part_regions(problem: Problem, terminal_position: np.ndarray, terminal_part: np.ndarray) -> np.ndarray:
    """int64 (nz, ny, nx): per supply-grid voxel, the part whose terminals may lie in it, or -1.

    Every tissue voxel belongs to the part of the terminal nearest to its block of 2 x 2 x 2
    voxels (its centre's: eight times fewer lookups than by voxel, for about as many free
    terminals). A terminal at x covers the voxel centres within ρ (the supply radius,
    voxels) of x, and x lies within √3/2 of its voxel's centre; so a terminal in a voxel with
    no voxel of another part within ρ + √3/2 covers only voxels of its own part
    (:func:`vasc_pipeline.kernel.margins.mark_margins`, which also sees another part across a
    thin cavity), whatever the partition. Such voxels get their part's index, every other
    voxel -1.
    """
    t = problem.tissue
    tissue = t.mask != 0
    blocks = np.argwhere(tissue) >> 1  # (z, y, x) index of each tissue voxel's block
    occupied = np.zeros(tuple((n + 1) // 2 for n in t.shape), dtype=bool)
    occupied[tuple(blocks.T)] = True
    block_index = np.argwhere(occupied)
    centres = t.origin + t.voxel_size * (2 * block_index[:, ::-1] + 0.5)
    _, nearest = cKDTree(terminal_position).query(centres, workers=-1)
    block_part = np.zeros(occupied.shape, dtype=np.int64)
    block_part[tuple(block_index.T)] = terminal_part[nearest]
    region = np.full(t.shape, -1, dtype=np.int64)  # -1: not tissue, no count to share
    region[tissue] = block_part[tuple(blocks.T)]
    near = np.zeros(t.shape, dtype=bool)
    mark_margins(region, problem.model.supply_rho + MARGIN_SLACK, near)
    region[near] = -1
    return region


def make_parts(problem: Problem, state: kernel.State, k: int, shift: np.ndarray, leaves: bool = False) -> list[Part]:
    """The phase's ``k`` parts of the tree in ``state`` (:func:`cut`).

    Parts of whole subtrees (``leaves`` false) move their bifurcations and swap their nodes;
    their terminals stay put. Parts of terminals (``leaves``), grouped by place, each hanging
    from its parent, move their terminals and swap their parents; a terminal joins its part
    only where its supply sphere stays in the part's region (:func:`part_regions`), and then
    only there may it move (``Part.mask``).
    """
    model = problem.model
    roots = cut(state.parent, state.children, state.n_downstream, state.position, model.n_inlets, k, shift, leaves)
    first_terminal, first_bifurcation = model.n_inlets, model.n_inlets + model.n_terminals
    masks: list[np.ndarray | None] = [None] * k
    corners: list[np.ndarray | None] = [None] * k
    if leaves:
        terminal_part = np.empty(model.n_terminals, dtype=np.int64)
        for p, part_roots in enumerate(roots):
            terminal_part[part_roots - first_terminal] = p
        region = part_regions(problem, state.position[first_terminal:first_bifurcation], terminal_part)
        voxel = np.floor((state.position - model.origin) / model.voxel_size + 0.5).astype(np.int64)
        reach = int(np.ceil(model.supply_rho + MARGIN_SLACK))  # how far a sphere reaches beyond its voxel
        boxes = ndimage.find_objects(region + 1, max_label=k)  # each part's voxels' bounding box
        for p in range(k):
            x, y, z = voxel[roots[p]].T
            roots[p] = roots[p][region[z, y, x] == p]  # the others are border terminals: frozen
            box = boxes[p] or (slice(0, 1),) * 3
            lo = np.array([max(b.start - reach, 0) for b in box], dtype=np.int64)
            box = tuple(slice(a, min(b.stop + reach, n)) for a, b, n in zip(lo, box, region.shape))
            masks[p], corners[p] = (region[box] == p).astype(np.uint8), lo
    kernel.pressure_cost(model, state)  # every node's pressure, into scratch_pressure
    out = []
    for p, part_roots in enumerate(roots):
        nodes = _subtree_nodes(state.children, part_roots)
        inlets = np.unique(state.parent[part_roots])  # one pseudo-inlet per parent, with its children here
        terminals = nodes[nodes < first_bifurcation]
        out.append(
            Part(
                np.concatenate([inlets, terminals, nodes[nodes >= first_bifurcation]]),
                part_roots,
                len(inlets),
                len(terminals),
                masks[p],
                inlet_pressure=state.scratch_pressure[inlets].copy(),
                corner=corners[p],
            )
        )
    return out


def part_model(model: kernel.Model, part: Part) -> kernel.Model:
    """The kernel model of a part: its node counts and pseudo-inlet pressures, counts kept
    between its pseudo-inlets' trees, terminals moving only in parts of terminals, within their
    mask (the supply grid then the part's box); the whole tree's tables, exclusion grid, weights
    and schedule."""
    own = dict(
        n_inlets=part.n_inlets,
        n_terminals=part.n_terminals,
        pressure_inlet=part.inlet_pressure,
        fixed_inlet_counts=True,
    )
    if part.mask is None:  # its terminals stay put: no tissue to look up
        return model._replace(
            **own,
            mask=_NO_GRID,
            move_terminals=False,
            supply_target=_NO_TARGET,
        )
    target = model.supply_target
    return model._replace(
        **own,
        mask=part.mask,
        origin=model.origin + model.voxel_size * part.corner[::-1],
        bifurcation_region=np.zeros((0, 0, 0), dtype=np.uint8),  # its bifurcations are pseudo-inlets: fixed
        supply_target=np.ascontiguousarray(target[part.box]) if target.size else target,  # the box's, as the map
    )


# The grid a part's kernel never reads (the tissue of a part whose terminals stay put), and its targets.
_NO_GRID = np.zeros((1, 1, 1), dtype=np.uint8)
_NO_TARGET = np.zeros((0, 0, 0), dtype=np.uint8)


def part_state(problem: Problem, model: kernel.Model, state: kernel.State, part: Part, rng: np.ndarray) -> kernel.State:
    """A kernel state holding the part's subtrees (renumbered in ``part.nodes`` order), the
    whole tree's supply map and C_s, the whole tree's step count and step sizes, and ``rng``."""
    k_in = part.n_inlets
    local = np.full(state.parent.size, -1, dtype=np.int64)
    local[part.nodes[k_in:]] = np.arange(k_in, part.nodes.size)
    own = part.nodes[k_in:]
    parent = np.full(part.nodes.size, -1, dtype=np.int64)
    parent[k_in:] = local[state.parent[own]]
    children = np.full((part.nodes.size, 2), -1, dtype=np.int64)
    children[k_in:] = np.where(state.children[own] >= 0, local[np.maximum(state.children[own], 0)], -1)
    for j, g in enumerate(part.nodes[:k_in]):  # a pseudo-inlet: its children in this part, in their slots' order
        kids = [local[c] for c in state.children[g] if c >= 0 and local[c] >= 0]
        children[j, : len(kids)] = kids
        parent[kids] = j
    m = part.nodes.size
    arrays = {
        "parent": parent,
        "children": children,
        "position": state.position[part.nodes],
        "n_downstream": state.n_downstream[part.nodes],
        "seg_length": np.zeros(m),
        "seg_exclusion": np.zeros(m),
        "supply": _part_supply(state.supply, part),
        "costs": np.zeros_like(state.costs),
        "compensation": np.zeros_like(state.compensation),
        "rng": rng,
        "counters": state.counters,
        "step_size": state.step_size,
        "schedule": state.schedule,
        "cell_of": np.full(m, -1, dtype=np.int64),
        "cell_head": np.full_like(state.cell_head, -1),
        "cell_next": np.full(m, -1, dtype=np.int64),
        "cell_prev": np.full(m, -1, dtype=np.int64),
    }
    sub = restore_state(problem, arrays, n_terminals=max(part.n_terminals, 1))
    own_model = part_model(model, part)
    kernel.initialise_segments(own_model, sub)
    if own_model.pressure_on:  # the moments its ΔC_p reads (its C_p stays 0: the merge recomputes it)
        kernel.pressure_moments(own_model, sub)
    sub.costs[kernel.SUPPLY] = state.costs[kernel.SUPPLY] + state.compensation[kernel.SUPPLY]
    return sub


def _part_supply(supply: np.ndarray, part: Part) -> np.ndarray:
    """The part's view of the supply map: its box's, or one voxel where it reads none."""
    return supply[:1, :1, :1] if part.mask is None else supply[part.box]


def anneal_parts(
    problem: Problem,
    model: kernel.Model,
    state: kernel.State,
    parts: list[Part],
    n_steps: int,
    phase_seed: int,
    map: Callable = map,
) -> list[tuple]:
    """Anneal every part on ``model`` (the whole tree's, or its coarse twin) for its share of
    ``n_steps`` proposals (by node count), along the schedule of the whole tree's next
    ``n_steps`` steps (:func:`anneal_part`); returns the parts' results in part order.
    ``state`` is not changed."""
    total_nodes = max(sum(p.nodes.size - p.n_inlets for p in parts), 1)
    jobs = []
    for index, part in enumerate(parts):
        rng = seed_state(int(np.random.SeedSequence([phase_seed, index]).generate_state(1, np.uint64)[0]))
        sub = part_state(problem, model, state, part, rng)
        share = int(n_steps) * (part.nodes.size - part.n_inlets) // total_nodes
        jobs.append((part_model(model, part), sub, share, int(n_steps)))
    return list(map(anneal_part, jobs))


# What a part's anneal hands back: all that the merge reads.
PART_RESULT = ("position", "parent", "children", "n_downstream", "counters", "step_size")


# Legs of a part's anneal, each starting where the whole tree's schedule stands at that share
# of the round: a part's temperature then lags the schedule by at most 1/SCHEDULE_LEGS of a
# round (about 22 000 steps of a round's 1.4 million at N = 2000).
SCHEDULE_LEGS = 64


def anneal_part(job: tuple[kernel.Model, kernel.State, int, int]) -> tuple:
    """One part's anneal, ``(model, state, n_steps, span)`` -> the fields of :data:`PART_RESULT`
    of its final state: the task a worker runs.

    The part proposes ``n_steps`` moves while the whole tree's schedule runs ``span`` steps on
    from the state's step: its moves are spread over that span (in :data:`SCHEDULE_LEGS` legs,
    each starting at its share of the span), so every part cools as far as the round does,
    not by its own n_steps alone (a part of 1/k of the tree would end each round at the
    temperature of 1/k of it). Its step count then reads ``n_steps`` more, as without the legs, for
    the merge's count of proposals."""
    model, sub, n_steps, span = job
    if n_steps > 0 and sub.parent.size > model.n_inlets:
        start = int(sub.counters[kernel.COUNTER_STEP])
        legs = min(SCHEDULE_LEGS, n_steps)
        for leg in range(legs):
            sub.counters[kernel.COUNTER_STEP] = start + span * leg // legs
            kernel.anneal_block(model, sub, n_steps * (leg + 1) // legs - n_steps * leg // legs)
        sub.counters[kernel.COUNTER_STEP] = start + n_steps
    return tuple(getattr(sub, name) for name in PART_RESULT)


# The counters the parts add to the whole tree's (the step count and the adaptation windows
# are the whole tree's own).
_SUMMED_COUNTERS = [
    kernel.COUNTER_TERMINAL_PROPOSED,
    kernel.COUNTER_TERMINAL_ACCEPTED,
    kernel.COUNTER_BIFURCATION_PROPOSED,
    kernel.COUNTER_BIFURCATION_ACCEPTED,
    kernel.COUNTER_SWAP_PROPOSED,
    kernel.COUNTER_SWAP_ACCEPTED,
    kernel.COUNTER_LOCAL_SWAP_PROPOSED,
]


def merge_parts(model: kernel.Model, state: kernel.State, parts: list[Part], results: list[tuple]) -> None:
    """Write the parts' subtrees back into ``state``, add their proposals to its counters and
    take the mean (by node count) of the step size their moves adapted (terminals' in parts of
    terminals, bifurcations' in parts of subtrees), then recompute its caches and sums on
    ``model`` (the supply map and every running sum from scratch: the merged state is exact)."""
    step0 = int(state.counters[kernel.COUNTER_STEP])
    counters = state.counters.copy()
    adapted = 0 if parts and parts[0].mask is not None else 1
    step, weight = 0.0, 0
    for part, result in zip(parts, results):
        position, parent, children, n_downstream, sub_counters, step_size = result
        k_in = part.n_inlets
        own = part.nodes[k_in:]
        mine = set(own.tolist())
        for j, g in enumerate(part.nodes[:k_in]):  # the slots of g that held this part's nodes
            kids = iter(part.nodes[c] for c in children[j] if c >= 0)
            state.children[g] = [next(kids) if c in mine else c for c in state.children[g]]
        state.position[own] = position[k_in:]
        state.parent[own] = part.nodes[parent[k_in:]]
        state.children[own] = np.where(children[k_in:] >= 0, part.nodes[np.maximum(children[k_in:], 0)], -1)
        state.n_downstream[own] = n_downstream[k_in:]
        counters[_SUMMED_COUNTERS] += sub_counters[_SUMMED_COUNTERS] - state.counters[_SUMMED_COUNTERS]
        counters[kernel.COUNTER_STEP] += int(sub_counters[kernel.COUNTER_STEP]) - step0
        step += own.size * step_size[adapted]
        weight += own.size
    state.counters[:] = counters
    if weight:
        state.step_size[adapted] = step / weight
    kernel.initialise(model, state)


def phase_ends(problem: Problem) -> np.ndarray:
    """The global step at which each phase of the parts' anneal ends (:meth:`Schedule.phase_ends
    <vasc_pipeline.config.schedule.Schedule.phase_ends>`)."""
    return problem.schedule.phase_ends()
